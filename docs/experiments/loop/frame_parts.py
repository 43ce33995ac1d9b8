"""Time the parts of a HIL step that commit 2376c72 and its successors replaced, old against new, in
one process (timeit, best of 5):

    python docs/experiments/loop/frame_parts.py

* decoding a datagram: ``Codec.decode_stream`` (pymavlink's parser) against ``Codec.decode``
  (``parse_clean``), on a HIL_SENSOR-only frame, a frame with everything due at once, and a command;
* encoding: pymavlink's ``<name>_encode`` + ``pack`` against ``Codec.encode``;
* LOS guidance: ``LineOfSight.update`` as it was at b0a120d (numpy; read from git) against today's.

The datagrams are a real run's: harbour, seed 1, after 400 frames of the in-process loop of
``hil bench frame``. Figures on the development machine are in docs/performance.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import timeit
import types
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path[:0] = [str(REPO), str(REPO / "tests")]


def best_us(fn, n: int = 3000) -> float:
    fn()
    return min(timeit.repeat(fn, number=n, repeat=5)) / n * 1e6


def main() -> int:
    import numpy as np

    from autopilot_bridge.guidance import LineOfSight
    from common.mavlink import Codec, mavlink2
    from hil.benches.frame import _Loop

    loop = _Loop(argparse.Namespace(scenario="harbour", seed=1, config=None, overrides=[]))
    datagrams = []
    for _ in range(400):
        datagrams.append(loop.core.frame())
        loop.step()
    loop.ap.link.send_controls(loop.core.time_usec, 0.3, 0.4)
    command = loop.rx.recv(65536)
    rx = Codec(255, 190, accept=[c.msgname for c in mavlink2.mavlink_map.values()])
    rows = []
    small, big = min(datagrams, key=len), max(datagrams, key=len)
    for name, d in ((f"decode a HIL_SENSOR frame ({len(small)} B)", small),
                    (f"decode a frame with all due ({len(big)} B)", big),
                    ("decode a HIL_ACTUATOR_CONTROLS", command)):
        rows.append((name, best_us(lambda d=d: rx.decode_stream(d)), best_us(lambda d=d: rx.decode(d))))
    old, new = Codec(1, 51), Codec(1, 51)
    sensor = (1, *([0.1] * 13), 0x1FFF)
    controls = (123, [0.1, 0.2] + [0.0] * 14, 128, 0)
    rows.append(("encode a HIL_SENSOR", best_us(lambda: old.pack(old.mav.hil_sensor_encode(*sensor))),
                 best_us(lambda: new.encode("hil_sensor", *sensor))))
    rows.append(("encode a HIL_ACTUATOR_CONTROLS",
                 best_us(lambda: old.pack(old.mav.hil_actuator_controls_encode(*controls))),
                 best_us(lambda: new.encode("hil_actuator_controls", *controls))))
    old_guidance = sys.modules["guidance_b0a120d"] = types.ModuleType("guidance_b0a120d")
    exec(subprocess.run(["git", "show", "b0a120d:autopilot_bridge/guidance.py"], cwd=REPO, check=True,
                        capture_output=True, text=True).stdout, old_guidance.__dict__)
    t = np.linspace(0, 60, 400)
    path = np.c_[t * 2.0, 10 * np.sin(t / 5)]
    north, east = float(path[110, 0]) + 0.3, float(path[110, 1]) - 0.2
    timed = []
    for cls in (old_guidance.LineOfSight, LineOfSight):
        los = cls(path, 5.0, 2.0)

        def update(los=los) -> None:
            los.index = 100
            los.update(north, east, 6.0)
        timed.append(best_us(update))
    rows.append(("LOS guidance, LineOfSight.update", *timed))
    print(f"{'':84s} {'old us':>8s} {'new us':>8s}")
    for name, a, b in rows:
        print(f"{name:84s} {a:8.1f} {b:8.1f}")
    loop.close()
    sys.stdout.flush()
    os._exit(0)   # the in-process loop's planner worker: no interpreter teardown


if __name__ == "__main__":
    sys.exit(main())
