"""The CAN actuator path on its own, for `hil soak --rate` and `hil bench can`.

* ``python -m hil.can_path esc ...``: the simulated ESC nodes (:class:`simulator.esc.EscBank`) as
  a process on a bus, applying RawCommands as they arrive and publishing Status/NodeStatus by the
  wall clock; it records (transfer ID, time applied) and prints its summary as JSON at the end.
* ``python -m hil.can_path echo ...``: bare python-can, no stack: every frame received is
  stamped and sent straight back (the bench's reference).
* :func:`esc_process_command`, :func:`recording_actuators`, :func:`paced`: the commanding side
  that `hil bench can` and `hil soak --rate` share.
* :func:`pair_latency`: command -> applied latencies from the two sides' records. Both processes
  stamp with ``time.monotonic()`` (CLOCK_MONOTONIC, one clock for every process of a machine).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from common.dronecan_codec import TRANSFER_ID_MODULO

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path
    from types import FrameType

    from can.typechecking import CanFilter

    from autopilot_bridge.can_actuators import CanActuators
    from hil.settings import HilConfig


def pair_latency(sent_tid: npt.ArrayLike, sent_at: npt.ArrayLike, applied_tid: np.ndarray,
                 applied_at: np.ndarray, modulo: int = TRANSFER_ID_MODULO) -> np.ndarray:
    """Latencies (s) of the applied commands, each paired with the earliest unpaired command sent
    before it with the same transfer ID (right unless ``modulo`` or more commands in a row were lost)."""
    st, sa = np.asarray(sent_tid), np.asarray(sent_at)
    out = []
    j = 0
    for tid, ta in zip(applied_tid, applied_at, strict=False):
        k = j
        while k < len(st) and k < j + modulo and not (st[k] == tid and sa[k] <= ta):
            k += 1
        if k < len(st) and k < j + modulo:
            out.append(ta - sa[k])
            j = k + 1
    return np.array(out)


def esc_process_command(args: argparse.Namespace, record: str | Path) -> list[str]:
    """``python -m hil.can_path esc`` with the caller's ``--config``/``--set`` (so both ends use the
    same [can] and [esc] settings), running 30 s past ``args.duration`` and recording to ``record``."""
    cmd = [sys.executable, "-m", "hil.can_path", "esc", "--duration", repr(float(args.duration) + 30.0),
           "--record", str(record)]
    from hil.config import config_args

    cmd += config_args(args.config)
    for o in args.overrides:
        cmd += ["--set", o]
    return cmd


def recording_actuators(cfg: HilConfig) -> CanActuators:
    """The autopilot's CAN back-end on the configured bus, recording (transfer ID, time sent) of each
    command; a bus that cannot be opened is a one-line UsageError."""
    from autopilot_bridge.can_actuators import CanActuators
    from common.can_params import open_bus
    from hil.errors import UsageError

    try:
        acts = CanActuators(open_bus(cfg.can), cfg.can)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    acts.sent_times.start()
    return acts


def paced(rate: float, duration: float, send: Callable[[int], None], idle: Callable[[float], None],
          max_idle: float = 0.005) -> int:
    """Call ``send(k)`` at ``rate`` Hz for ``duration`` s of wall time (no drift: the k-th call is due at
    ``t0 + k / rate``), and ``idle(seconds)`` (at most ``max_idle``) while waiting; returns the calls made."""
    period, t0, k = 1.0 / rate, time.monotonic(), 0
    while (now := time.monotonic()) - t0 < duration:
        target = t0 + k * period
        if now < target:
            idle(min(target - now, max_idle))
            continue
        send(k)
        k += 1
    return k


def stats_ms(lat_s: np.ndarray) -> dict[str, float | None]:
    if len(lat_s) == 0:
        return {"p50": None, "p99": None, "max": None, "samples": 0}
    ms = lat_s * 1e3
    return {"p50": round(float(np.percentile(ms, 50)), 4), "p99": round(float(np.percentile(ms, 99)), 4),
            "max": round(float(ms.max()), 4), "samples": int(len(ms))}


def _stop_flag() -> dict[str, bool]:
    flag = {"stop": False}

    def handler(_signum: int, _frame: FrameType | None) -> None:
        flag["stop"] = True

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)
    return flag


def esc_main(args: argparse.Namespace) -> int:
    from common.can_params import open_bus
    from hil import settings
    from simulator.esc import EscBank
    from simulator.vessel import Vessel

    cfg = settings.load(args.config, args.overrides)
    vessel = Vessel(cfg.vessel)
    filters: list[CanFilter] | None = None
    if args.only_from_autopilot:  # messages (service bit 0) from the autopilot's node ID only
        filters = [{"can_id": cfg.can.autopilot_node_id, "can_mask": 0xFF, "extended": True}]
    esc = EscBank(open_bus(cfg.can, can_filters=filters), cfg.can, cfg.esc, vessel)
    esc.applied_times.start(spill_to=args.record)
    flag = _stop_flag()
    print("esc: ready", file=sys.stderr, flush=True)
    t0 = time.monotonic()
    end = t0 + args.duration
    while not flag["stop"]:
        esc.poll(0.005)
        now = time.monotonic()
        if now >= end:
            break
        c = esc.controls() or (0.0, 0.0)
        esc.publish(now - t0, (vessel.thrust(c[0]), vessel.thrust(c[1])))
    esc.bus.shutdown()
    esc.applied_times.save(args.record)
    print(json.dumps(esc.summary()), flush=True)
    return 0


def echo_main(args: argparse.Namespace) -> int:
    import can

    bus = can.Bus(interface=args.interface, channel=args.channel,
                  can_filters=[{"can_id": args.request_id, "can_mask": 0x1FFFFFFF, "extended": True}])
    flag = _stop_flag()
    print("echo: ready", file=sys.stderr, flush=True)
    stamps = []
    end = time.monotonic() + args.duration
    while not flag["stop"] and time.monotonic() < end:
        msg = bus.recv(0.05)
        # Filtered in the kernel on SocketCAN; the check stays for back-ends that filter nothing.
        if msg is None or msg.arbitration_id != args.request_id:
            continue
        stamps.append((msg.data[0], time.monotonic()))
        bus.send(can.Message(arbitration_id=args.reply_id, data=msg.data, is_extended_id=True))
    bus.shutdown()
    np.savez(args.record, tid=np.array([s[0] for s in stamps], dtype=np.int16),
             at=np.array([s[1] for s in stamps], dtype=float))
    print(json.dumps({"echoed": len(stamps)}), flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m hil.can_path")
    sub = p.add_subparsers(dest="role", required=True)
    e = sub.add_parser("esc")
    e.add_argument("--config", action="append", default=None)
    e.add_argument("--set", dest="overrides", action="append", default=[])
    e.add_argument("--duration", type=float, required=True)
    e.add_argument("--record", required=True)
    e.add_argument("--only-from-autopilot", action="store_true",
                   help="kernel filter: take only message frames from the autopilot's node ID (bench)")
    e.set_defaults(func=esc_main)
    c = sub.add_parser("echo")
    c.add_argument("--interface", required=True)
    c.add_argument("--channel", required=True)
    c.add_argument("--duration", type=float, required=True)
    c.add_argument("--record", required=True)
    c.add_argument("--request-id", type=int, default=0x100)
    c.add_argument("--reply-id", type=int, default=0x101)
    c.set_defaults(func=echo_main)
    args = p.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
