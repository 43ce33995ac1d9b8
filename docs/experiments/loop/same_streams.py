"""Do two lockstep runs carry the same simulator frames and the same commands?

    python docs/experiments/loop/same_streams.py RUN_A/run.tlog RUN_B/run.tlog

Compares, frame for frame, the simulator's HIL messages (HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION,
ODOMETRY, OBSTACLE_DISTANCE) and the vessel computer's HIL_ACTUATOR_CONTROLS of two run.tlog
files, ignoring the time stamps and the ground-station telemetry (paced by the wall clock). Runs
of the same scenario, seed and duration agree up to the end of the shorter one: after the last
step, the number of frames re-sent while the processes stop depends on the wall clock. Used to
check that a speed-up of the loop changed no byte of what it computes (docs/performance.md).
Exit status 0 when they agree.
"""

from __future__ import annotations

import sys

SIMULATOR = {107, 113, 115, 330, 331}   # HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION, OBSTACLE_DISTANCE, ODOMETRY
COMMANDS = {93}                         # HIL_ACTUATOR_CONTROLS


def streams(path: str) -> tuple[list[bytes], list[bytes]]:
    """(simulator frames, command frames) of a .tlog: 8-byte time stamp, then one MAVLink frame."""
    data = open(path, "rb").read()
    sim: list[bytes] = []
    cmd: list[bytes] = []
    i = 0
    while i + 8 < len(data):
        i += 8
        if data[i] == 0xFD:
            n = 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
            msg_id = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        else:
            n, msg_id = 8 + data[i + 1], data[i + 5]
        frame = data[i:i + n]
        i += n
        if msg_id in SIMULATOR:
            sim.append(frame)
        elif msg_id in COMMANDS:
            cmd.append(frame)
    return sim, cmd


def main() -> int:
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    a, b = streams(sys.argv[1]), streams(sys.argv[2])
    same = True
    for name, x, y in zip(("simulator frames", "commands"), a, b, strict=True):
        n = min(len(x), len(y))
        first = next((k for k in range(n) if x[k] != y[k]), None)
        same &= first is None and n > 0
        verdict = f"the first {n} identical" if first is None else f"first difference at {first}"
        print(f"{name}: {len(x)} and {len(y)}, {verdict}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
