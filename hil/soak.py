"""The machinery of `hil soak` (hil/commands/soak.py parses its arguments): a long HIL loop in
real time, or the DroneCAN actuator path alone at a high rate, with the processes' memory and file
descriptors sampled from /proc and the CAN checks of both sides."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from hil.hilrun import HilRun
    from hil.settings import HilConfig
    from hil.tap import Tap

from common.tables import JsonTable, to_table
from hil.console import progress
from hil.errors import RunFailed


def proc_resources(pid: int) -> dict[str, float] | None:
    """Resident memory (MB) and open file descriptors of a live process, from /proc."""
    try:
        rss_kb = next(int(line.split()[1]) for line in open(f"/proc/{pid}/status") if line.startswith("VmRSS:"))
        return {"rss_mb": round(rss_kb / 1024.0, 2), "fds": len(os.listdir(f"/proc/{pid}/fd"))}
    except (OSError, StopIteration, ValueError):
        return None


class ResourceWatch:
    """Baseline after the warm-up and the last sample before the end, for each named process."""

    def __init__(self, warmup: float) -> None:
        self.warmup = warmup
        self.start: dict[str, dict] = {}
        self.end: dict[str, dict] = {}
        self.t_start: float | None = None
        self.t_end: float | None = None
        self.t0: float | None = None  # the first sample: the processes are up and working

    def sample(self, pids: dict[str, int]) -> None:
        now = time.monotonic()
        if self.t0 is None:
            self.t0 = now
        got = {k: r for k, pid in pids.items() if (r := proc_resources(pid)) is not None}
        if self.t_start is None:
            if now - self.t0 >= self.warmup and len(got) == len(pids):
                self.start, self.t_start = got, now
            return
        if len(got) == len(pids):
            self.end, self.t_end = got, now

    def report(self, max_growth: float, noise: float, max_fd_growth: int = 2) -> tuple[dict, list[str]]:
        out, problems = {}, []
        hours = ((self.t_end or 0) - (self.t_start or 0)) / 3600.0
        for name, s in self.start.items():
            e = self.end.get(name)
            if e is None or hours <= 0:
                continue
            growth = e["rss_mb"] - s["rss_mb"]
            per_h = growth / hours
            out[name] = {"rss_mb_start": s["rss_mb"], "rss_mb_end": e["rss_mb"], "rss_growth_mb_per_h": round(per_h, 2),
                         "fds_start": s["fds"], "fds_end": e["fds"]}
            if growth > noise and per_h > max_growth:
                problems.append(f"{name}: resident memory grew {growth:.1f} MB ({per_h:.0f} MB/h > {max_growth:g})")
            if e["fds"] > s["fds"] + max_fd_growth:
                problems.append(f"{name}: open file descriptors {s['fds']} -> {e['fds']} (> +{max_fd_growth})")
        if not out:
            problems.append("resources: no baseline and end sample (run too short for the warm-up?)")
        return {"processes": out, "measured_over_s": round(hours * 3600.0, 1)}, problems


def warmup_s(args: argparse.Namespace) -> float:
    return args.warmup if args.warmup is not None else min(60.0, max(5.0, 0.1 * args.duration))


def _load_record(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import numpy as np

    if not path.exists():
        return np.zeros(0), np.zeros(0)
    z = np.load(path)
    return z["tid"], z["at"]


def _can_checks(sides: dict[str, dict | None], problems: list[str]) -> JsonTable:
    """Per-node transfer counters of both sides; a loss or a reject is a problem."""
    out: JsonTable = {}
    for side, s in sides.items():
        if not s:
            problems.append(f"{side}: no CAN summary")
            continue
        out[side] = {k: s.get(k) for k in ("transfers_sent", "transfers_received", "transfers_lost",
                                           "transfers_duplicated", "rejects", "send_errors", "frames_received")}
        lost = sum((s.get("transfers_lost") or {}).values())
        if lost:
            problems.append(f"{side}: {lost} transfers lost")
        if s.get("rejects"):
            problems.append(f"{side}: rejected frames {s['rejects']}")
        if s.get("send_errors"):
            problems.append(f"{side}: {s['send_errors']} send errors")
    return out


def soak_loop(args: argparse.Namespace, cfg: HilConfig, out: Path) -> JsonTable:
    from hil.cpu_load import LoadWatch, overruns_allowed
    from hil.hilrun import RunOptions, run_loop

    watch = ResourceWatch(warmup_s(args))
    load = LoadWatch(every_s=1.0)
    on_can = cfg.can.actuators == "can"
    ap_rec, sim_rec = out / "autopilot-can.npz", out / "sim-can.npz"

    def sample(tap: Tap, run: HilRun) -> None:
        if tap.truth and run.ap is not None and run.sim is not None and run.ap.poll() is None \
                and run.sim.poll() is None:
            watch.sample({"autopilot": run.ap.pid, "simulator": run.sim.pid})
            load.sample([os.getpid(), run.ap.pid, run.sim.pid])

    progress(f"soak: HIL loop in real time for {args.duration:g} s on {args.scenario}, actuators {cfg.can.actuators}"
             + (f" ({cfg.can.interface}:{cfg.can.channel})" if on_can else ""))
    opts = RunOptions(scenario=args.scenario, lockstep=False, speedup=1.0, duration=args.duration, seed=args.seed,
                      config=args.config, overrides=list(args.overrides), out=out / "run", plot=False,
                      on_progress=progress, hooks=[sample], stop_at_goal=False,
                      wall_timeout=args.duration * 1.5 + 300.0,
                      extra_autopilot_args=["--can-record", str(ap_rec)] if on_can else [],
                      extra_sim_args=["--can-record", str(sim_rec)] if on_can else [])
    summary = run_loop(opts, cfg)
    problems: list[str] = []
    if summary.outcome not in ("timeout", "goal"):
        problems.append(f"run ended early: {summary.outcome}")
    sim = summary.simulator_counters()
    result: JsonTable = {
        "mode": "hil_loop", "actuators": cfg.can.actuators, "duration_s": args.duration,
        "outcome": summary.outcome, "sim_time_s": summary.sim_time_s,
        "stale_failsafe_events": None if sim is None else sim["stale_command_events"],
        "deadline_overruns": summary.deadline_overruns,
        "events": list(summary.events),
    }
    seen_load = load.report()
    allowed = overruns_allowed(args.max_overruns, seen_load, args.load_per_overrun)
    result["load"] = seen_load
    result["overruns_allowed"] = allowed
    if (summary.deadline_overruns or 0) > allowed:
        why = ("" if seen_load is None else f" (foreign load {seen_load['foreign_cpu_s']:.1f} CPU-s of "
               f"{seen_load['wall_s'] * seen_load['cpus']:.0f} in {seen_load['wall_s']:.0f} s)")
        problems.append(f"planner deadline overruns {summary.deadline_overruns} > {allowed} allowed{why}")
    if on_can:
        can = summary.can
        result["can"] = _can_checks({"autopilot": None if can is None else to_table(can["autopilot"]),
                                     "simulator": None if can is None else to_table(can["simulator"])},
                                    problems)
        result["can_log"] = None if can is None else can.get("can_log")
        lat = _latency(ap_rec, sim_rec)
        result["command_to_applied_ms"] = lat
    else:
        result["control_latency_ms"] = to_table(summary.control_latency_ms)
    res, res_problems = watch.report(args.max_rss_growth, args.rss_noise, args.max_fd_growth)
    result["resources"] = res
    result["problems"] = problems + res_problems
    return result


def _latency(sent_path: Path, applied_path: Path) -> dict[str, float | None]:
    from hil.can_path import pair_latency, stats_ms

    st, sa = _load_record(sent_path)
    at, aa = _load_record(applied_path)
    return stats_ms(pair_latency(st, sa, at, aa))


def soak_can_path(args: argparse.Namespace, cfg: HilConfig, out: Path) -> JsonTable:
    import numpy as np

    from hil import processes
    from hil.can_path import esc_process_command, paced, pair_latency, recording_actuators, stats_ms

    rec = out / "esc.npz"
    acts = recording_actuators(cfg)
    watch = ResourceWatch(warmup_s(args))
    esc = processes.start(esc_process_command(args, rec), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    problems: list[str] = []
    try:
        processes.wait_for_marker(esc, b"esc: ready")
        progress(f"soak: CAN path at {args.rate:g} Hz for {args.duration:g} s on {cfg.can.interface}:{cfg.can.channel}")
        period = 1.0 / args.rate
        t0 = time.monotonic()
        next_report = [t0 + 5.0]

        def send(k: int) -> None:
            x = 0.8 * np.sin(2 * np.pi * 0.05 * k * period)  # a slow sweep through forward and reverse
            acts.send_controls(int(round(k * period * 1e6)), x, -x)
            if (k + 1) % 50 == 0:
                watch.sample({"commander": os.getpid(), "esc_nodes": esc.pid})
            now = time.monotonic()
            if now >= next_report[0]:
                next_report[0] += 5.0
                progress(f"soak: {now - t0:.0f}/{args.duration:g} s, {acts.commands_sent} commands, "
                         f"{sum(acts.tracker.received.values())} transfers back")

        k = paced(args.rate, args.duration, send, acts.service, max_idle=0.01)
        deadline = time.monotonic() + 0.5
        while time.monotonic() < deadline:
            acts.service(0.05)
    finally:
        processes.stop(esc)
        acts.close()
    try:
        o, e = esc.communicate(timeout=30)
        esc_summary = json.loads(o.decode().strip().splitlines()[-1])
    except (ValueError, IndexError, subprocess.TimeoutExpired):
        raise RunFailed("the ESC node process printed no summary") from None
    behind = k - int(args.duration * args.rate)
    result: JsonTable = {"mode": "can_path", "rate_hz": args.rate, "duration_s": args.duration,
                              "commands_sent": acts.commands_sent,
                              "commands_behind_schedule": -behind if behind < 0 else 0}
    result["can"] = _can_checks({"autopilot": to_table(acts.summary()), "esc_nodes": esc_summary}, problems)
    st, sa = acts.sent_times.arrays()
    at, aa = _load_record(rec)
    result["command_to_applied_ms"] = stats_ms(pair_latency(st, sa, at, aa))
    result["stale_failsafe_events"] = None  # no simulator clock on the bare path
    result["deadline_overruns"] = None
    res, res_problems = watch.report(args.max_rss_growth, args.rss_noise, args.max_fd_growth)
    result["resources"] = res
    result["problems"] = problems + res_problems
    return result
