"""`hil bench can`: command -> applied latency of our CAN actuator path vs bare python-can, one run."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hil.console import emit, load_settings, progress
from hil.errors import RunFailed, UsageError

BARE_REQUEST, BARE_REPLY = 0x100, 0x101   # 29-bit IDs of the bare leg (source node 0/1: no DroneCAN node takes them)


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    from hil.commands.can_options import add_can_arguments

    p = sub.add_parser(
        "can", parents=parents,
        help="CAN actuator path: command -> applied latency vs bare python-can between two processes",
        description="Two legs in the same run and environment, each between two processes on the same bus. "
                    "Ours: this process sends thruster commands through the autopilot's CAN back-end "
                    "(DroneCAN RawCommand) at --rate; the simulated ESC nodes (another process) receive, "
                    "validate and apply them; latency = applied - commanded (both on CLOCK_MONOTONIC). Bare: "
                    "the same rate of one-frame messages with python-can alone, stamped on sending and on "
                    "receipt by an echo process that sends them straight back (one-way latency and round "
                    "trip). The legs alternate in blocks (--block) within one run, so a busy machine "
                    "slows both alike. Reports p50/p99/max and the overhead ratio ours/bare (p50 and p99). Goal: p50 "
                    "overhead <= 1.5x; on native vcan p99 <= 2 ms at 100 Hz.",
    )
    p.add_argument("--rate", type=float, default=100.0, metavar="HZ", help="commands per second (default: 100)")
    p.add_argument("--duration", type=float, default=10.0, metavar="S", help="seconds per leg (default: 10)")
    p.add_argument("--block", type=float, default=1.0, metavar="S",
                   help="the legs alternate in blocks of about this many seconds, so both see the same "
                        "machine load (default: 1)")
    add_can_arguments(p, actuators=False)
    p.set_defaults(func=run)


def _child(cmd: list[str]) -> subprocess.Popen:
    from hil import processes
    from hil.processes import wait_for_marker

    proc = processes.start(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wait_for_marker(proc, b"ready")
    return proc


def _finish(proc: subprocess.Popen) -> dict:
    from hil import processes

    processes.stop(proc)
    out, err = proc.communicate(timeout=30)
    try:
        return json.loads(out.decode().strip().splitlines()[-1])
    except (ValueError, IndexError):
        raise RunFailed(f"benchmark child printed no summary: {err.decode(errors='replace')[-300:]}") from None


def run(args: argparse.Namespace) -> int:
    import can
    import numpy as np

    from hil.can_path import esc_process_command, paced, pair_latency, recording_actuators, stats_ms
    from hil.commands.can_options import can_overrides

    args.overrides = list(args.overrides) + can_overrides(args)
    cfg = load_settings(args)
    if not (args.rate > 0 and args.duration > 0 and args.block > 0):
        raise UsageError("--rate, --duration and --block must be > 0")
    rounds = max(1, round(args.duration / args.block))
    block = args.duration / rounds
    result: dict = {"interface": cfg.can.interface, "channel": cfg.can.channel, "rate_hz": args.rate,
                    "duration_s": args.duration, "rounds": rounds,
                    "goal": {"p50_overhead_max": 1.5, "p99_ms_native_vcan": 2.0}}
    with tempfile.TemporaryDirectory(prefix="hil-bench-can-") as tmp:
        rec, rec2 = Path(tmp) / "esc.npz", Path(tmp) / "echo.npz"
        esc = echo = bus = acts = None
        try:
            acts = recording_actuators(cfg)
            # Kernel filters keep each leg's frames away from the other leg's processes: the ESC
            # nodes see only the autopilot's messages, the echo and the bare sender only their IDs.
            esc = _child(esc_process_command(args, rec) + ["--only-from-autopilot"])
            echo = _child([sys.executable, "-m", "hil.can_path", "echo", "--interface", cfg.can.interface,
                           "--channel", cfg.can.channel, "--duration", repr(2 * args.duration + 30),
                           "--record", str(rec2)])
            bus = can.Bus(interface=cfg.can.interface, channel=cfg.can.channel,
                          can_filters=[{"can_id": BARE_REPLY, "can_mask": 0x1FFFFFFF, "extended": True}])
            sent_at, sent_seq, rtt = [], [], []
            pending: dict[int, float] = {}
            seq = [0]

            def send_bare(_k: int) -> None:
                k = seq[0]
                seq[0] += 1
                t = time.monotonic()
                bus.send(can.Message(arbitration_id=BARE_REQUEST, data=bytes([k % 256, 0, 0, 0, 0]),
                                     is_extended_id=True))
                sent_at.append(t)
                sent_seq.append(k % 256)
                pending[k % 256] = t

            def idle_bare(wait: float) -> None:
                msg = bus.recv(wait)
                while msg is not None:
                    if msg.data[0] in pending:
                        rtt.append(time.monotonic() - pending.pop(msg.data[0]))
                    msg = bus.recv(0.0)

            def send_ours(k: int) -> None:
                n = acts.commands_sent
                acts.send_controls(n * 10_000, 0.5 * np.sin(n / 50), 0.2)

            progress(f"bench can: {rounds} rounds of {block:.2f} s per leg at {args.rate:g} Hz "
                     f"(ours, then bare python-can echo)")
            for r in range(rounds):
                acts.service(0.0)
                paced(args.rate, block, send_ours, acts.service)
                acts.service(0.05)
                idle_bare(0.0)
                paced(args.rate, block, send_bare, idle_bare)
                idle_bare(0.05)
                if (r + 1) % max(1, rounds // 5) == 0 or r + 1 == rounds:
                    progress(f"bench can: round {r + 1}/{rounds}")
        finally:
            esc_summary = _finish(esc) if esc is not None else {}
            if echo is not None:
                _finish(echo)
            if bus is not None:
                bus.shutdown()
            if acts is not None:
                acts.close()
        z = np.load(rec)
        sent_tid, sent_at_ours = acts.sent_times.arrays()
        ours = pair_latency(sent_tid, sent_at_ours, z["tid"], z["at"])
        result["ours_command_to_applied_ms"] = stats_ms(ours)
        result["ours_lost"] = acts.commands_sent - int(esc_summary.get("raw_commands_applied", 0))
        z = np.load(rec2)
        bare = pair_latency(np.array(sent_seq), np.array(sent_at), z["tid"], z["at"], modulo=256)
        result["bare_one_way_ms"] = stats_ms(bare)
        result["bare_round_trip_ms"] = stats_ms(np.array(rtt))
        result["bare_lost"] = len(sent_seq) - len(bare)
    o, b = result["ours_command_to_applied_ms"], result["bare_one_way_ms"]
    if o["samples"] and b["samples"]:
        result["overhead_p50"] = round(o["p50"] / b["p50"], 2) if b["p50"] else None
        result["overhead_p99"] = round(o["p99"] / b["p99"], 2) if b["p99"] else None
    emit(args, result)
    return 0
