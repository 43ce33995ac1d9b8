"""`hil run --autopilot ardupilot`: ArduPilot's ArduRover SITL flies the simulated boat.

The simulator answers ArduRover's servo packets as its JSON physics (:mod:`simulator.json_backend`)
in this process, in lockstep: ArduRover's clock is the physics' timestamp. ArduRover is started
with ArduPilot's rover, motorboat and skid-steering parameter files (beside the binary) plus one
written here (system id, the cruise speed and the throttle that holds it on this hull), home at the
scenario's start and start heading (``--home``), its JSON physics port and its MAVLink ports moved to
a private instance (``-I N``: SERIAL0 to our UDP socket, SERIAL1 and SERIAL2 on TCP 5762+10N and
5763+10N for a ground station).

This process is ArduRover's mission planner: it uploads the scenario's route (the global route of
`hil run`, on the chart inflated by the safety radius) as an ArduPilot mission, arms and sets AUTO,
and judges the run from the truth as `hil run` does (goal, collisions with the chart and the
traffic, clearance, energy); ``run.tlog`` holds ArduRover's MAVLink, what was sent to it and the
truth (HIL_STATE_QUATERNION, AIS_VESSEL of the ships), stamped with simulated time.

Everything this process does to ArduRover happens between two physics steps, while ArduRover waits
for the answer, so it happens at the same simulated time in every run.
"""

from __future__ import annotations

import math
import os
import shutil
import socket
import struct
import subprocess
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, final

import numpy as np

from autopilot_bridge.tracking_stats import TrackingSummary
from common.frames import map_to_ned
from common.geodesy import LocalFrame
from common.mavlink import MavMessage
from hil.ardupilot_fence import FENCE_VERTEX_EXCLUSION, MISSION_TYPE_FENCE, FenceItem
from hil.errors import RunFailed, UsageError
from simulator.json_backend import JsonLinkCounters

if TYPE_CHECKING:
    from hil.hilrun import RunOptions
    from hil.run_summary import RunSummary
    from hil.settings import HilConfig
    from simulator.config import VesselParams
    from simulator.core import SimulatorCore
    from simulator.json_backend import JsonPhysics, JsonServer

ENV_BINARY = "ARDUPILOT_SITL"
PARAM_FILES = ("rover.parm", "motorboat.parm", "rover-skid.parm")   # ArduPilot's motorboat-skid frame
JSON_PORT, SERIAL0_PORT = 9002, 5760          # ArduPilot SITL's ports of instance 0; +10 per instance
INSTANCES = range(11, 400)                    # private instances: ports 9112.. and 5870.. upwards
ROVER_AUTO, ROVER_HOLD = 10, 4                # Rover custom modes
GCS_SYSID, GCS_COMPID = 255, 190
# ArduRover's UNIX clock at boot (2025-01-01 00:00 UTC) instead of the host's: SYSTEM_TIME and its logs
# then repeat byte for byte from run to run.
SITL_START_TIME = 1735689600
POLL_EVERY = 10                               # physics steps between looks at ArduRover's MAVLink
SETUP_TIMEOUT_S = 120.0                       # simulated s for mission upload, arming and AUTO
IDLE_TIMEOUT_S = 20.0                         # wall s without a servo packet: ArduRover is gone


class FenceUpload(TypedDict):
    """The chart sent as ArduRover's exclusion fence: polygons, vertices, and ArduRover's item requests."""

    polygons: int
    vertices: int
    requests: int


class ArduRoverSetup(TypedDict):
    """How ArduRover was set up and flew: the binary, its instance, the parameters written for it,
    when it went AUTO (s of simulated time), the mission and fence uploaded, and its last messages."""

    binary: str
    instance: int
    params: dict[str, float]
    auto_at_s: float | None
    mission_items: int
    fence: FenceUpload | None
    mission_time_s: float | None        # from AUTO to the end of the run
    setup_failure: str | None
    statustext: list[str]


@final
class ArduPilotSimulatorSection(JsonLinkCounters):
    """The run summary's ``simulator`` section where ArduRover flew: the JSON physics' counters and
    ArduRover's setup."""

    ardupilot: ArduRoverSetup


@dataclass(frozen=True)
class SitlFiles:
    """The ArduRover SITL binary and the ArduPilot parameter files beside it."""

    binary: Path
    param_files: tuple[Path, ...]


def find_sitl(path: str | None) -> SitlFiles:
    """The binary from ``path`` or $ARDUPILOT_SITL; UsageError (one line) when absent or unusable."""
    given = path or os.environ.get(ENV_BINARY)
    if not given:
        raise UsageError(f"--autopilot ardupilot needs the ArduRover SITL binary: --ardupilot-bin PATH or "
                         f"{ENV_BINARY}=PATH (README.md, 'ArduRover in the loop', says how to get one)")
    binary = Path(given).expanduser().resolve()
    if not binary.is_file():
        raise UsageError(f"ArduRover SITL binary {binary}: no such file")
    if not os.access(binary, os.X_OK):
        raise UsageError(f"ArduRover SITL binary {binary}: not executable")
    missing = [n for n in PARAM_FILES if not (binary.parent / n).is_file()]
    if missing:
        raise UsageError(f"ArduRover SITL: {', '.join(missing)} missing beside {binary} (ArduPilot's "
                         f"Tools/autotest/default_params/)")
    try:
        probe = subprocess.run([str(binary), "--help"], capture_output=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise UsageError(f"ArduRover SITL binary {binary} does not run: {exc}") from None
    if b"--model" not in probe.stdout + probe.stderr:
        raise UsageError(f"{binary} is not an ArduPilot SITL binary (its --help does not list --model)")
    return SitlFiles(binary, tuple(binary.parent / n for n in PARAM_FILES))


def read_params(paths: tuple[Path, ...]) -> dict[str, float]:
    """ArduPilot parameter files merged in order (later wins); lines ArduPilot would skip
    (comments, a name without a value) are skipped here too."""
    out: dict[str, float] = {}
    for p in paths:
        for line in p.read_text(errors="replace").splitlines():
            parts = line.replace(",", " ").split()
            if len(parts) < 2 or parts[0].startswith("#"):
                continue
            try:
                value = float(parts[1])
            except ValueError:
                continue
            if math.isfinite(value):
                out[parts[0]] = value
    return out


def cruise_throttle(vessel: VesselParams, speed: float) -> float:
    """Percent throttle (both thrusters) that holds ``speed`` (m/s) in calm water on ``vessel``'s hull:
    ArduRover's CRUISE_THROTTLE for CRUISE_SPEED, from eq. (4)'s surge balance."""
    from simulator.vessel import Vessel, hull_dynamics

    v = Vessel(vessel)
    lo, hi = 0.0, 1.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        t = v.thrust(mid)
        d = hull_dynamics((0.0, 0.0, 0.0, speed, 0.0, 0.0), v.propulsion(t, t), (0.0, 0.0, 0.0), (0.0, 0.0),
                          v.coefficients)
        lo, hi = (mid, hi) if d[3] < 0 else (lo, mid)
    return round(100.0 * 0.5 * (lo + hi), 1)


def full_turn_rate(vessel: VesselParams) -> float:
    """Steady yaw rate (rad/s) of ``vessel``'s hull at full differential thrust (one thruster full
    ahead, the other full astern), from eq. (4)'s yaw balance."""
    from simulator.vessel import Vessel, hull_dynamics

    v = Vessel(vessel)
    moment = v.propulsion(v.thrust(1.0), v.thrust(-1.0))[2]
    lo, hi = 0.0, 20.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        d = hull_dynamics((0.0, 0.0, 0.0, 0.0, 0.0, mid), (0.0, 0.0, abs(moment)), (0.0, 0.0, 0.0), (0.0, 0.0),
                          v.coefficients)
        lo, hi = (mid, hi) if d[5] > 0 else (lo, mid)
    return 0.5 * (lo + hi)


TURN_MARGIN = 0.8   # ArduRover may ask for this share of the hull's full turn rate (the rest corrects)


def project_params(cfg: HilConfig) -> dict[str, float]:
    """The parameters this project lays over ArduPilot's, all from the configuration: the system id;
    the vessel computer's cruise speed with the throttle that holds it on this hull; what it does after
    the last waypoint (``autopilot.mission_done``, ``loiter_radius``); and the turn
    this hull can make. ArduPilot's defaults assume a rover that turns at 0.6 g and 120 deg/s; this
    boat makes 0.08 g at 1.5 m/s, and with those defaults ArduRover overshot the breakwater's corner of
    the harbour route and collided 122.1 s after AUTO (docs/ardupilot.md)."""
    speed = float(cfg.autopilot.cruise_speed)
    rate = TURN_MARGIN * full_turn_rate(cfg.vessel)
    sysid = float(cfg.autopilot.system_id)
    # The system id under both names: MAV_SYSID since ArduPilot 4.7 (the shipped binary knows only it),
    # SYSID_THISMAV before; each ignores the other's name in a defaults file.
    return {"MAV_SYSID": sysid, "SYSID_THISMAV": sysid, "CRUISE_SPEED": speed, "WP_SPEED": speed,
            "CRUISE_THROTTLE": cruise_throttle(cfg.vessel, speed),
            # after the last waypoint: keep station (LOITER) or hold, as the vessel computer's mission_done
            "MIS_DONE_BEHAVE": 1.0 if cfg.autopilot.mission_done == "loiter" else 0.0,
            "LOIT_RADIUS": float(cfg.autopilot.loiter_radius),
            "ATC_STR_RAT_MAX": round(math.degrees(rate), 1),
            "ATC_TURN_MAX_G": round(speed * rate / 9.80665, 3),
            # No on-board .BIN log: its writer thread runs on the wall clock (13 MB a harbour run), and
            # what it drops showed in SYS_STATUS, so two runs' tlogs differed. run.tlog is the record.
            "LOG_BACKEND_TYPE": 0.0}


def write_params(path: Path, params: dict[str, float]) -> None:
    path.write_text("".join(f"{k} {v:g}\n" for k, v in params.items()))


def _free(kind: int, port: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def mission_items(route_ned: np.ndarray, home: tuple[float, float], geo: LocalFrame) -> list[tuple[float, float]]:
    """(lat, lon) in degrees of each mission item: item 0 is home, then the route after its start."""
    pts = [home] + [(float(n), float(e)) for n, e in route_ned[1:]]
    return [geo.sea_level_to_geodetic(n, e) for n, e in pts]


@dataclass
class Mission:
    """ArduRover's set-up, step by step: upload the mission, arm, AUTO (simulated times in s)."""

    items: list[tuple[float, float]]
    fence: list[FenceItem] = field(default_factory=list)    # exclusion polygons' vertices (none: no fence)
    phase: str = "wait_heartbeat"      # -> fence (with one) -> upload -> arm -> auto -> flying (or failed)
    sent_at: float = -math.inf
    armed: bool = False
    mode: int = -1
    auto_at: float | None = None
    failure: str | None = None
    statustext: list[str] = field(default_factory=list)
    requests: int = 0
    fence_requests: int = 0


class ArduPilotRun:
    """One run of ArduRover on a scenario; :meth:`execute` returns the summary."""

    def __init__(self, opts: RunOptions, cfg: HilConfig, sitl: SitlFiles, user_params: Path | None = None,
                 fence: bool = False) -> None:
        from hil import scenario as scenarios
        from hil import settings
        from hil.hilrun import run_folder
        from hil.judging import Judge

        self.opts, self.sitl, self.user_params = opts, sitl, user_params
        self.scen = scenarios.load(opts.scenario, cfg.current, cfg.planner.safety_radius)
        # The simulator as `hil run` starts it on this scenario: the start and the scenario's current.
        over = [*opts.overrides, *scenarios.simulator_overrides(self.scen, cfg.current), f"sim.seed={opts.seed}"]
        self.cfg = settings.load(opts.config, over)
        self.out: Path = run_folder(opts)
        self.out.mkdir(parents=True, exist_ok=True)
        self.geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
        north, east, psi = map_to_ned(self.scen.start[0], self.scen.start[1], self.scen.start_heading)
        self.home = (north, east)
        self.home_heading_deg = math.degrees(psi) % 360.0
        # The mission: the global route; with the chart as fence, the route as the scenario gives it
        # (it may cross the chart: ArduRover's Dijkstra plans round its fence).
        given = self.scen.waypoints if fence and self.scen.waypoints is not None else self.scen.reference_path
        self.route = np.asarray(given, dtype=float)[:, ::-1]   # NED
        self.fence_polygons: list[np.ndarray] = []
        fence_items: list[FenceItem] = []
        if fence:
            from hil.ardupilot_fence import DIJKSTRA_MAX_POINTS, chart_polygons, dijkstra_points
            from hil.ardupilot_fence import fence_items as to_items

            try:
                self.fence_polygons = chart_polygons(self.scen.occ, self.scen.resolution)
            except ValueError as exc:   # more vertices than ArduRover stores
                raise UsageError(f"--ardupilot-fence: scenario {opts.scenario!r}: {exc}") from None
            if dijkstra_points(self.fence_polygons) > DIJKSTRA_MAX_POINTS:
                raise UsageError(f"scenario {opts.scenario!r}: its chart makes {dijkstra_points(self.fence_polygons)} "
                                 f"fence points, more than ArduRover's Dijkstra takes ({DIJKSTRA_MAX_POINTS})")
            fence_items = to_items(self.fence_polygons, self.geo)
        truth_occ = self.scen.truth_occ()
        self.judge = Judge(truth_occ, self.scen.resolution, cfg.vessel.L / 2.0,
                           (self.scen.goal[1], self.scen.goal[0]), cfg.autopilot.goal_tolerance)
        self.encounter_judge = None
        if self.scen.traffic:
            from hil.encounter_report import EncounterJudge

            self.encounter_judge = EncounterJudge(cfg.vessel.L, cfg.vessel.W, cfg.colregs)
        self.mission = Mission(mission_items(self.route, self.home, self.geo), fence_items)
        self.truth: dict[int, tuple[float, float, float, float]] = {}
        self.energy = 0.0
        self.min_clearance = math.inf
        self.outcome: str | None = None
        self.collision_at: float | None = None
        self.tlog_frames = 0
        self.events: list[str] = []

    # -- ArduRover ---------------------------------------------------------------------------------
    def sitl_command(self, instance: int, mav_port: int, param_file: Path) -> list[str]:
        lat, lon = self.geo.sea_level_to_geodetic(*self.home)
        files = (*self.sitl.param_files, param_file, *((self.user_params,) if self.user_params else ()))
        defaults = ",".join(str(p) for p in files)
        return [str(self.sitl.binary), "--model", "JSON:127.0.0.1", "--speedup", "100", "-I", str(instance), "-w",
                "--start-time", str(SITL_START_TIME),
                "--home", f"{lat:.9f},{lon:.9f},{self.cfg.geodesy.alt0:g},{self.home_heading_deg:.3f}",
                "--serial0", f"udpclient:127.0.0.1:{mav_port}", "--defaults", defaults]

    def execute(self) -> RunSummary:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink2

        from hil.assembly.simulator import simulator_settings
        from simulator.core import SimulatorCore
        from simulator.json_backend import JsonPhysics, SkidMixer

        cfg, opts = self.cfg, self.opts
        folder = self.out / "ardupilot"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        params = project_params(cfg)
        if self.mission.fence:
            from hil.ardupilot_fence import oa_params

            params.update(oa_params(float(cfg.planner.safety_radius), float(cfg.vessel.L) / 2.0))
        param_file = folder / "usv-hil.parm"
        write_params(param_file, params)
        try:
            mixer = SkidMixer.from_params({**read_params(self.sitl.param_files), **params,
                                           **(read_params((self.user_params,)) if self.user_params else {})})
        except ValueError as exc:
            raise UsageError(f"ArduRover parameters: {exc}") from None
        core = SimulatorCore(simulator_settings(cfg), None, tuple(self.scen.traffic or ()))
        self.core = core
        physics = JsonPhysics(core, mixer, self.home)
        physics.moored = True       # until ArduRover is armed in AUTO: its boot takes ~40 s of simulated time
        self.physics = physics
        self.mav = mavlink2.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        self.mav.robust_parsing = True
        self.mav_peer: tuple[str, int] | None = None
        self.ap_sysid = int(cfg.autopilot.system_id)
        instance, server = self._open_instance(physics)
        self.server = server
        self.tlog = open(self.out / "run.tlog", "wb")
        self.mav_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        proc: subprocess.Popen | None = None
        wall0 = time.monotonic()
        self.deadline = wall0 + opts.wall_timeout
        try:
            self.mav_sock.bind(("127.0.0.1", 0))
            self.mav_sock.setblocking(False)
            cmd = self.sitl_command(instance, self.mav_sock.getsockname()[1], param_file)
            (folder / "command.txt").write_text(" ".join(cmd) + "\n")
            with open(folder / "ardurover.log", "wb") as log:
                try:
                    proc = subprocess.Popen(cmd, cwd=folder, stdout=log, stderr=subprocess.STDOUT,
                                            start_new_session=True, preexec_fn=_die_with_parent)
                except OSError as exc:
                    raise UsageError(f"ArduRover SITL binary {self.sitl.binary} does not start: {exc}") from None
            opts.on_progress(f"run: ArduRover pid {proc.pid}, instance {instance}: JSON physics on UDP "
                             f"{JSON_PORT + 10 * instance}, ground stations on TCP {SERIAL0_PORT + 10 * instance + 2}")
            server.run()
        except KeyboardInterrupt:
            self.outcome = "interrupted"
        finally:
            server.close()
            if proc is not None:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            self.tlog.close()
            self.mav_sock.close()
        if self.outcome is None:
            if server.idle:
                cause = _last_line(folder / "ardurover.log")
                code = None if proc is None else proc.returncode
                raise RunFailed(f"ArduRover sent no servo packet for {IDLE_TIMEOUT_S:g} s (exit code "
                                f"{code}){': ' + cause if cause else ''} (see {folder / 'ardurover.log'})")
            self.outcome = "timeout"
        return self._summary(time.monotonic() - wall0, params, instance)

    def _open_instance(self, physics: JsonPhysics) -> tuple[int, JsonServer]:
        """The first SITL instance whose MAVLink TCP ports are free, with its JSON port bound here (a
        run beside this one then takes the next)."""
        from simulator.json_backend import JsonServer

        for i in INSTANCES:
            if not all(_free(socket.SOCK_STREAM, SERIAL0_PORT + 10 * i + k) for k in range(4)):
                continue
            try:
                return i, JsonServer(physics, ("127.0.0.1", JSON_PORT + 10 * i),
                                     duration=self.opts.duration + SETUP_TIMEOUT_S + 1.0,
                                     after_step=self._after_step, idle_timeout=IDLE_TIMEOUT_S)
            except ValueError:
                continue
        raise RunFailed(f"no free ArduPilot SITL instance (instances {INSTANCES.start}-{INSTANCES.stop - 1})")

    # -- between two physics steps ----------------------------------------------------------------
    def _after_step(self, core: SimulatorCore) -> None:
        t = core.t
        x, y, psi, u, v, r = core.state
        speed = math.hypot(u, v)
        p, s = core.controls
        self.energy += (abs(core.vessel.thrust(p)) + abs(core.vessel.thrust(s))) * speed * core.frame_dt
        if core.truth_due.due(core.n):
            self._judge(core, t, x, y, psi, u, v)
        if core.n % POLL_EVERY == 0:
            self._mavlink(t)
            if time.monotonic() > self.deadline:
                self.outcome = "wall_timeout"
            if self.outcome is not None:
                self.server.stop()

    def _judge(self, core: SimulatorCore, t: float, n: float, e: float, psi: float, u: float, v: float) -> None:
        c, s = math.cos(psi), math.sin(psi)
        vn, ve = u * c - v * s, u * s + v * c
        tu = core.time_usec
        self.truth[tu] = (n, e, vn, ve)
        lat, lon = self.geo.sea_level_to_geodetic(n, e)
        self._log(tu, core.codec.encode(
            "hil_state_quaternion", tu, [math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)], 0.0, 0.0, core.state[5],
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(self.cfg.geodesy.alt0 * 1000)),
            _i16(100 * vn), _i16(100 * ve), 0, 0, 0, 0, 0, 0))
        if core.traffic is not None:
            ts = self.traffic_time(t)
            for frame in core.traffic.truth_messages(ts, core.truth_codec):
                self._log(tu, frame)
            if self.encounter_judge is not None:
                for ship in core.traffic.ships:
                    st = ship.state(ts, core.traffic.params.turning_window)
                    sp = ship.spec
                    self.encounter_judge.add(tu, (n, e, psi), sp.mmsi, sp.name,
                                             (sp.bow, sp.stern, sp.port, sp.starboard),
                                             st.north, st.east, st.course, st.speed)
        if self.outcome is not None:
            return
        clearance = self.judge.clearance(n, e)
        self.min_clearance = min(self.min_clearance, clearance)
        if clearance < self.judge.hull_radius:
            self.outcome, self.collision_at = "collision", t
        elif self.encounter_judge is not None and self.encounter_judge.collision is not None:
            self.outcome, self.collision_at = "collision", self.encounter_judge.collision[0]
        elif self.opts.stop_at_goal and self.judge.at_goal(n, e):
            self.outcome = "goal"
        elif self.mission.auto_at is not None and t - self.mission.auto_at >= self.opts.duration:
            self.outcome = "timeout"    # --duration counts the mission, from AUTO
        if self.mission.phase not in ("flying", "failed") and t - (self.mission.auto_at or 0.0) > SETUP_TIMEOUT_S \
                and self.outcome is None:
            self.mission.failure = f"not in AUTO after {SETUP_TIMEOUT_S:g} s (phase {self.mission.phase})"
            self.outcome = "autopilot_not_ready"

    def traffic_time(self, t: float) -> float:
        """The ships' clock (s): they wait at their starts until the boat is let go, in AUTO, so the
        encounters happen as they do for the vessel computer, which leaves at once."""
        auto = self.mission.auto_at
        return 0.0 if auto is None else t - auto

    def _log(self, tu: int, frame: bytes) -> None:
        self.tlog.write(struct.pack(">Q", tu) + frame)
        self.tlog_frames += 1

    def _send(self, msg: MavMessage) -> None:
        if self.mav_peer is None:
            return
        frame = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.mav_sock.sendto(frame, self.mav_peer)
        self._log(self.core.time_usec, frame)

    def _mavlink(self, t: float) -> None:
        """Read what ArduRover sent since the last look and take the set-up's next step."""
        while True:
            try:
                data, sender = self.mav_sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                break
            if self.mav_peer is None:
                self.mav_peer = sender
            elif sender != self.mav_peer:
                continue
            try:
                msgs = self.mav.parse_buffer(data) or []
            except Exception:   # a malformed frame: pymavlink raises its own MAVError  # noqa: BLE001
                continue
            for m in msgs:
                if m.get_type() == "BAD_DATA" or m.get_srcSystem() != self.ap_sysid:
                    continue
                self._log(self.core.time_usec, bytes(m.get_msgbuf()))
                self._take(m, t)
        self._advance(t)

    def _take(self, m: MavMessage, t: float) -> None:
        ms, kind = self.mission, m.get_type()
        if kind == "HEARTBEAT" and m.get_srcComponent() == 1:
            ms.armed = bool(m.base_mode & 128)
            ms.mode = int(m.custom_mode)
            if ms.phase == "wait_heartbeat":
                ms.phase, ms.sent_at = "fence" if ms.fence else "upload", -math.inf
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and ms.phase == "fence" \
                and int(m.mission_type) == MISSION_TYPE_FENCE:
            seq = int(m.seq)
            if 0 <= seq < len(ms.fence):
                ms.fence_requests += 1
                f = ms.fence[seq]
                self._send(self.mav.mission_item_int_encode(
                    self.ap_sysid, 1, seq, 0, FENCE_VERTEX_EXCLUSION, 0, 1, float(f.vertices), 0.0, 0.0, 0.0,
                    int(round(f.lat * 1e7)), int(round(f.lon * 1e7)), 0.0, MISSION_TYPE_FENCE))
                ms.sent_at = t
        elif kind == "MISSION_ACK" and ms.phase == "fence" and int(m.mission_type) == MISSION_TYPE_FENCE:
            if int(m.type) == 0:
                ms.phase, ms.sent_at, ms.failure = "upload", -math.inf, None
                self.events.append(f"{t:.1f} s: fence of {len(ms.fence)} vertices accepted")
            else:
                ms.failure, ms.sent_at = f"ArduRover refused the fence (MAV_MISSION_RESULT {m.type})", t
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and ms.phase == "upload" \
                and int(m.mission_type) == 0:
            seq = int(m.seq)
            if 0 <= seq < len(ms.items):
                ms.requests += 1
                lat, lon = ms.items[seq]
                self._send(self.mav.mission_item_int_encode(
                    self.ap_sysid, 1, seq, 3, 16, 0, 1, 0.0, 0.0, 0.0, 0.0,
                    int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0, 0))
                ms.sent_at = t
        elif kind == "MISSION_ACK" and ms.phase == "upload" and int(m.mission_type) == 0:
            if int(m.type) == 0:
                ms.phase, ms.sent_at, ms.failure = "arm", -math.inf, None
                self.events.append(f"{t:.1f} s: mission of {len(ms.items) - 1} waypoints accepted")
            else:   # e.g. its mission storage not ready yet ("Only 0 items are supported"): again in 2 s
                ms.failure, ms.sent_at = f"ArduRover refused the mission (MAV_MISSION_RESULT {m.type})", t
        elif kind == "STATUSTEXT":
            text = m.text if isinstance(m.text, str) else m.text.decode(errors="replace")
            text = text.rstrip("\x00")
            if len(ms.statustext) < 200:
                ms.statustext.append(f"{t:.1f} s: {text}")

    def _advance(self, t: float) -> None:
        ms = self.mission
        if ms.phase == "fence" and t - ms.sent_at > 2.0:
            self._send(self.mav.mission_count_encode(self.ap_sysid, 1, len(ms.fence), MISSION_TYPE_FENCE))
            ms.sent_at = t
        elif ms.phase == "upload" and t - ms.sent_at > 2.0:
            self._send(self.mav.mission_count_encode(self.ap_sysid, 1, len(ms.items), 0))
            ms.sent_at = t
        elif ms.phase in ("arm", "auto") and t - ms.sent_at > 1.0:
            if ms.armed and ms.mode == ROVER_AUTO:
                ms.phase, ms.auto_at = "flying", t
                self.physics.moored = False
                self.events.append(f"{t:.1f} s: armed, AUTO")
                return
            if ms.mode != ROVER_AUTO:
                self._send(self.mav.command_long_encode(self.ap_sysid, 1, 176, 0, 1, ROVER_AUTO, 0, 0, 0, 0, 0))
            elif not ms.armed:
                self._send(self.mav.command_long_encode(self.ap_sysid, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            ms.phase, ms.sent_at = "auto", t
        if self.mav_peer is not None and round(t * 10) % 10 == 0:   # a GCS heartbeat each simulated second
            self._send(self.mav.heartbeat_encode(6, 8, 0, 0, 4))

    # -- the summary -------------------------------------------------------------------------------
    def _summary(self, wall: float, params: dict[str, float], instance: int) -> RunSummary:
        from hil.run_summary import RunSecurity, RunSummary

        times = sorted(self.truth)
        track = np.array([self.truth[t][:2] for t in times]) if times else np.zeros((0, 2))
        length = float(np.sum(np.hypot(*np.diff(track, axis=0).T))) if len(track) > 1 else 0.0
        reached = self.outcome == "goal" and self.collision_at is None
        encounters = traffic = None
        if self.encounter_judge is not None:
            from hil.encounter_report import totals
            from hil.judging import ship_collision
            from hil.run_summary import RunTraffic

            enc = self.encounter_judge.report(self.truth)
            encounters = tuple(enc)
            traffic = RunTraffic(**totals(enc), ship_collision=ship_collision(self.encounter_judge))
        ms, physics = self.mission, self.physics
        xte = route_cross_track(track, self.route)
        return RunSummary(
            scenario=self.opts.scenario, seed=self.opts.seed, mode="lockstep", outcome=self.outcome or "timeout",
            reached_goal=reached, collisions=0 if self.collision_at is None else 1,
            collision_time_s=self.collision_at,
            min_clearance_m=None if not math.isfinite(self.min_clearance) else round(self.min_clearance, 3),
            sim_time_s=round(times[-1] * 1e-6, 3) if times else 0.0, wall_time_s=round(wall, 2),
            path_length_m=round(length, 2), energy_J=round(self.energy, 1),
            planning_cycles=None, plans_accepted=None, deadline_overruns=None, worker_restarts=None,
            fallback_activations=None, tracking=xte, navigation_rmse_m=None, control_latency_ms=None,
            simulator_restarts=0, navigation=None, sensed_obstacles=None,
            simulator=ArduPilotSimulatorSection(
                packets=physics.packets, repeats=physics.repeats, malformed=physics.malformed, steps=physics.core.n,
                frame_rate_hz=physics.frame_rate, wrong_peer=self.server.wrong_peer,
                ardupilot=ArduRoverSetup(
                    binary=str(self.sitl.binary), instance=instance, params=params, auto_at_s=ms.auto_at,
                    mission_items=len(ms.items),
                    fence=FenceUpload(polygons=len(self.fence_polygons), vertices=len(ms.fence),
                                      requests=ms.fence_requests) if ms.fence else None,
                    mission_time_s=None if ms.auto_at is None or not times else round(times[-1] * 1e-6 - ms.auto_at, 3),
                    setup_failure=ms.failure, statustext=ms.statustext[-20:])),
            security=RunSecurity(simulator=None, autopilot=None, autopilot_navigation_numeric={}, tap=None),
            tlog=str(self.out / "run.tlog"), tlog_messages=self.tlog_frames, events=tuple(self.events),
            actuators="ardupilot", encounters=encounters, traffic=traffic)


def route_cross_track(track: np.ndarray, route: np.ndarray) -> TrackingSummary | None:
    """RMS and largest distance (m) of each track point (N, 2) from the route polyline (M, 2)."""
    if len(track) == 0 or len(route) < 2:
        return None
    a, b = route[:-1], route[1:]
    ab = b - a
    den = np.maximum(np.sum(ab * ab, axis=1), 1e-12)
    p = track[:, None, :]
    w = np.clip(np.sum((p - a) * ab, axis=2) / den, 0.0, 1.0)
    d = np.min(np.hypot(*(p - (a + w[..., None] * ab)).transpose(2, 0, 1)), axis=1)
    return TrackingSummary(frames=len(track), cross_track_rms_m=round(float(np.sqrt(np.mean(d * d))), 3),
                           cross_track_max_m=round(float(d.max()), 3))


def _die_with_parent() -> None:
    """In ArduRover's process before it starts (Linux): SIGKILL when this process ends, however it ends.
    Its own session keeps a terminal's Ctrl-C from it (this process ends it, after the summary), but a
    `hil` killed outright left it running for good: it waits for the physics' answer in lockstep, so
    its SIGTERM handler, which exits from its main loop, never runs."""
    import ctypes
    import signal
    import sys

    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))   # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _i16(v: float) -> int:
    return max(-32768, min(32767, int(round(v))))


def _last_line(path: Path) -> str:
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip() and "No JSON" not in ln]
    except OSError:
        return ""
    return lines[-1].strip()[:200] if lines else ""


def run_ardupilot(opts: RunOptions, cfg: HilConfig, sitl: SitlFiles, user_params: str | None = None,
                  fence: bool = False) -> RunSummary:
    """`hil run --autopilot ardupilot`: the run folder (run.tlog, summary.json, plot.png, ardupilot/).
    ``user_params``: an ArduPilot parameter file laid over all others (the user's own tuning).
    ``fence``: the chart as ArduRover's exclusion fence, planned round by its Dijkstra (OA_TYPE 2),
    and the scenario's route as given (not the global route) as its mission."""
    from common.tables import to_table
    from hil.files import write_json_atomic

    extra = Path(user_params).expanduser().resolve() if user_params else None
    run = ArduPilotRun(opts, cfg, sitl, extra, fence)
    out = run.out
    summary = run.execute()
    summary = replace(summary, run_folder=str(out))
    if opts.plot:
        try:
            from hil.run_plot import plot_run

            plot_run(out / "plot.png", run.scen, run.truth, None, run.cfg,
                     ships=run.encounter_judge.ships if run.encounter_judge is not None else None,
                     encounters=summary.encounters,
                     outcome="ArduRover: " + ("goal reached" if summary.reached_goal else summary.outcome))
            summary = replace(summary, plot=str(out / "plot.png"))
        except Exception as exc:  # a plot must never lose the run's data  # noqa: BLE001
            summary = replace(summary, plot_error=f"{type(exc).__name__}: {exc}")
    write_json_atomic(out / "summary.json", to_table(summary))
    return summary
