"""A seeded chaos ground station (issue 31, point 7): everything a careless, broken or hostile GCS does,
in random order, against a live vessel's ground-station port.

Actions (weights in :data:`ACTIONS`): mission uploads (well formed, abandoned half-way, with items out
of sequence or NaN/absurd fields), fence and rally uploads, mission downloads and clears, mode changes
(valid and unknown custom modes, COMMAND_LONG and SET_MODE), arm/disarm, GUIDED targets (DO_REPOSITION,
SET_POSITION_TARGET_GLOBAL_INT; anywhere within ~50 m, on land and off the chart too), parameter reads
and writes (real names with normal, NaN, infinite and huge values; not the control gains:
:data:`UNSAFE_PARAMS`), disconnect and reconnect (a new socket, alternating UDP and TCP when both are
given), floods (a burst of frames, read requests and garbage), silences (no heartbeat for up to 7 s:
the GCS failsafe), garbage bytes. With a key it signs its frames, and also sends frames signed with a
wrong key, replays captured ones and stamps one a day ahead. It never sends MANUAL_CONTROL (a person
steering into a quay is not the autopilot's fault).

Every random choice comes from ``numpy.random.default_rng(seed)``; what the vessel answers depends on
timing, so two runs with one seed make the same requests, not necessarily in the same wall-clock
instants. :class:`ChaosGcs.run` returns what it did and what it heard (:class:`ChaosStats`).
"""

from __future__ import annotations

import math
import select
import socket
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autopilot_bridge.gcs.signing import signing_now
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2

ACTIONS: dict[str, float] = {
    "upload": 3, "upload_abandon": 1, "upload_broken": 1, "upload_fence": 1, "upload_rally": 1,
    "download": 1, "clear": 0.3, "mode": 3, "set_mode_msg": 1, "arm": 2, "guided": 3, "param_set": 2,
    "param_read": 1, "reconnect": 1, "flood": 0.5, "silence": 0.3, "garbage": 1,
}
SIGNED_ONLY = {"wrong_key": 1, "replay": 1}
MODES = (0, 4, 5, 10, 11, 15, 3, 99, 255)     # MANUAL HOLD LOITER AUTO RTL GUIDED and three unknown ones
# Control gains are left alone: their advertised ranges include values that cannot steer the boat
# (HDG_KP = 0 was accepted and, with seed 31, the boat then hit the quay 84.6 s into a 150 s leg;
# docs/security.md, Open). SYSID_THISMAV too: it re-addresses the vessel, and the client tells its vessel
# from another run's by the system id (tests/test_vessel_parameters.py changes it). Every other parameter
# is fair game.
UNSAFE_PARAMS = frozenset({"HDG_KP", "HDG_KI", "HDG_KD", "SPD_BANDWIDTH", "SYSID_THISMAV"})


@dataclass
class ChaosStats:
    actions: Counter[str] = field(default_factory=Counter)
    heard: Counter[str] = field(default_factory=Counter)            # message types from the vessel
    mission_acks: Counter[str] = field(default_factory=Counter)     # MISSION_ACK results addressed to us
    command_acks: Counter[str] = field(default_factory=Counter)     # COMMAND_ACK results addressed to us
    attacks: Counter[str] = field(default_factory=Counter)          # signed frames meant to be refused, by kind
    connections: int = 0
    foreign: int = 0      # frames from another system id: another run's vessel still sending to a port now ours
    tcp_connect_failures: int = 0
    frames_sent: int = 0
    wall_s: float = 0.0


def _name(enum: str, value: int) -> str:
    e = mavlink2.enums.get(enum, {}).get(int(value))
    return e.name if e is not None else f"{enum}_{int(value)}"


class ChaosGcs:
    """``udp``/``tcp``: the vessel's udpin and tcpin addresses (either may be None); ``vessel``: its system id.
    Frames from any other system id are counted as ``foreign`` and otherwise ignored: a run beside this one
    may still send to a UDP port its own ground station let go and this client's new socket was given."""

    def __init__(self, seed: int, udp: tuple[str, int] | None, tcp: tuple[str, int] | None = None,
                 key: bytes | None = None, sysid: int = 255, vessel: int = 1) -> None:
        if udp is None and tcp is None:
            raise ValueError("chaos GCS: give a UDP or a TCP address")
        self.rng = np.random.default_rng(seed)
        self.udp, self.tcp, self.key = udp, tcp, key
        self.stats = ChaosStats()
        self.mav = self._mav(sysid, key)
        self.vessel = self.target = vessel
        self.anchor: tuple[float, float] | None = None    # the vessel's lat/lon (deg), from GLOBAL_POSITION_INT
        self.params: list[str] = []
        self.sock: socket.socket | None = None
        self.is_tcp = False
        self.parser = mavlink2.MAVLink(None, 255, 190)
        self.parser.robust_parsing = True
        self.captured: list[bytes] = []
        self.silent_until = 0.0
        self.last_beat = 0.0
        self._connect(prefer_tcp=False)

    @staticmethod
    def _mav(sysid: int, key: bytes | None) -> Any:
        mav = mavlink2.MAVLink(None, sysid, 190)
        if key is not None:
            mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, 0
            mav.signing.timestamp = signing_now()
        return mav

    # -- the wire --------------------------------------------------------------------------------
    def _connect(self, prefer_tcp: bool) -> None:
        if self.sock is not None:
            self.sock.close()
        use_tcp = self.tcp is not None and (prefer_tcp or self.udp is None)
        self.is_tcp = use_tcp
        self.parser = mavlink2.MAVLink(None, 255, 190)
        self.parser.robust_parsing = True
        if use_tcp:
            assert self.tcp is not None
            try:
                self.sock = socket.create_connection(self.tcp, timeout=5.0)
            except OSError:           # the vessel's TCP server refused or is gone: counted, UDP instead
                self.stats.tcp_connect_failures += 1
                use_tcp = self.is_tcp = False
        if not use_tcp:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.stats.connections += 1
        self.beat(force=True)

    def raw(self, data: bytes) -> None:
        assert self.sock is not None
        try:
            if self.is_tcp:
                self.sock.sendall(data)
            else:
                assert self.udp is not None
                self.sock.sendto(data, self.udp)
            self.stats.frames_sent += 1
        except (BlockingIOError, InterruptedError):
            pass                      # the vessel does not read fast enough: dropped, as a radio would
        except OSError:
            self._connect(prefer_tcp=not self.is_tcp)   # the vessel closed our TCP connection: come back

    def send(self, name: str, *args: Any, mav: Any = None) -> bytes:
        mav = mav or self.mav
        data = bytes(getattr(mav, f"{name}_encode")(*args).pack(mav))
        if self.key is not None and len(self.captured) < 64 and self.rng.random() < 0.05:
            self.captured.append(data)
        self.raw(data)
        return data

    def beat(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or (now >= self.silent_until and now - self.last_beat >= 1.0):
            self.last_beat = now
            self.send("heartbeat", M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)

    def pump(self, wait: float = 0.0) -> list[Any]:
        """What the vessel sent (bounded: at most 64 reads), after waiting up to ``wait`` s for the first."""
        assert self.sock is not None
        out: list[Any] = []
        if wait > 0:
            select.select([self.sock], [], [], wait)
        for _ in range(64):
            try:
                data = self.sock.recv(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._connect(prefer_tcp=not self.is_tcp)
                break
            if not data:
                self._connect(prefer_tcp=False)
                break
            for m in self.parser.parse_buffer(data) or []:
                if isinstance(m, (mavlink2.MAVLink_bad_data, mavlink2.MAVLink_unknown)):
                    continue
                if m.get_srcSystem() != self.vessel:
                    self.stats.foreign += 1
                    continue
                out.append(m)
        for m in out:
            self._note(m)
        return out

    def _note(self, m: Any) -> None:
        kind = m.get_type()
        self.stats.heard[kind] += 1
        if kind == "HEARTBEAT" and m.get_srcComponent() == 1:
            self.target = m.get_srcSystem()
        elif kind == "GLOBAL_POSITION_INT" and (m.lat or m.lon):
            self.anchor = (m.lat * 1e-7, m.lon * 1e-7)
        elif kind == "PARAM_VALUE":
            name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
            if name and name not in self.params and name not in UNSAFE_PARAMS and len(self.params) < 512:
                self.params.append(name)
        elif kind == "MISSION_ACK" and m.target_system == self.mav.srcSystem:
            self.stats.mission_acks[_name("MAV_MISSION_RESULT", m.type)] += 1
        elif kind == "COMMAND_ACK" and m.target_system == self.mav.srcSystem:
            self.stats.command_acks[_name("MAV_RESULT", m.result)] += 1

    def wait_for(self, types: tuple[str, ...], timeout: float) -> Any:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.beat()
            for m in self.pump(wait=min(0.05, max(0.0, end - time.monotonic()))):
                if m.get_type() in types and getattr(m, "target_system", self.mav.srcSystem) in (0, self.mav.srcSystem):
                    return m
        return None

    # -- actions ---------------------------------------------------------------------------------
    def _point(self, spread_m: float = 50.0) -> tuple[int, int]:
        lat, lon = self.anchor or (0.0, 0.0)
        dn, de = self.rng.uniform(-spread_m, spread_m, 2)
        return (int(round((lat + dn / 111_320.0) * 1e7)),
                int(round((lon + de / (111_320.0 * max(0.1, math.cos(math.radians(lat))))) * 1e7)))

    def _upload(self, mtype: int, count: int, answer: int, broken: bool = False) -> None:
        self.send("mission_count", self.target, 1, count, mtype)
        answered = 0
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            m = self.wait_for(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"), end - time.monotonic())
            if m is None or m.get_type() == "MISSION_ACK":
                return
            if answered >= answer:
                continue                         # abandoned: silent from here on
            seq = int(m.seq)
            if broken and self.rng.random() < 0.3:
                seq = int(self.rng.integers(0, count + 3))
            cmd = {M.MAV_MISSION_TYPE_FENCE: 5001, M.MAV_MISSION_TYPE_RALLY: 5100}.get(mtype, M.MAV_CMD_NAV_WAYPOINT)
            x, y = self._point()
            p = [0.0, float("nan"), 0.0, float("nan")]
            if broken and self.rng.random() < 0.3:
                p[int(self.rng.integers(0, 4))] = float(self.rng.choice([np.nan, np.inf, -1e38, 1e38]))
            self.send("mission_item_int", self.target, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1,
                      *p, x, y, 0.0, mtype)
            answered += 1

    def act(self, action: str) -> None:
        self.stats.actions[action] += 1
        t, rng = self.target, self.rng
        if action in ("upload", "upload_abandon", "upload_broken"):
            count = int(rng.integers(1, 9))
            answer = count if action != "upload_abandon" else int(rng.integers(0, count))
            self._upload(M.MAV_MISSION_TYPE_MISSION, count, answer, broken=action == "upload_broken")
        elif action in ("upload_fence", "upload_rally"):
            mtype = M.MAV_MISSION_TYPE_FENCE if action == "upload_fence" else M.MAV_MISSION_TYPE_RALLY
            count = int(rng.integers(1, 6))
            self._upload(mtype, count, count)
        elif action == "download":
            self.send("mission_request_list", t, 1, int(rng.choice([0, 1, 2])))
            c = self.wait_for(("MISSION_COUNT",), 1.0)
            for seq in range(min(int(c.count), 16) if c is not None else 0):
                self.send("mission_request_int", t, 1, seq, c.mission_type)
                self.wait_for(("MISSION_ITEM_INT", "MISSION_ACK"), 0.5)
        elif action == "clear":
            self.send("mission_clear_all", t, 1, int(rng.choice([0, 255])))
        elif action == "mode":
            self.send("command_long", t, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                      float(rng.choice(MODES)), 0, 0, 0, 0, 0)
        elif action == "set_mode_msg":
            self.send("set_mode", t, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(rng.choice(MODES)))
        elif action == "arm":
            self.send("command_long", t, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, float(rng.random() < 0.8),
                      0, 0, 0, 0, 0, 0)
        elif action == "guided":
            x, y = self._point()
            if rng.random() < 0.5:
                self.send("command_int", t, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0,
                          -1.0, 0.0, 0.0, float("nan"), x, y, 0.0)
            else:
                self.send("set_position_target_global_int", 0, t, 1, M.MAV_FRAME_GLOBAL_INT, 0b110111111000,
                          x, y, 0.0, 0, 0, 0, 0, 0, 0, 0, 0)
        elif action == "param_set":
            if self.params:
                name = str(rng.choice(self.params))
                value = float(rng.choice([rng.normal(0, 10), np.nan, np.inf, -1e38, 0.0, 1e6]))
                self.send("param_set", t, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
            else:
                self.send("param_request_list", t, 1)
        elif action == "param_read":
            if self.params and rng.random() < 0.7:
                self.send("param_request_read", t, 1, str(rng.choice(self.params)).encode(), -1)
            else:
                self.send("param_request_list", t, 1)
        elif action == "reconnect":
            self._connect(prefer_tcp=bool(rng.random() < 0.5))
        elif action == "flood":
            for _ in range(int(rng.integers(100, 400))):
                kind = rng.integers(0, 4)
                if kind == 0:
                    self.raw(rng.bytes(int(rng.integers(1, 280))))
                elif kind == 1:
                    self.send("ping", int(time.time() * 1e6), 0, 0, 0)
                elif kind == 2:
                    self.send("mission_request_list", t, 1, 0)
                else:
                    self.send("heartbeat", M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        elif action == "silence":
            self.silent_until = time.monotonic() + float(rng.uniform(2.0, 7.0))
        elif action == "garbage":
            self.raw(rng.bytes(int(rng.integers(1, 600))))
        elif action == "wrong_key":
            other = self._mav(int(rng.integers(1, 255)), bytes(rng.integers(0, 256, 32, dtype=np.uint8)))
            self.stats.attacks["bad_signature"] += 1
            self.send("command_long", t, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0, mav=other)
        elif action == "replay" and self.captured:
            self.raw(self.captured[int(rng.integers(0, len(self.captured)))])
            self.stats.attacks["replay"] += 1
            if rng.random() < 0.1:
                self.stats.attacks["future"] += 1       # a GCS whose clock is a day fast
                ahead = self._mav(int(rng.integers(100, 200)), self.key)
                ahead.signing.timestamp = signing_now() + 86400 * 100_000
                self.send("command_long", t, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0, mav=ahead)

    def run(self, duration_s: float, connect_timeout: float = 120.0,
            alive: Callable[[], bool] | None = None) -> ChaosStats:
        """Wait for the vessel's first HEARTBEAT (and learn its parameter names), then act for ``duration_s``,
        or until ``alive()`` says the vessel is gone (an hour is not spent talking to a run that ended)."""
        start = time.monotonic()
        if self.wait_for(("HEARTBEAT",), connect_timeout) is None:
            raise TimeoutError("chaos GCS: no HEARTBEAT from the vessel")
        self.send("param_request_list", self.target, 1)
        self.wait_for(("NONE",), 1.0)
        names = list(ACTIONS) + (list(SIGNED_ONLY) if self.key is not None else [])
        weights = np.array([ACTIONS.get(n, SIGNED_ONLY.get(n, 0.0)) for n in names], dtype=float)
        weights /= weights.sum()
        end = time.monotonic() + duration_s
        while time.monotonic() < end and (alive is None or alive()):
            self.act(str(self.rng.choice(names, p=weights)))
            self.wait_for(("NONE",), float(self.rng.uniform(0.02, 0.3)))   # hear the answers, keep beating
        self.stats.wall_s = time.monotonic() - start
        return self.stats

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
