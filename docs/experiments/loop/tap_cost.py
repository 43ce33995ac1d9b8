"""The tap's cost per datagram (hil/tap.py), its short cut for clean datagrams against the pymavlink
path, on the datagrams of a real run.

    python docs/experiments/loop/tap_cost.py [RUN_FOLDER]

Without a folder it runs ``hil run --lockstep --duration 150 --no-plot`` (harbour) first. The run's
run.tlog is regrouped into datagrams (consecutive frames of one time stamp and one component, as the
processes send them), and every datagram is handed to a fresh lockstep Tap five times per path; the
best of the five is reported, per datagram and per lockstep step.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))

from pymavlink import mavutil  # noqa: E402

from common.geodesy import LocalFrame  # noqa: E402
from hil import tap as tap_module  # noqa: E402


def datagrams(tlog: Path) -> tuple[list[bytes], int]:
    log = mavutil.mavlink_connection(str(tlog))
    out: list[bytes] = []
    cur: list[bytes] = []
    key = None
    steps = 0
    while (m := log.recv_match()) is not None:
        steps += m.get_type() == "HIL_SENSOR"
        k = (m._timestamp, m.get_srcComponent())
        if k != key and cur:
            out.append(b"".join(cur))
            cur = []
        key = k
        cur.append(bytes(m.get_msgbuf()))
    out.append(b"".join(cur))
    return out, steps


def best_of_five(dgs: list[bytes]) -> float:
    best = float("inf")
    for _ in range(5):
        with tempfile.TemporaryDirectory() as d:
            t = tap_module.Tap(Path(d) / "x.tlog", LocalFrame(38.9, 121.6, 0.0), lockstep=True)
            t0 = time.perf_counter()
            for g in dgs:
                t._handle(g, None)
            best = min(best, time.perf_counter() - t0)
            t.close()
    return best


def main(argv: list[str]) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(argv[0]) if argv else Path(tmp) / "run"
        if not argv:
            subprocess.run([sys.executable, "-m", "hil", "run", "--lockstep", "--duration", "150", "--no-plot",
                            "--out", str(folder)], cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           env=dict(os.environ, PYTHONPATH=str(REPO)), check=False)
        dgs, steps = datagrams(folder / "run.tlog")
    print(f"{len(dgs)} datagrams, {steps} steps")
    fast = best_of_five(dgs)
    clean_frames = tap_module.clean_frames
    tap_module.clean_frames = lambda _data: None   # every datagram through the pymavlink path
    try:
        slow = best_of_five(dgs)
    finally:
        tap_module.clean_frames = clean_frames
    for name, t in (("short cut", fast), ("pymavlink path", slow)):
        print(f"  {name:15s} {1e6 * t / len(dgs):6.2f} us a datagram, {1e6 * t / steps:6.1f} us a step")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
