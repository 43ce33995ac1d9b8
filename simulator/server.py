"""The simulator's socket loops: lockstep and real time (see docs/simulator.md for the protocol).

Both loops send one datagram per frame from the command socket to every destination and stop
when ``duration`` simulated seconds have been run (0: never), or when ``stop()`` is called
(the ``hil sim`` command calls it from its SIGINT/SIGTERM handler).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, NotRequired, TypedDict

from common.current_tally import CurrentStats, describe
from common.percentiles import StreamingPercentiles
from common.udp import BusyPoll, BusyPollSummary, UdpEndpoint
from simulator.core import OUT_OF_STEP, BatterySummary, Command, SimulatorCore, TruthState
from simulator.esc import EscBankSummary

if TYPE_CHECKING:
    from simulator.esc import EscBank

POLL_S = 0.05  # longest wait before the stop flag is looked at again (wall seconds)
MAX_DATAGRAMS_PER_STEP = 64  # real time: command datagrams read per step at most (a flood waits in the socket)
# Real time: a step this late (wall s) is a stall (the process was paused: SIGSTOP, a debugger, a swapped
# VM): the missed steps are not replayed, the schedule restarts from now, and the stall is an event.
MAX_BEHIND_S = 0.25
STALLS_KEPT = 100   # stall events kept for the summary (count and total are exact)
LEARN = "learn"
# Why a pipelined lockstep refuses CAN actuators (here and in hil.commands.can_options' pre-flight).
PIPELINE_NOT_WITH_CAN = "the pipelined lockstep takes its commands over MAVLink, not from CAN ESCs"


class JitterMs(TypedDict):
    """Real time: how late the steps were (ms of wall time)."""

    p50: float | None
    p99: float | None
    max: float | None


class Stepping(TypedDict):
    """Lockstep: the steps from the first to the last and the wall time between them (s)."""

    steps: int
    wall_s: float
    steps_per_s: float | None


class StallEvent(TypedDict):
    t_s: float           # s of simulated time
    length_s: float      # wall s


class Stalls(TypedDict):
    """Real time: the stalls (the process paused), counted and the first STALLS_KEPT of them listed."""

    count: int
    total_s: float
    events: list[StallEvent]


class CommandPort(TypedDict):
    """Who sent commands to the simulator's port, and what it refused of them."""

    source: str | None                   # "host:port" of the autopilot that earned the port; None: none
    wrong_source_address: int
    wrong_source_id: int
    budget_stops: int
    kernel_drops: int | None


class GpsCounts(TypedDict):
    fixes: int
    dropout_fixes: int
    glitches: int


class AisCounts(TypedDict):
    ships: int
    reports: int
    lost: int


class SimulatorCanSummary(EscBankSummary):
    """``--actuators can``: the ESC bank's counters, with the lockstep's missing commands and the MAVLink
    commands ignored because the thrust comes from CAN."""

    lockstep_commands_missing: int
    mavlink_commands_ignored: int


class SimulatorCurrent(TypedDict):
    """The current the hull felt: the ``[current]`` source and its samples, once a frame (m/s, NED)."""

    source: str
    felt: CurrentStats | None


class SimulatorSummary(TypedDict):
    """What `hil sim` prints at its end (times in s, distances in m): the steps, the traffic on its ports,
    rejects by reason, the failsafes, the stalls, the battery and the truth at the end."""

    mode: str                            # "lockstep" or "realtime"
    seed: int
    steps: int
    sim_time_s: float
    wall_time_s: float
    steps_per_wall_s: float | None
    stepping: Stepping | None
    messages_sent: dict[str, int]
    datagrams_sent: int
    commands_received: int
    rejects: dict[str, int]
    malformed_dropped: int
    clamped_controls: int
    stale_command_events: int
    stale_command_times_s: list[float]
    lockstep_resends: int
    pipeline_skips: NotRequired[int]     # the pipelined lockstep only
    busy_poll: BusyPollSummary | None
    command_port: CommandPort
    jitter_ms: JitterMs | None
    stalls: Stalls
    gps: GpsCounts
    battery: BatterySummary
    distance_m: float
    ais: AisCounts | None
    final_state: TruthState
    current: SimulatorCurrent
    can: NotRequired[SimulatorCanSummary]   # --actuators can
    commands_on: NotRequired[str]        # "host:port" of the command port (added by `hil sim`)


class SimulatorServer:
    """Runs a :class:`SimulatorCore` over a :class:`UdpEndpoint` in lockstep or real time."""

    def __init__(self, core: SimulatorCore, endpoint: UdpEndpoint, *, lockstep: bool, duration: float,
                 speedup: float = 1.0, lockstep_resend: float = 1.0,
                 progress: Callable[[str], None] | None = None, progress_every_s: float = 5.0,
                 esc: EscBank | None = None, can_lockstep_wait: float = 1.0, command_source: str | None = None,
                 busy_poll: float = 0.0, pipeline: bool = False) -> None:
        """``command_source``: None takes commands from any address, "HOST:PORT" only from there,
        "learn" only from the address of the first valid command (docs/security.md). ``busy_poll``:
        lockstep waits for a command polling the socket up to this long (s) first (common.udp.BusyPoll).
        ``pipeline``: lockstep one frame ahead (:meth:`_run_pipelined`; MAVLink commands only)."""
        if pipeline and esc is not None:
            raise ValueError(f"sim.lockstep_pipeline: {PIPELINE_NOT_WITH_CAN}")
        self.core, self.ep = core, endpoint
        self.learn_source = command_source == LEARN
        if command_source and not self.learn_source:
            endpoint.set_peer(command_source)
        # CAN actuators: thrust comes from the ESC nodes' RawCommands;
        # in lockstep the HIL_ACTUATOR_CONTROLS answer is only the clock (docs/can.md).
        self.esc, self.can_lockstep_wait = esc, can_lockstep_wait
        self.can_commands_missing = 0
        self.mavlink_commands_ignored = 0
        self.lockstep, self.duration, self.speedup = lockstep, duration, speedup
        self.lockstep_resend = lockstep_resend
        self.busy = BusyPoll(busy_poll) if lockstep and busy_poll > 0 else None
        self.progress, self.progress_every_s = progress, progress_every_s
        self.end_frame = int(round(duration / core.frame_dt)) if duration > 0 else None
        self.lockstep_resends = 0
        self.pipeline = lockstep and pipeline
        self.pipeline_skips = 0   # pipelined lockstep: frames whose command never came (a later one did)
        self.budget_stops = 0
        self.datagrams_sent = 0
        self.lateness = StreamingPercentiles()  # real time: lateness of each step vs its ideal wall time (ms)
        self.max_behind = MAX_BEHIND_S
        self.stalls: list[tuple[float, float]] = []   # real time: (simulated s, wall s missed), the first STALLS_KEPT
        self.stall_count = 0
        self.stall_total_s = 0.0
        self._stop = False
        self.wall_time = 0.0
        # lockstep: wall clock (time.monotonic) of the first and the last step, so the loop's speed
        # can be read without the processes' start-up and shut-down (one-off costs)
        self.first_step_at: float | None = None
        self.first_step_n = 1          # core.n after the first timed step
        self.last_step_at: float | None = None

    def stop(self) -> None:
        """Ask the loop to end after the current step (safe from a signal handler)."""
        self._stop = True

    @property
    def stopped(self) -> bool:
        """:meth:`stop` was called."""
        return self._stop

    def _done(self) -> bool:
        return self._stop or (self.end_frame is not None and self.core.n >= self.end_frame)

    def _publish(self, datagram: bytes) -> None:
        if self.esc is not None:
            self.esc.publish(self.core.t, self.core.thrust, self.core.battery.voltage)
        self.ep.send(datagram)
        self.datagrams_sent += 1

    def _maybe_progress(self, start: float, last: list[float]) -> None:
        now = time.monotonic()
        if self.progress and now - last[0] >= self.progress_every_s:
            last[0] = now
            c = self.core
            self.progress(f"sim: t={c.t:.1f} s, {c.n} steps, {c.n / max(1e-9, now - start):.0f} steps/s, "
                          f"{c.commands_received} commands")

    def run(self) -> SimulatorSummary:
        start = time.monotonic()
        try:
            if self.pipeline:
                self._run_pipelined(start)
            elif self.lockstep:
                self._run_lockstep(start)
            else:
                self._run_realtime(start)
        finally:
            self.wall_time = time.monotonic() - start
        return self.summary()

    # -- lockstep --------------------------------------------------------------------------
    def _run_lockstep(self, start: float) -> None:
        core, last_progress = self.core, [start]
        frame = core.frame()
        self._publish(frame)
        last_send = time.monotonic()
        while not self._done():
            data, last_send = self._wait_for_commands(last_send, (frame,))
            if data is None:
                continue
            stepped = False
            for cmd in core.receive(data):
                self._learn()
                if not stepped and cmd.time_usec == core.time_usec:
                    if self.esc is None:
                        core.apply(cmd)
                    else:
                        self._apply_can(self.esc, cmd)
                    core.step()
                    stepped = True
                    self.last_step_at = time.monotonic()
                    if self.first_step_at is None:
                        self.first_step_at, self.first_step_n = self.last_step_at, core.n
                else:
                    core.rejects[OUT_OF_STEP] += 1
            if stepped:
                frame = core.frame()
                self._publish(frame)
                last_send = time.monotonic()
                if core.n % 1000 == 0:
                    self._maybe_progress(start, last_progress)

    def _run_pipelined(self, start: float) -> None:
        """Lockstep one frame ahead (``sim.lockstep_pipeline``). Plain lockstep waits for the answer
        to the frame at t_k before it integrates from t_k, so the simulator and the vessel computer
        take turns. Here the simulator integrates from t_k with the command it has (the answer to
        t_(k-1)) while the vessel computer answers t_k, and the two work at once: the answer to t_k
        acts from t_(k+1) to t_(k+2), a one-frame actuator delay, the same in every run.

        Frames not yet answered stay pending (two in the steady state) and are re-sent together when
        no command came for ``lockstep_resend``. A command for the later of two pending frames means
        the earlier one's was lost: that frame is skipped (``pipeline_skips``), the command acts from
        the next step, and the simulator steps once more to have two frames pending again."""
        core, last_progress = self.core, [start]
        pending: list[tuple[int, bytes]] = []   # (time_usec, datagram) sent and not yet answered, oldest first

        def step_and_publish(timed: bool = True) -> None:
            core.step()
            if timed:   # the speed counts from the first step a command drove, as in plain lockstep
                self.last_step_at = time.monotonic()
                if self.first_step_at is None:
                    self.first_step_at, self.first_step_n = self.last_step_at, core.n
            frame = core.frame()
            self._publish(frame)
            pending.append((core.time_usec, frame))

        first = core.frame()
        self._publish(first)
        pending.append((core.time_usec, first))
        if not self._done():
            step_and_publish(timed=False)   # the first frame's command will act from the second
        last_send = time.monotonic()
        while not self._done():
            data, last_send = self._wait_for_commands(last_send, (frame for _, frame in pending))
            if data is None:
                continue
            for cmd in core.receive(data):
                self._learn()
                if self._done():
                    break
                answered = next((i for i, (tu, _) in enumerate(pending) if tu == cmd.time_usec), None)
                if answered is None:
                    core.rejects[OUT_OF_STEP] += 1
                    continue
                self.pipeline_skips += answered
                del pending[:answered + 1]
                core.apply(cmd)
                step_and_publish()
                if len(pending) < 2 and not self._done():
                    step_and_publish()
                last_send = time.monotonic()
                if core.n % 1000 == 0:
                    self._maybe_progress(start, last_progress)

    def _wait_for_commands(self, last_send: float, unanswered: Iterable[bytes]) -> tuple[bytes | None, float]:
        """Lockstep: the next datagram on the command socket (None: none yet), and the wall time of the
        last send. When no command came for ``lockstep_resend`` after ``last_send``, the frames not yet
        answered are re-sent unchanged first: a lost datagram cannot deadlock the loop."""
        wait = min(POLL_S, max(0.0, last_send + self.lockstep_resend - time.monotonic()))
        data = self.ep.recv(timeout=wait, poll=self.busy)
        if data is None and time.monotonic() - last_send >= self.lockstep_resend:
            for frame in unanswered:
                self._publish(frame)
            self.lockstep_resends += 1
            last_send = time.monotonic()
        return data, last_send

    def _learn(self) -> None:
        """--commands-from learn: the first valid command's address becomes the only source."""
        if self.learn_source and self.ep.peer is None and self.ep.last_sender is not None:
            self.ep.set_peer(self.ep.last_sender)

    def _apply_can(self, esc: EscBank, token: Command) -> None:
        """Lockstep over CAN: apply the ESCs' RawCommand that ``token`` announces (bounded wait)."""
        from common.dronecan_layout import quantize

        want = (quantize(token.port), quantize(token.stdb))
        deadline = time.monotonic() + self.can_lockstep_wait
        esc.poll(0.0)
        while esc.raw != want and (left := deadline - time.monotonic()) > 0:
            esc.poll(min(left, POLL_S))
        controls = esc.controls()
        if esc.raw != want or controls is None:
            self.can_commands_missing += 1  # thrust stays as it was; the stale failsafe still runs
            return
        esc.commands_seen = 0
        self.core.apply(Command(token.time_usec, *controls))

    # -- real time -------------------------------------------------------------------------
    def _run_realtime(self, start: float) -> None:
        core, last_progress = self.core, [start]
        period = core.frame_dt / self.speedup
        t0 = time.perf_counter()
        self._publish(core.frame())
        k = 0
        while not self._done():
            k += 1
            ideal = t0 + k * period
            while (remaining := ideal - time.perf_counter()) > 0:
                if self._stop:
                    return
                time.sleep(min(remaining, POLL_S))
            late = time.perf_counter() - ideal
            if late > self.max_behind:
                t0 = self._stalled(late, t0, period)   # skip ahead: the missed steps are not replayed
                late = 0.0
            self.lateness.add(max(0.0, late * 1e3))
            newest = None
            for _ in range(MAX_DATAGRAMS_PER_STEP):
                data = self.ep.recv(0.0)
                if data is None:
                    break
                cmds = core.receive(data)
                if cmds:
                    newest = cmds[-1]
                    self._learn()
            else:
                self.budget_stops += 1
            if self.esc is not None:
                self.mavlink_commands_ignored += newest is not None
                newest = None
                self.esc.poll(0.0)
                controls = self.esc.controls()
                if self.esc.commands_seen and controls is not None:
                    self.esc.commands_seen = 0
                    newest = Command(core.time_usec, *controls)
            if newest is not None:
                core.apply(newest)
            core.step()
            self._publish(core.frame())
            self._maybe_progress(start, last_progress)

    def _stalled(self, late: float, t0: float, period: float) -> float:
        """A stall of ``late`` wall seconds: counted and reported; the schedule's origin moved so that this
        step is due now. Before (issue 31) a 5 s SIGSTOP was caught up at once, about 4 s of it under the
        thrust set before the pause, and nothing reported it."""
        self.stall_count += 1
        self.stall_total_s += late
        if len(self.stalls) < STALLS_KEPT:
            self.stalls.append((self.core.t, late))
        if self.progress is not None:
            self.progress(f"sim: stalled {late:.2f} s (wall) at t={self.core.t:.2f} s; skipped ahead, "
                          f"the missed steps are not replayed")
        return t0 + late

    # -- report ----------------------------------------------------------------------------
    def jitter_ms(self) -> JitterMs | None:
        j = self.lateness
        if not j.count:
            return None
        return JitterMs(p50=j.percentile(50), p99=j.percentile(99), max=j.max)

    def stepping(self) -> Stepping | None:
        """Lockstep: the steps from the first to the last and the wall time between them (s), i.e.
        the loop's speed without start-up and shut-down; None before two steps or in real time."""
        steps = self.core.n - self.first_step_n
        if self.first_step_at is None or self.last_step_at is None or steps < 1:
            return None
        wall = self.last_step_at - self.first_step_at
        return Stepping(steps=steps, wall_s=round(wall, 6), steps_per_s=round(steps / wall, 1) if wall > 0 else None)

    def summary(self) -> SimulatorSummary:
        c = self.core
        out = SimulatorSummary(
            mode="lockstep" if self.lockstep else "realtime",
            seed=c.cfg.sim.seed,
            steps=c.n,
            sim_time_s=c.t,
            wall_time_s=self.wall_time,
            steps_per_wall_s=c.n / self.wall_time if self.wall_time > 0 else None,
            stepping=self.stepping(),
            messages_sent=dict(sorted(c.messages_sent.items())),
            datagrams_sent=self.datagrams_sent,
            commands_received=c.commands_received,
            rejects=dict(sorted(c.rejects.items())),
            malformed_dropped=sum(v for k, v in c.rejects.items() if k != OUT_OF_STEP),
            clamped_controls=c.clamped_controls,
            stale_command_events=c.stale_command_events,
            stale_command_times_s=[round(t, 3) for t in c.stale_command_times],
            lockstep_resends=self.lockstep_resends,
            busy_poll=None if self.busy is None else self.busy.summary(),
            command_port=CommandPort(source=None if self.ep.peer is None else f"{self.ep.peer[0]}:{self.ep.peer[1]}",
                                     wrong_source_address=self.ep.wrong_source,
                                     wrong_source_id=c.rejects.get("wrong_source_id", 0),
                                     budget_stops=self.budget_stops + self.ep.budget_stops,
                                     kernel_drops=self.ep.kernel_drops()),
            jitter_ms=self.jitter_ms(),
            stalls=Stalls(count=self.stall_count, total_s=round(self.stall_total_s, 3),
                          events=[StallEvent(t_s=round(t, 3), length_s=round(d, 3)) for t, d in self.stalls]),
            gps=GpsCounts(fixes=c.gps.fixes, dropout_fixes=c.gps.dropout_fixes, glitches=c.gps.glitches),
            battery=c.battery_summary(),
            distance_m=c.distance,
            ais=None if c.traffic is None else AisCounts(ships=len(c.traffic.ships), reports=c.traffic.reports_sent,
                                                         lost=c.traffic.reports_lost),
            final_state=c.truth(),
            current=SimulatorCurrent(source=describe(c.cfg.current), felt=c.current_felt.stats()),
        )
        if self.pipeline:
            out["pipeline_skips"] = self.pipeline_skips
        if self.esc is not None:
            out["can"] = SimulatorCanSummary(**self.esc.summary(), lockstep_commands_missing=self.can_commands_missing,
                                             mavlink_commands_ignored=self.mavlink_commands_ignored)
        return out
