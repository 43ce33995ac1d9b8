"""`hil bench can-flood`: the simulator's real-time step while foreign nodes flood the CAN bus (issue 31).

In-process on python-can's ``virtual`` bus (this machine has no SocketCAN; ``hil vcan`` gives one inside
User-Mode Linux, where every syscall costs far more): the simulator core and its ESC nodes
(:class:`simulator.esc.EscBank`) step at the real-time frame rate (100 Hz) as ``hil sim`` does in real
time: each step the ESCs' poll reads the bus (bounded: frames and wall time), the newest valid RawCommand
is applied, the core steps and encodes its frame. Each step the autopilot's CAN back-end
(:class:`autopilot_bridge.can_actuators.CanActuators`) sends its RawCommand in the middle of that step's
share of the flood: single-frame full-astern RawCommands from node 99, which the ESCs must never apply.

The flood is put on the bus in the same thread, and the time that takes is taken off the step clock, so
the step's lateness (jitter) and the poll's time are the simulator's own work; the poll's CPU time
(``poll_cpu_ms``) is what a busy machine's scheduling does not inflate. The autopilot's command
carries its step number (in the port value), so the age of each applied command is known. The virtual
bus queues without bound (SocketCAN drops what its receive buffer cannot hold), so a flood faster than
the drain shows how the autopilot's commands age behind it: the core's stale-command failsafe (0.5 s
without a command) does not see that age, since each late command is new to it.
Legs: quiet; a saturated 1 Mbit/s bus (8,000 frames/s, ~80 a step); a bus without a bit rate
(``--rate``, default 50,000/s: over the 256-frame cap); each flood leg with the bound (256 frames and
2 ms) and with the frame cap alone (the bound before issue 31's time budget).
"""

from __future__ import annotations

import argparse
import itertools
import time
from typing import TYPE_CHECKING

from common.tables import JsonTable
from hil.console import emit, progress
from hil.errors import UsageError

if TYPE_CHECKING:
    import can

    from hil.settings import HilConfig

REAL_BUS_RATE = 8000.0     # frames/s: a 1 Mbit/s bus full of ~130-bit extended frames
FOREIGN_NODE = 99
AGE_MOD = 4096             # step numbers carried in the port command (int14, < 8191)
_channels = itertools.count()


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "can-flood", parents=parents,
        help="the simulator's real-time step under a flood of foreign RawCommands on CAN (issue 31)",
        description="In-process on python-can's virtual bus: the simulator core and its ESC nodes step in "
                    "real time (100 Hz) while the autopilot's back-end sends one RawCommand a step in the middle "
                    "of a flood of foreign full-astern RawCommands. Legs: quiet, 8,000 frames/s (a saturated "
                    "1 Mbit/s bus), --rate frames/s; each flood leg with the poll bounded by 256 frames and "
                    "2 ms and by the 256 frames alone. Reports step lateness (jitter) and poll time "
                    "(p50/p99/max, ms; the poll also in CPU time), stale-command events, commands applied, frames read "
                    "and left queued, "
                    "polls cut by cause, and the last RawCommand applied (the autopilot's, never the flood's).",
    )
    p.add_argument("--duration", type=float, default=10.0, metavar="S",
                   help="wall seconds per leg, 0.05-3600 (default: 10)")
    p.add_argument("--interface", default="virtual", choices=("virtual", "socketcan"),
                   help="python-can interface (default: virtual, in-process; socketcan: e.g. inside `hil vcan`)")
    p.add_argument("--channel", default="vcan0", help="SocketCAN channel (default: vcan0)")
    p.add_argument("--rate", type=float, default=50_000.0, metavar="PER_S",
                   help="the fast flood's foreign frames per second, 0-1e6 (default: 50000)")
    p.set_defaults(func=run)


def _pct(xs: list[float]) -> dict[str, float] | None:
    if not xs:
        return None
    s = sorted(xs)
    return {"p50": round(s[len(s) // 2], 3), "p99": round(s[min(len(s) - 1, int(0.99 * len(s)))], 3),
            "max": round(s[-1], 3)}


def _queued(bus: can.BusABC) -> int | None:
    """Frames waiting in a python-can virtual bus's receive queue (None: a SocketCAN socket's is not known)."""
    queue = getattr(bus, "queue", None)
    return None if queue is None else int(queue.qsize())


def leg(cfg: HilConfig, duration_s: float, rate: float, time_budget: bool, filtered: bool = False) -> JsonTable:
    """One real-time run of ``duration_s`` wall seconds under ``rate`` foreign frames/s; ``filtered``: the
    ESC socket with the simulator's kernel filter (SocketCAN only)."""
    import can

    from autopilot_bridge.can_actuators import CanActuators
    from common import dronecan_codec as dc
    from common.can_params import kernel_filters, open_bus
    from hil.assembly.simulator import simulator_settings
    from simulator.core import Command, SimulatorCore
    from simulator.esc import EscBank

    if cfg.can.interface == "socketcan":
        esc_filters = kernel_filters(cfg.can, cfg.can.autopilot_node_id) if filtered else None
        esc_bus = open_bus(cfg.can, can_filters=esc_filters)
        ap_bus, flood_bus = open_bus(cfg.can), open_bus(cfg.can)
    else:
        channel = f"can-flood-{next(_channels)}"
        esc_bus, ap_bus, flood_bus = (can.Bus(interface="virtual", channel=channel) for _ in range(3))
    try:
        core = SimulatorCore(simulator_settings(cfg))
        esc = EscBank(esc_bus, cfg.can, cfg.esc, core.vessel)
        if not time_budget:
            esc.budget_s = float("inf")
        acts = CanActuators(ap_bus, cfg.can)
        period = core.frame_dt
        per_step = rate * period
        owed = 0.0
        tid = 0
        payload = dc.raw_command([-dc.RAW_COMMAND_MAX, -dc.RAW_COMMAND_MAX])
        late_ms: list[float] = []
        poll_ms: list[float] = []
        poll_cpu_ms: list[float] = []      # the same, CPU time of this thread: what a busy machine does not inflate
        age_ms: list[float] = []           # applied command's age: steps since the autopilot sent it
        excluded = 0.0                     # wall time spent putting the flood on the bus

        def clock() -> float:
            return time.perf_counter() - excluded

        steps = int(round(duration_s / period))
        t0 = clock()
        for k in range(1, steps + 1):
            ideal = t0 + k * period
            while (remaining := ideal - clock()) > 0:
                time.sleep(min(remaining, 0.001))
            late_ms.append(max(0.0, (clock() - ideal) * 1e3))
            a = time.perf_counter()
            owed += per_step
            n = int(owed)
            owed -= n
            for i in range(n + 1):
                if i == n // 2:   # the step number rides in the port value: the applied command's age
                    acts.send_controls(core.time_usec, (k % AGE_MOD) / dc.RAW_COMMAND_MAX, 0.3)
                if i < n:
                    for f in dc.to_frames(dc.RAW_COMMAND, payload, FOREIGN_NODE, tid):
                        flood_bus.send(f)
                    tid = (tid + 1) % 32
            excluded += time.perf_counter() - a
            p0, c0 = time.perf_counter(), time.thread_time()
            esc.poll(0.0)
            poll_ms.append((time.perf_counter() - p0) * 1e3)
            poll_cpu_ms.append((time.thread_time() - c0) * 1e3)
            controls = esc.controls()
            if esc.commands_seen and controls is not None and esc.raw is not None:
                esc.commands_seen = 0
                age_ms.append(((k - esc.raw[0]) % AGE_MOD) * period * 1e3)
                core.apply(Command(core.time_usec, *controls))
            core.step()
            core.frame()
        s = esc.summary()
        return {
            "flood_frames_per_s": rate, "bound": "256 frames + 2 ms" if time_budget else "256 frames",
            "kernel_filter": filtered,
            "steps": steps, "step_lateness_ms": _pct(late_ms), "poll_ms": _pct(poll_ms),
            "poll_cpu_ms": _pct(poll_cpu_ms),
            "stale_command_events": core.stale_command_events, "command_age_ms": _pct(age_ms),
            "commands_sent": acts.commands_sent, "commands_applied": esc.commands,
            "frames_read": s["frames_received"], "frames_left_queued": _queued(esc_bus),
            "rejects": s["rejects"], "polls_cut": s["budget_stops"],
            "last_raw_command": s["last_raw_command"],
        }
    finally:
        for b in (esc_bus, ap_bus, flood_bus):
            b.shutdown()


MAX_DURATION_S = 3600.0
MAX_RATE = 1e6             # frames/s: 125x what a 1 Mbit/s bus carries


def run(args: argparse.Namespace) -> int:
    from hil import settings

    if not 0.05 <= args.duration <= MAX_DURATION_S:
        raise UsageError(f"--duration {args.duration:g}: between 0.05 and {MAX_DURATION_S:g} s")
    if not 0.0 <= args.rate <= MAX_RATE:
        raise UsageError(f"--rate {args.rate:g}: between 0 and {MAX_RATE:g} frames/s")

    cfg = settings.load(args.config, [*args.overrides, f'can.interface="{args.interface}"',
                                      f'can.channel="{args.channel}"', 'can.actuators="can"'])
    legs = [(0.0, True, False), (REAL_BUS_RATE, True, False), (REAL_BUS_RATE, False, False),
            (args.rate, True, False), (args.rate, False, False)]
    if args.interface == "socketcan":
        legs += [(REAL_BUS_RATE, True, True), (args.rate, True, True)]
    out = []
    for rate, budget, filtered in legs:
        progress(f"can-flood: {rate:.0f} frames/s, {'frames + time' if budget else 'frames'} bound"
                 f"{', kernel filter' if filtered else ''}, {args.duration:g} s")
        out.append(leg(cfg, args.duration, rate, budget, filtered))
    bus = "python-can virtual (in-process)" if args.interface == "virtual" else f"socketcan {args.channel}"
    summary = {"bench": "can-flood", "bus": bus, "legs": out}
    human = [f"{r['flood_frames_per_s']:>7.0f}/s {r['bound']:<17}{' kernel filter' if r['kernel_filter'] else ''}, "
             f"lateness p99 {r['step_lateness_ms']['p99']:.2f} "
             f"max {r['step_lateness_ms']['max']:.2f} ms, poll p99 {r['poll_ms']['p99']:.2f} ms, stale "
             f"{r['stale_command_events']}, command age max {r['command_age_ms']['max']:.0f} ms, "
             f"applied {r['commands_applied']}/{r['commands_sent']}" for r in out]
    emit(args, summary, human)
    return 0
