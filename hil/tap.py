"""The tap of a HIL run (hil/hilrun.py): a third UDP endpoint that both processes copy their frames
to. It writes every accepted MAVLink frame to the run's .tlog (0600 when a signing key is set),
takes the truth only from the simulator's stream, the commands only from the autopilot's, and
nothing from a socket other than theirs and the autopilot's telemetry copies (refusals counted, not
recorded), and keeps what the judge needs."""

from __future__ import annotations

import bisect
import math
import os
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING

from common.geodesy import LocalFrame
from common.mavlink import Codec, MavMessage, clean_frames, frame_ids, leading_uint64, mavlink2, message_at
from common.udp import UdpEndpoint
from hil.run_summary import TapCounters

if TYPE_CHECKING:
    from hil.encounter_report import EncounterJudge

# The kinds the tap reads (Tap._take); every other frame of a clean datagram is written as it came.
_READ = frozenset(getattr(mavlink2, f"MAVLINK_MSG_ID_{k}") for k in (
    "HIL_STATE_QUATERNION", "AIS_VESSEL", "HIL_ACTUATOR_CONTROLS", "LOCAL_POSITION_NED", "STATUSTEXT",
    "MISSION_ITEM_REACHED"))
_HIL_SENSOR = mavlink2.MAVLINK_MSG_ID_HIL_SENSOR
_STAMP, _STAMP_MAX = struct.Struct(">Q"), (1 << 64) - 1   # a .tlog record's time stamp
# The lockstep clock is HIL_SENSOR's time_usec, read as the frame's leading uint64 (its first wire field).
assert mavlink2.MAVLink_hil_sensor_message.ordered_fieldnames[0] == "time_usec"
assert mavlink2.MAVLink_hil_sensor_message.fieldtypes[0] == "uint64_t"


class Tap:
    """Receives everything both processes send to it; writes the .tlog; keeps the evaluation data."""

    def __init__(self, tlog_path: Path, geo: LocalFrame, encounters: EncounterJudge | None = None,
                 truth_component_id: int = 52, sim_component_id: int = 51, lockstep: bool = False,
                 private: bool = False) -> None:
        self.ep = UdpEndpoint("127.0.0.1:0", [], recv_buffer=8 << 20)
        # Every message of the dialect: the autopilot copies all ground-station traffic here too.
        self.codec = Codec(255, 190, accept=[c.msgname for c in mavlink2.mavlink_map.values()])
        # Ship traffic (hil.encounter_report.EncounterJudge): the truth AIS_VESSEL of each datagram
        # belongs to the HIL_STATE_QUATERNION before it in the same datagram.
        self.encounters = encounters
        self.truth_component_id, self.sim_component_id = truth_component_id, sim_component_id
        self.ais_forwarded = 0  # AIS_VESSEL from the vessel computer's telemetry (forwarded to ground stations)
        # With a signing key the tlog holds signed frames: owner-only (0600), like the JSON summaries
        # (written through mkstemp), even where an older run.tlog was there.
        fd = os.open(tlog_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if private else 0o666)
        if private:
            os.fchmod(fd, 0o600)
        self.tlog = os.fdopen(fd, "wb")
        self.geo = geo
        self.truth: dict[int, tuple[float, float, float, float]] = {}  # time_usec -> (north, east, vn, ve)
        self.truth_times: list[int] = []   # the keys of truth, ascending (kept so, not sorted per read)
        self.estimate: dict[tuple[int, int], tuple[float, float]] = {}  # (segment, ms) -> (north, east)
        self.commands: list[tuple[int, float, float]] = []             # (time_usec, port, stdb)
        self.statustext: list[str] = []
        self.mission_reached = False
        self.frames = 0
        # A simulator restart starts its clock at 0 again: each stream keeps a running epoch so
        # that the run's time axis stays monotonic (epoch = the time reached before the restart).
        self._epoch = {"truth": 0, "estimate": 0, "commands": 0, "clock": 0}
        self._last = {"truth": -1, "estimate": -1, "commands": -1, "clock": -1}
        self._segment = {"truth": 0, "estimate": 0, "commands": 0, "clock": 0}
        # tlog time stamps: in lockstep the run's start (wall clock) plus the simulated time of the
        # newest simulator frame, so that log viewers replay simulated time (docs/simulator.md);
        # in real time the wall clock.
        self.lockstep = lockstep
        self._t0_usec = int(time.time() * 1e6)
        self._sim_usec = 0
        # (segment, time_usec) -> (n, e, run time usec)
        self.truth_raw: dict[tuple[int, int], tuple[float, float, int]] = {}
        # Source addresses of the two processes (HilRun sets them once the ports are chosen):
        # truth only from the simulator, commands only from the autopilot's HIL socket.
        self.sim_addr: tuple[str, int] | None = None
        self.ap_addr: tuple[str, int] | None = None
        # The autopilot's copies of its ground-station traffic (estimate, texts, mission progress): with
        # this set too, a datagram from any other socket is refused whole.
        self.telemetry_addr: tuple[str, int] | None = None
        self.sim_ids: tuple[int, int] | None = None
        self.refused: dict[str, int] = {}
        self.write_error: OSError | None = None   # the .tlog could not be written (a full disk)
        self.counters_at_close: TapCounters | None = None
        # The truth sample (time, north, east, heading) of the datagram being read: the ship truth
        # (AIS_VESSEL) after it in the same datagram is of the same instant.
        self._own: tuple[int, float, float, float] | None = None

    def _monotonic(self, stream: str, t: int, back_gap: int) -> int:
        if t + back_gap < self._last[stream]:
            self._epoch[stream] += self._last[stream]
            self._segment[stream] += 1
        self._last[stream] = t
        return self._epoch[stream] + t

    @property
    def port(self) -> int:
        return self.ep.address[1]

    def pump(self, timeout: float) -> int:
        """Read what is queued (waiting up to ``timeout`` for the first datagram); returns datagrams read."""
        n = 0
        data = self.ep.recv(timeout=timeout)
        while data is not None:
            n += 1
            self._handle(data, self.ep.last_sender)
            if n >= UdpEndpoint.READ_BUDGET:
                break
            data = self.ep.recv(timeout=0.0)
        return n

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def _allowed(self, m: MavMessage, sender: tuple[str, int] | None) -> bool:
        """Truth only from the simulator's socket and ids; commands only from the autopilot's socket."""
        kind = m.get_type()
        truth = kind == "HIL_STATE_QUATERNION" or (kind == "AIS_VESSEL" and
                                                   m.get_srcComponent() == self.truth_component_id)
        if truth:
            if self.sim_addr is not None and sender != self.sim_addr:
                self._refuse("truth_wrong_source_address")
                return False
            if self.sim_ids is not None and m.get_srcSystem() != self.sim_ids[0]:
                self._refuse("truth_wrong_source_id")
                return False
        elif kind == "HIL_ACTUATOR_CONTROLS" and self.ap_addr is not None and sender != self.ap_addr:
            self._refuse("command_wrong_source_address")
            return False
        return True

    def _write(self, data: bytes) -> None:
        if self.write_error is not None:
            return
        try:
            self.tlog.write(data)
        except OSError as exc:  # a full disk: the run stops and says so (HilRun.execute)
            self.write_error = exc

    def _handle(self, data: bytes, sender: tuple[str, int] | None = None) -> None:
        self._own = None
        if self.telemetry_addr is not None and sender not in (self.sim_addr, self.ap_addr, self.telemetry_addr):
            self._refuse("wrong_source_address")
            return
        spans = clean_frames(data) if self.codec.mav.signing.secret_key is None else None
        if spans is None:   # not what our processes send, or signed: pymavlink parses and names the faults
            msgs, _ = self.codec.decode(data)
            self._take(msgs, self._stamp(msgs, sender), sender)
            return
        # A clean datagram: message objects only for the kinds the tap reads; the other frames (about
        # half of a run's, HIL_SENSOR the largest) go to the .tlog as they came, byte for byte.
        ids = [frame_ids(data, start)[0] for start, _ in spans]
        clock = None
        if self.lockstep and _HIL_SENSOR in ids and self._from_simulator(sender):
            start, end = spans[ids.index(_HIL_SENSOR)]
            clock = leading_uint64(data, start, end)
        stamp = self._stamp_at(clock)
        batch: list[MavMessage] = []
        for (start, end), msg_id in zip(spans, ids, strict=True):
            if msg_id in _READ:
                batch.append(message_at(data, start, end))
                continue
            if batch:
                self._take(batch, stamp, sender)
                batch = []
            self._write(stamp + data[start:end])
            self.frames += 1
        if batch:
            self._take(batch, stamp, sender)

    def _take(self, msgs: list[MavMessage], stamp: bytes, sender: tuple[str, int] | None) -> None:
        own = self._own
        for m in msgs:
            if not self._allowed(m, sender):
                continue
            self._write(stamp + bytes(m.get_msgbuf()))
            self.frames += 1
            kind = m.get_type()
            if kind == "HIL_STATE_QUATERNION":
                t = self._monotonic("truth", int(m.time_usec), 1_000_000)
                if t not in self.truth:
                    n, e = self.geo.geodetic_to_sea_level(m.lat * 1e-7, m.lon * 1e-7)
                    self.truth[t] = (n, e, m.vx * 0.01, m.vy * 0.01)
                    bisect.insort(self.truth_times, t)   # at the end, unless a datagram came late
                    self.truth_raw[(self._segment["truth"], int(m.time_usec))] = (n, e, t)
                    q = m.attitude_quaternion
                    own = (t, n, e, 2.0 * math.atan2(q[3], q[0]))
            elif kind == "AIS_VESSEL":
                if m.get_srcComponent() != self.truth_component_id:
                    self.ais_forwarded += m.get_srcComponent() != self.sim_component_id
                elif own is not None and self.encounters is not None:
                    n, e = self.geo.geodetic_to_sea_level(m.lat * 1e-7, m.lon * 1e-7)
                    name = m.name if isinstance(m.name, str) else m.name.decode(errors="replace")
                    self.encounters.add(own[0], own[1:], int(m.MMSI), name.rstrip("\x00 "),
                                        (float(m.dimension_bow), float(m.dimension_stern), float(m.dimension_port),
                                         float(m.dimension_starboard)),
                                        n, e, math.radians(m.COG * 0.01), m.velocity * 0.01)
            elif kind == "HIL_ACTUATOR_CONTROLS":
                t = self._monotonic("commands", int(m.time_usec), 1_000_000)
                self.commands.append((t, float(m.controls[0]), float(m.controls[1])))
            elif kind == "LOCAL_POSITION_NED":
                self._monotonic("estimate", int(m.time_boot_ms), 1000)
                self.estimate[(self._segment["estimate"], int(m.time_boot_ms))] = (float(m.x), float(m.y))
            elif kind == "STATUSTEXT":
                self.statustext.append(m.text if isinstance(m.text, str) else m.text.decode(errors="replace"))
            elif kind == "MISSION_ITEM_REACHED":
                self.mission_reached = True
        self._own = own

    def _from_simulator(self, sender: tuple[str, int] | None) -> bool:
        return self.sim_addr is None or sender == self.sim_addr

    def _stamp(self, msgs: list, sender: tuple[str, int] | None) -> bytes:
        """The tlog time stamp (8 bytes, big-endian µs since the Unix epoch) of one datagram's messages."""
        if not self.lockstep or not self._from_simulator(sender):
            return self._stamp_at(None)
        return self._stamp_at(next((int(m.time_usec) for m in msgs if m.get_type() == "HIL_SENSOR"), None))

    def _stamp_at(self, sensor_usec: int | None) -> bytes:
        """The tlog time stamp of a datagram whose first HIL_SENSOR (from the simulator) says
        ``sensor_usec`` (None: none). In lockstep the simulated time: only the simulator's clock
        moves it, and a time past the stamp's 64 bits is held at the largest stamp."""
        if not self.lockstep:
            return _STAMP.pack(int(time.time() * 1e6))
        if sensor_usec is not None:
            t = self._monotonic("clock", sensor_usec, 1_000_000)
            self._sim_usec = max(self._sim_usec, t)
        return _STAMP.pack(min(self._t0_usec + self._sim_usec, _STAMP_MAX))

    def counters(self) -> TapCounters:
        """What the tap refused, by reason, and its socket's counters (kernel drops)."""
        ep = self.ep.counters()
        return TapCounters(refused=dict(sorted(self.refused.items())), wrong_source=ep["wrong_source"],
                           budget_stops=ep["budget_stops"], kernel_drops=ep["kernel_drops"])

    def close(self) -> None:
        try:
            self.tlog.close()
        except OSError as exc:
            self.write_error = self.write_error or exc
        self.ep.close()
