"""The whole HIL loop: the simulator and the vessel computer as two OS processes linked by UDP.

`hil run` starts ``python -m hil sim`` and ``python -m hil autopilot`` as subprocesses on loopback
ports chosen here, and listens on a third port as a *tap*: the simulator sends its frames to the
autopilot and the tap, the autopilot sends its commands to the simulator and the tap, and its
telemetry to the tap. The tap writes every MAVLink frame to the run's ``.tlog``; the run is judged
from its truth (HIL_STATE_QUATERNION) by :mod:`hil.judging`: collisions and clearance against the
chart, the goal, path length, energy, and the navigation error of the autopilot's own estimate
(LOCAL_POSITION_NED). This module supervises: processes, tap, loop. The run ends when the vessel
reaches the goal, collides, or the simulated time is up; both processes are then stopped with
SIGTERM (their summaries are collected), also on Ctrl-C, and never left behind.

Each end takes only its peer (docs/security.md): the simulator takes commands only from the
autopilot's socket (``--commands-from``), the autopilot sensor frames only from the simulator's
(``--sensors-from``), and the tap takes the truth only from the simulator's socket, commands
only from the autopilot's, and nothing from any other socket than those two and the autopilot's
telemetry copies (``--telemetry-from``); what it refuses is counted (``security.tap`` of
summary.json) and not written to the .tlog.
"""

from __future__ import annotations

import errno
import gc
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import numpy as np

from common.frames import map_to_ned
from common.geodesy import LocalFrame
from common.readiness import GO, ReadyWait
from common.tables import to_table
from hil import config, placement, processes
from hil import scenario as scenarios
from hil.errors import RunFailed, UsageError
from hil.judging import Judge, RunRecord, summarise
from hil.progress_watch import STALL_WINDOW_S, ProgressWatch
from hil.routing import RouteRequest, planned_route, write_route
from hil.run_summary import RunSummary, read_autopilot_summary
from hil.tap import Tap

if TYPE_CHECKING:
    from hil.can_log import CanLogSummary, CanRecorder
    from hil.settings import HilConfig

REPO = Path(__file__).resolve().parent.parent


def free_udp_port() -> int:
    """A free UDP port on 127.0.0.1, reserved host-wide so that parallel runs never share it
    (:mod:`hil.ports`; :meth:`HilRun.execute` releases a run's ports when it ends)."""
    from hil.ports import reserve_udp_port

    return reserve_udp_port()


def startup_error(log: Path) -> str:
    """The one-line error a child process printed before exiting (``hil ...: error: ...``), or ''."""
    try:
        lines = log.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    for line in reversed(lines):
        head, sep, rest = line.partition(": error: ")
        if sep and head.startswith("hil "):
            return rest.strip()
    return lines[-1].strip() if lines else ""


LOCKSTEP_TAP_PERIOD_S = 0.01  # wall seconds between the tap's reads in lockstep

# Summary keys whose values depend on the wall clock or on the host, not on the seed: what two
# lockstep runs of the same seed may differ in. Counters read when the processes are stopped
# (after the deciding sample, until the SIGTERM arrives), latencies, paths, and warnings about
# other runs on this host (a system id in use).
WALL_CLOCK_KEYS = frozenset({"wall_time_s", "control_latency_ms", "run_folder", "tlog", "plot", "simulator",
                             "tlog_messages", "navigation", "gcs", "sensed_obstacles", "security", "warnings",
                             "current"})

# Campaigns (Monte Carlo) run many loops at once and nobody watches them: they open no ground-station link.
NO_GCS = ["gcs.endpoints=[]"]


@dataclass
class RunOptions:
    scenario: str = "harbour"
    lockstep: bool = True
    speedup: float = 1.0
    duration: float = 300.0              # s of simulated time at most
    seed: int = 1
    config: str | tuple[str, ...] | None = None   # --config file(s), laid over the defaults in order
    overrides: list[str] = field(default_factory=list)
    out: Path | None = None              # run folder
    wall_timeout: float = 900.0          # s, whatever happens
    actuators: str = "mavlink"
    extra_autopilot_args: list[str] = field(default_factory=list)
    extra_sim_overrides: list[str] = field(default_factory=list)
    extra_sim_args: list[str] = field(default_factory=list)
    stop_at_goal: bool = True            # hil soak: keep running after the goal until the time is up
    on_progress: Callable[[str], None] = lambda _m: None
    plot: bool = True
    hooks: list[Callable[[Tap, HilRun], None]] = field(default_factory=list)  # tests: fault injection
    traffic: tuple | None = None         # ships replacing the scenario's [[traffic]] (Monte Carlo draws)
    # CPUs of the processes (hil.placement): "auto" places a lockstep run on a pair of CPUs no other
    # run holds, "off" never; campaigns, which run several loops at once, say "off".
    cpus: str | placement.Placement = "auto"
    # lockstep: wall seconds per progress check (hil.progress_watch); None: the larger of STALL_WINDOW_S and
    # twice autopilot.lockstep_planner_timeout
    stall_window_s: float | None = None

    def __post_init__(self) -> None:
        # The children run in the repository (cwd=REPO): files the user named relative to where
        # they stand must be absolute before they travel on a child's command line.
        if Path(self.scenario).suffix == ".toml":
            self.scenario = str(Path(self.scenario).resolve())
        if self.config is not None:
            self.config = tuple(str(Path(p).resolve()) for p in config.config_files(self.config))
    # hil run: Ctrl-C/SIGTERM end the run with outcome "interrupted" and its folder written (a GCS session
    # with --wait-for-arm ends that way); elsewhere (Monte Carlo, soak) the interrupt propagates.
    summary_on_interrupt: bool = False


def gcs_endpoints_in_effect(configured: Sequence[str], autopilot_args: Sequence[str]) -> list[str]:
    """The ground-station endpoints the vessel computer will open: the ``--gcs`` values among its
    arguments when there are any (``none`` alone: the link off), else the configured ones."""
    given = [autopilot_args[i + 1] for i, a in enumerate(autopilot_args[:-1]) if a == "--gcs"]
    if not given:
        return list(configured)
    return [e for e in given if e != "none"]


class HilRun:
    """One run: processes, tap, judge; :meth:`execute` returns the summary."""

    def __init__(self, opts: RunOptions, cfg: HilConfig) -> None:
        self.opts, self.cfg = opts, cfg
        self.scen = scenarios.load(opts.scenario, cfg.current, cfg.planner.safety_radius, cfg.geodesy)
        self.scen.check_current_time(float(opts.duration))
        # The global route, planned before any process starts: a waypoint it cannot reach is a one-line error.
        # Planned once per run: the vessel computer takes it from route.json (hil.routing.PlannedRoute).
        request = self.scen.route if isinstance(self.scen.route, RouteRequest) else None
        self.route = self.scen.reference_path
        if opts.traffic is not None:
            self.scen.traffic = tuple(opts.traffic)
        self.out: Path = run_folder(opts)
        self.out.mkdir(parents=True, exist_ok=True)
        self.route_file: Path | None = None
        if request is not None:
            self.route_file = self.out / "route.json"
            write_route(self.route_file, planned_route(request, self.route))
            opts.on_progress(f"run: planned the global route through {len(request.waypoints)} waypoints "
                             f"({len(self.route)} points); the vessel computer takes it from {self.route_file}")
        # A reused run folder: the processes' logs of this run start empty (_spawn), and the logs
        # of an earlier run's simulator restarts, which this run may not have, go.
        for stale in self.out.glob("sim-restart*.log"):
            stale.unlink(missing_ok=True)
        self.geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
        from hil.encounter_report import EncounterJudge

        self.encounter_judge = (EncounterJudge(cfg.vessel.L, cfg.vessel.W, cfg.colregs, route=self.route)
                                if self.scen.traffic else None)
        self.tap = Tap(self.out / "run.tlog", self.geo, self.encounter_judge, cfg.traffic.truth_component_id,
                       cfg.link.component_id, lockstep=opts.lockstep, private=bool(cfg.gcs.signing_key_file))
        goal_ned = (self.scen.goal[1], self.scen.goal[0])
        # The truth: the chart plus the obstacles it lacks; the simulator's range sensor scans it.
        truth_occ = self.scen.truth_occ()
        self.world_file = self.out / "world.npz"
        np.savez_compressed(self.world_file, occ=truth_occ, resolution=self.scen.resolution)
        self.judge = Judge(truth_occ, self.scen.resolution, cfg.vessel.L / 2.0, goal_ned,
                           cfg.autopilot.goal_tolerance)
        self.traffic_file: Path | None = None
        if self.scen.traffic:  # the simulator sails the scenario's ships (or a Monte Carlo draw of them)
            from hil.config import to_table

            self.traffic_file = self.out / "traffic.json"
            self.traffic_file.write_text(json.dumps([to_table(s) for s in self.scen.traffic], indent=1))
        self.ap_port = free_udp_port()
        self.sim_port = free_udp_port()
        self.telemetry_port = free_udp_port()   # the autopilot's copies of its ground-station traffic leave from here
        self.tap.sim_addr, self.tap.ap_addr = ("127.0.0.1", self.sim_port), ("127.0.0.1", self.ap_port)
        self.tap.telemetry_addr = ("127.0.0.1", self.telemetry_port)
        self.tap.sim_ids = (cfg.link.system_id, cfg.link.component_id)
        self.warnings: list[str] = []
        self._sysid_lock: TextIO | None = None
        self.sim: subprocess.Popen | None = None
        self.ap: subprocess.Popen | None = None
        self.sim_restarts = 0
        self.can_recorder: CanRecorder | None = None  # when the thrusters are on CAN
        self.can_log: CanLogSummary | None = None
        self.placement: placement.Placement | None = None
        self._cpu_claim: placement.Claim | None = None
        self.pinned: dict[str, int] = {}          # role -> CPU, what the placement pinned
        self._own_cpus: set[int] | None = None    # this process's CPUs before the placement

    # -- processes ---------------------------------------------------------------------------------
    def _common_args(self) -> list[str]:
        args = []
        args += config.config_args(self.opts.config)
        for o in self.opts.overrides:
            args += ["--set", o]
        return args

    def sim_command(self, initial: tuple[float, float, float] | None = None) -> list[str]:
        s = self.scen
        north, east, psi = map_to_ned(s.start[0], s.start[1], s.start_heading) if initial is None else initial
        cur = self.scen.current
        args = [sys.executable, "-m", "hil", "sim", *self._common_args(),
                "--state-to", f"127.0.0.1:{self.ap_port}", "--state-to", f"127.0.0.1:{self.tap.port}",
                "--commands-on", f"127.0.0.1:{self.sim_port}", "--commands-from", f"127.0.0.1:{self.ap_port}",
                "--seed", str(self.opts.seed),
                "--duration", repr(float(self.opts.duration) + 5.0), "--json", "--world", str(self.world_file),
                "--set", f"sim.initial.x={north!r}", "--set", f"sim.initial.y={east!r}",
                "--set", f"sim.initial.psi={psi!r}"]
        for k in ("enabled", "origin_x", "origin_y", "file", "uniform", "east_variable", "north_variable",
                  "start_time", "reach"):
            v = getattr(cur, k)
            args += ["--set", f"current.{k}={json.dumps(v)}"]
        if self.traffic_file is not None:
            args += ["--traffic", str(self.traffic_file)]
        for o in self.opts.extra_sim_overrides:
            args += ["--set", o]
        args += self.opts.extra_sim_args
        if self.opts.lockstep:
            args.append("--lockstep")
        else:
            args += ["--speedup", repr(float(self.opts.speedup))]
        return args

    def autopilot_command(self) -> list[str]:
        args = [sys.executable, "-m", "hil", "autopilot", *self._common_args(), "--scenario", self.opts.scenario,
                "--listen", f"127.0.0.1:{self.ap_port}", "--sensors-from", f"127.0.0.1:{self.sim_port}",
                "--actuators-to", f"127.0.0.1:{self.sim_port}", "--actuators-to", f"127.0.0.1:{self.tap.port}",
                "--telemetry-to", f"127.0.0.1:{self.tap.port}", "--telemetry-from", f"127.0.0.1:{self.telemetry_port}",
                "--seed", str(self.opts.seed), "--summary-out", str(self.out / "autopilot.json"), "--json",
                *(["--route", str(self.route_file)] if self.route_file is not None else []),
                *self.opts.extra_autopilot_args]
        if self.opts.lockstep:
            args.append("--lockstep")
        return args

    def _spawn(self, cmd: list[str], name: str, pass_fds: tuple[int, ...] = ()) -> subprocess.Popen:
        log = open(self.out / f"{name}.log", "wb")  # one process per name in a run
        return processes.start(cmd, stdout=subprocess.PIPE, stderr=log, cwd=REPO, start_new_session=True,
                               pass_fds=pass_fds)

    def start(self, ready_timeout: float = 180.0) -> None:
        """Both processes at once (their imports and set-up overlap on two cores), the simulator told
        to send its first frame only once the autopilot is listening (its start-up may include
        compiling the planner core), so that no frame is sent into the void."""
        if self.cfg.can.actuators == "can" and self.cfg.can.log:
            from hil.can_log import CanRecorder

            try:
                self.can_recorder = CanRecorder(self.cfg.can, self.out / "can.log")
            except ValueError as exc:
                raise UsageError(str(exc)) from None
        # Readiness comes on a pipe (common/readiness.py): one JSON line once the autopilot serves.
        read_end, write_end = os.pipe()
        go_read, go_write = os.pipe()
        waiting = False   # the wait owns (and closes) read_end
        try:
            try:
                self.ap = ap = self._spawn([*self.autopilot_command(), "--ready-fd", str(write_end)], "autopilot",
                                           pass_fds=(write_end,))
                self.sim = self._spawn([*self.sim_command(), "--start-fd", str(go_read)], "sim",
                                       pass_fds=(go_read,))
            finally:
                os.close(write_end)  # the children hold their own copies
                os.close(go_read)
            waiting = True
            self._wait_for_autopilot(ap, read_end, ready_timeout)
            self._place()   # the planner worker exists now; the simulator waits for GO
            try:
                os.write(go_write, GO)
            except BrokenPipeError:
                pass  # the simulator died meanwhile: the run's loop finds it exited and says why
        finally:
            os.close(go_write)  # without GO: the simulator exits without running
            if not waiting:
                os.close(read_end)  # a spawn failed

    def _place(self) -> None:
        if self.sim is None or self.ap is None:
            return
        self._cpu_claim = placement.claim(self.opts.cpus, self.opts.lockstep)
        if self._cpu_claim is None:
            return
        self.placement = self._cpu_claim.placement
        self._own_cpus = os.sched_getaffinity(0)
        self.pinned = placement.apply(self.placement, self.sim.pid, self.ap.pid)

    def _unplace(self) -> None:
        """This process gets back the CPUs it had (a process that runs one run after another, a
        test or a campaign's worker, starts the next one from where it began), and the CPUs' locks go."""
        if self._own_cpus is not None:
            placement.pin(os.getpid(), self._own_cpus)
            self._own_cpus = None
        if self._cpu_claim is not None:
            self._cpu_claim.release()
            self._cpu_claim = None

    def _wait_for_autopilot(self, ap: subprocess.Popen, read_end: int, ready_timeout: float) -> None:
        log = self.out / "autopilot.log"
        deadline = time.monotonic() + ready_timeout
        wait = ReadyWait(read_end)
        try:
            while True:
                try:
                    if wait.poll(timeout=0.05) is not None:
                        break
                except ValueError as exc:
                    raise RunFailed(f"the autopilot's start-up: {exc} (see {log})") from None
                if wait.eof or ap.poll() is not None:
                    try:
                        ap.wait(timeout=5.0)   # end of file: it is exiting
                    except subprocess.TimeoutExpired:
                        raise RunFailed(f"the autopilot closed its readiness pipe without being ready (see {log})") \
                            from None
                    cause = startup_error(log)
                    if ap.returncode == 2 and cause:  # a user mistake (a busy port ...): say which, exit 2
                        raise UsageError(f"the autopilot could not start: {cause}")
                    raise RunFailed(f"the autopilot exited during start-up{': ' + cause if cause else ''} (see {log})")
                if _exited(self.sim):
                    self._simulator_start_failed()
                if time.monotonic() > deadline:
                    raise _NotReady(f"the autopilot was not ready after {ready_timeout:g} s (see {log})")
                self.tap.pump(timeout=0.0)
        finally:
            wait.close()

    def _simulator_start_failed(self) -> None:
        """The simulator exited before its first frame: its one-line reason (a user mistake: exit 2)."""
        sim_log = self.out / "sim.log"
        cause = startup_error(sim_log)
        if self.sim is not None and self.sim.returncode == 2 and cause:
            raise UsageError(f"the simulator could not start: {cause}")
        raise RunFailed(f"the simulator exited during start-up{': ' + cause if cause else ''} (see {sim_log})")

    def restart_simulator(self) -> None:
        """Kill the simulator and start it again where the truth last was (fault injection)."""
        last = self.tap.truth[max(self.tap.truth)] if self.tap.truth else None
        self._stop(self.sim, kill=True)
        self.sim_restarts += 1
        initial = None
        if last is not None:
            initial = (last[0], last[1], math.atan2(last[3], last[2]) if math.hypot(last[2], last[3]) > 0.2 else 0.0)
        self.sim = self._spawn(self.sim_command(initial), f"sim-restart{self.sim_restarts}")
        if self.placement is not None:
            placement.pin(self.sim.pid, self.placement.simulator)

    def claim_system_id(self) -> None:
        """Warn when another `hil run` on this machine streams to ground stations with the same
        system id (they would show one vehicle jumping between two boats). A run whose ground-station
        link is off (``--gcs none``) streams to nobody and claims nothing."""
        if not gcs_endpoints_in_effect(self.cfg.gcs.endpoints, self.opts.extra_autopilot_args):
            return
        import fcntl

        sysid = self.cfg.autopilot.system_id
        path = Path(tempfile.gettempdir()) / f"usv-hil-sysid-{sysid}.lock"
        try:
            fh = open(path, "a")
        except OSError:
            return
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            self._sysid_lock = fh
        except OSError:
            fh.close()
            msg = (f"another hil run streams to ground stations with system id {sysid}; give this one "
                   f"another (--set autopilot.system_id=N) or ground stations see one vehicle for two boats")
            self.warnings.append(msg)
            self.opts.on_progress("warning: " + msg)

    @staticmethod
    def _stop(proc: subprocess.Popen | None, kill: bool = False) -> object | None:
        """Stop ``proc``'s process group; its last stdout line parsed as JSON (its summary, not yet read
        strictly: :mod:`hil.judging` does), or None."""
        if proc is None:
            return None
        dead = proc.poll() is not None
        try:
            # The whole process group, also when its leader is already dead: a SIGKILLed autopilot
            # leaves its planner worker behind, holding the stdout pipe open.
            os.killpg(proc.pid, signal.SIGKILL if (kill or dead) else signal.SIGTERM)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            out, _ = proc.communicate(timeout=1.0 if dead else 20.0)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            try:
                out, _ = proc.communicate(timeout=1.0)
            except subprocess.TimeoutExpired:  # a grandchild outside the group holds the pipe
                proc.kill()
                out = b""
        if kill:
            return None
        lines = (out or b"").decode(errors="replace").strip().splitlines()
        try:
            return json.loads(lines[-1]) if lines else None
        except json.JSONDecodeError:
            return None

    # -- the run -----------------------------------------------------------------------------------
    def execute(self) -> RunSummary:
        opts = self.opts
        wall0 = time.monotonic()
        outcome, collision_at = "timeout", None
        min_clearance, last_report = math.inf, wall0
        decided: int | None = None  # truth time (usec) of the sample that decided the outcome
        try:
            self.claim_system_id()
            try:
                self.start(ready_timeout=min(180.0, max(0.0, opts.wall_timeout)))
            except _NotReady:
                if opts.wall_timeout >= 180.0:
                    raise
                raise _WallTimeout() from None
            checked = 0
            window = opts.stall_window_s or max(STALL_WINDOW_S, 2.0 * self.cfg.autopilot.lockstep_planner_timeout)
            watch = ProgressWatch(window) if opts.lockstep else None
            processes.freeze_heap()   # unfrozen in the finally below: a campaign's runs share this process
            while True:
                if opts.lockstep:
                    # Read in batches: a tap woken by every datagram (three a step) took the cores from
                    # the two busy-polling processes (docs/performance.md). Its .tlog stamps are
                    # simulated time in lockstep, so batching changes nothing it records.
                    time.sleep(LOCKSTEP_TAP_PERIOD_S)
                    self.tap.pump(timeout=0.0)
                else:
                    self.tap.pump(timeout=0.05)
                # The tap keeps the truth's times sorted: sorting all of them on every pass cost 0.06 ms
                # at the end of a 3-minute run (8,450 samples) and 1.8 ms after an hour's soak.
                times = self.tap.truth_times
                # Sample by sample, so the deciding sample does not depend on how datagrams were batched.
                for tu in times[checked:]:
                    n, e, _, _ = self.tap.truth[tu]
                    c = self.judge.clearance(n, e)
                    min_clearance = min(min_clearance, c)
                    if c < self.judge.hull_radius:
                        outcome, collision_at, decided = "collision", tu * 1e-6, tu
                    elif opts.stop_at_goal and self.judge.at_goal(n, e):
                        outcome, decided = "goal", tu
                    elif tu * 1e-6 >= opts.duration:
                        outcome, decided = "timeout", tu
                    if decided is not None:
                        break
                checked = len(times)
                t_sim = times[-1] * 1e-6 if times else 0.0
                if decided is None and self.encounter_judge is not None and self.encounter_judge.collision:
                    collision_at = self.encounter_judge.collision[0]
                    outcome, decided = "collision", int(round(collision_at * 1e6))
                if decided is not None:
                    break
                if time.monotonic() - wall0 > opts.wall_timeout:
                    outcome = "wall_timeout"
                    break
                stalled = watch.check(time.monotonic(), t_sim) if watch is not None else None
                if stalled is not None:
                    opts.on_progress(f"run: {stalled}")
                    outcome = "stalled"
                    break
                if self.tap.write_error is not None:
                    outcome = "disk_full" if self.tap.write_error.errno in (errno.ENOSPC, errno.EDQUOT) \
                        else "write_error"
                    break
                if _exited(self.ap):
                    outcome = "autopilot_exited"
                    break
                if _exited(self.sim):
                    self.tap.pump(timeout=0.0)
                    if not self.tap.truth and not self.sim_restarts:
                        self._simulator_start_failed()  # it never sent a frame: why, in one line
                    outcome = "simulator_exited"
                    break
                for hook in opts.hooks:
                    hook(self.tap, self)
                if time.monotonic() - last_report > 5.0:
                    last_report = time.monotonic()
                    opts.on_progress(f"run: t={t_sim:.1f} s simulated, {time.monotonic() - wall0:.1f} s wall, "
                                     f"clearance min {min_clearance:.2f} m")
        except _WallTimeout:
            outcome = "wall_timeout"
        except KeyboardInterrupt:
            if not opts.summary_on_interrupt:
                raise
            outcome = "interrupted"
        finally:
            gc.unfreeze()
            if self._sysid_lock is not None:
                self._sysid_lock.close()
            self._unplace()
            # The autopilot first, so that the simulator receives every command it sent (the CAN
            # counters of both sides must agree); in real time the simulator may meanwhile count a
            # stale-command failsafe after the run's end: the summary counts those apart.
            ap_summary = self._stop(self.ap)
            sim_summary = self._stop(self.sim)
            self.tap.pump(timeout=0.0)
            self.tap.counters_at_close = self.tap.counters()
            self.tap.close()
            from hil.ports import release

            release(self.ap_port, self.sim_port)
            if self.can_recorder is not None:
                self.can_log = self.can_recorder.close()
        wall = time.monotonic() - wall0
        run = RunRecord(
            scenario=self.opts.scenario, seed=self.opts.seed, lockstep=self.opts.lockstep, speedup=self.opts.speedup,
            outcome=outcome, collision_at=collision_at, min_clearance=min_clearance, wall_s=wall, decided=decided,
            autopilot=ap_summary, simulator=sim_summary, simulator_restarts=self.sim_restarts, pinned=self.pinned,
            warnings=tuple(self.warnings), can_log=self.can_log, tlog=self.out / "run.tlog")
        return summarise(run, self.tap, self.cfg, self.encounter_judge)

class _NotReady(RunFailed):
    """The autopilot did not start listening in time."""


class _WallTimeout(Exception):
    """--wall-timeout passed before the run started."""


def run_folder(opts: RunOptions) -> Path:
    """The run's folder: every run writes one (RunOptions.out is optional only in its dataclass order)."""
    if opts.out is None:
        raise ValueError("RunOptions.out: a run needs a folder to write")
    return opts.out


def _exited(proc: subprocess.Popen | None) -> bool:
    """True when the process is not running (never started, or ended)."""
    return proc is None or proc.poll() is not None


def _disk_full(out: Path, exc: OSError) -> RunFailed:
    return RunFailed(f"run folder {out}: {exc.strerror or exc} (errno {exc.errno}); the run was stopped, "
                     f"nothing complete was written")


def _remove_partial(out: Path, names: tuple[str, ...] = ("summary.json", "plot.png", "world.npz")) -> None:
    """After a write failure: remove temporary files and half-written outputs of the run folder."""
    for p in list(out.glob(".*.tmp")) + [out / n for n in names]:
        try:
            p.unlink()
        except OSError:
            pass


def run_loop(opts: RunOptions, cfg: HilConfig) -> RunSummary:
    """Run the HIL loop and write the run folder (tlog, summary.json, plot.png); returns the summary.

    A folder that cannot be written (a full disk) ends the run with one line (RunFailed, exit 1)
    and no temporary files left behind."""
    if not scenarios.scenario_path(opts.scenario).exists():
        raise UsageError(f"unknown scenario {opts.scenario!r} (available: {', '.join(scenarios.available())})")
    try:
        return _run_loop(opts, cfg)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO):
            raise
        _remove_partial(run_folder(opts))
        raise _disk_full(run_folder(opts), exc) from None


def _run_loop(opts: RunOptions, cfg: HilConfig) -> RunSummary:
    from hil.files import write_json_atomic

    run = HilRun(opts, cfg)
    out = run.out
    summary = run.execute()
    if run.tap.write_error is not None:
        raise run.tap.write_error
    summary = replace(summary, run_folder=str(out))
    if opts.plot:
        try:
            from hil.run_plot import plot_run

            ap_path = out / "autopilot.json"
            ap = read_autopilot_summary(json.loads(ap_path.read_text()), str(ap_path)) if ap_path.exists() else None
            plot_run(out / "plot.png", run.scen, run.tap.truth, ap, cfg,
                     ships=run.encounter_judge.ships if run.encounter_judge is not None else None,
                     encounters=summary.encounters,
                     outcome="goal reached" if summary.reached_goal else
                     f"{summary.outcome}" + (f" at {summary.collision_time_s:.1f} s"
                                             if summary.collision_time_s is not None else ""))
            summary = replace(summary, plot=str(out / "plot.png"))
        except Exception as exc:  # a plot must never lose the run's data
            summary = replace(summary, plot_error=f"{type(exc).__name__}: {exc}")
    write_json_atomic(out / "summary.json", to_table(summary), private=bool(cfg.gcs.signing_key_file))
    return summary
