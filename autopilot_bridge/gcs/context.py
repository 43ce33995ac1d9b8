"""What every ground-station service shares: the :class:`Outbox` (encode, fan out, record, count) and the
:class:`VehicleView` (the vessel's command API, its newest status, its ids and chart)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Collection, Hashable
from typing import Protocol, cast

from autopilot_bridge.vehicle_api import VehicleApi, VehicleStatus
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import Codec, mavlink2
from common.udp import UdpEndpoint


class Transport(Protocol):
    """The interface of :mod:`autopilot_bridge.gcs.transport`'s classes."""

    stream: bool
    sent: int

    @property
    def address(self) -> tuple[str, int]: ...

    def receive(self, max_reads: int = ..., hold: Collection[Hashable] = ...) -> list[tuple[Hashable, bytes]]: ...

    def send(self, data: bytes) -> None: ...

    def heard(self, peer: Hashable, rank: int = ...) -> None: ...

    def close(self) -> None: ...


def enum_name(enum: str, value: int) -> str:
    entry = mavlink2.enums.get(enum, {}).get(int(value))
    return entry.name if entry is not None else f"{enum}_{int(value)}"


def finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def text_of(v: object) -> str:
    """A MAVLink char[] field as text (trailing NULs removed)."""
    return (v.decode(errors="replace") if isinstance(v, (bytes, bytearray)) else str(v)).rstrip("\x00")


STATUSTEXT_BYTES = 50          # the text field of STATUSTEXT
STATUSTEXT_MAX_CHUNKS = 8      # a text of up to 400 bytes arrives whole


def _utf8_chunks(text: str, size: int) -> list[bytes]:
    """``text`` as UTF-8 pieces of at most ``size`` bytes, never splitting a character."""
    chunks, cur = [], b""
    for ch in text:
        b = ch.encode()
        if len(cur) + len(b) > size:
            chunks.append(cur)
            cur = b""
        cur += b
    chunks.append(cur)
    return chunks


class Outbox:
    """Encodes messages with the vessel's ids and sends each frame to every transport and to the recorder."""

    def __init__(self, codec: Codec, transports: list[Transport], mirror: UdpEndpoint | None,
                 log: Callable[[str], None]) -> None:
        self.codec = codec
        self.transports = transports        # the link's list (closing the link empties it)
        self.mirror = mirror
        self.log = log
        self.sent = 0
        self.encode_errors: Counter[str] = Counter()
        self.commands: Counter[str] = Counter()        # "MAV_CMD_...:MAV_RESULT_..." of every COMMAND_ACK sent
        self.command_acks: Counter[str] = Counter()    # COMMAND_ACKs sent, by MAV_RESULT (refusals included)
        self.mission_acks: Counter[str] = Counter()    # MISSION_ACKs sent, by MAV_MISSION_RESULT
        self._statustext_id = 0                        # id of the last chunked STATUSTEXT (1-65535)

    def record(self, data: bytes) -> None:
        """Copy a frame to the recorder only (inbound frames that passed the security gate)."""
        if self.mirror is not None:
            self.mirror.send(data)

    def send_frame(self, data: bytes) -> None:
        for tr in self.transports:
            tr.send(data)
        self.record(data)
        self.sent += 1

    def send(self, name: str, *args: object) -> None:
        try:
            frame = self.codec.encode(name, *args)
        except Exception as exc:  # a field out of its wire range must cost a message, never the control loop
            self.encode_errors[name] += 1
            if self.encode_errors[name] == 1:
                self.log(f"gcs: {name} not sent: {type(exc).__name__}: {exc}")
            return
        self.send_frame(frame)
        if name == "command_ack":
            # COMMAND_ACK's command and result, MISSION_ACK's type: enum fields, ints on the wire
            cmd, result = enum_name("MAV_CMD", cast(int, args[0])), enum_name("MAV_RESULT", cast(int, args[1]))
            self.command_acks[result] += 1
            self.commands[f"{cmd}:{result}"] += 1
        elif name == "mission_ack":
            self.mission_acks[enum_name("MAV_MISSION_RESULT", cast(int, args[2]))] += 1

    def statustext(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        """One STATUSTEXT, or for a text over its 50 bytes MAVLink 2 chunks that ground stations join
        (same non-zero ``id``, ``chunk_seq`` 0, 1, ...; the last shorter than 50 bytes, else an empty
        NUL-terminated one follows), at most ``STATUSTEXT_MAX_CHUNKS``."""
        data = text.encode()
        if len(data) <= STATUSTEXT_BYTES:
            self.send("statustext", severity, data)
            return
        chunks = _utf8_chunks(text, STATUSTEXT_BYTES)[:STATUSTEXT_MAX_CHUNKS]
        if len(chunks[-1]) == STATUSTEXT_BYTES and len(chunks) < STATUSTEXT_MAX_CHUNKS:
            chunks.append(b"")
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        for seq, chunk in enumerate(chunks):
            self.send("statustext", severity, chunk, self._statustext_id, seq)

    def close(self) -> None:
        if self.mirror is not None:
            self.mirror.close()
            self.mirror = None


class VehicleView:
    """The vessel as the services see it: ids, chart, command API (after ``attach``), newest status."""

    def __init__(self, system_id: int, component_id: int, geo: LocalFrame,
                 chart_size: tuple[float, float] | None) -> None:
        self.sysid, self.compid = system_id, component_id
        self.geo = geo
        self.chart_size = chart_size        # (north extent, east extent) m of the chart, or None
        self.api: VehicleApi | None = None
        self.status: VehicleStatus | None = None   # the newest frame's (published by the vehicle)
        self.t = 0.0                        # its time, s of vessel time

    def on_chart(self, lat: float, lon: float) -> tuple[int, str] | None:
        """None for a point on the chart; else (MAV_MISSION_RESULT, why)."""
        if self.chart_size is None:
            return None
        n, e = self.geo.geodetic_to_sea_level(lat, lon)
        north_max, east_max = self.chart_size
        if not 0.0 <= n <= north_max:
            return M.MAV_MISSION_INVALID_PARAM5_X, f"waypoint {n:.0f} m north is off the chart (0-{north_max:.0f})"
        if not 0.0 <= e <= east_max:
            return M.MAV_MISSION_INVALID_PARAM6_Y, f"waypoint {e:.0f} m east is off the chart (0-{east_max:.0f})"
        return None
