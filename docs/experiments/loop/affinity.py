"""The vessel computer's frame when it shares a core with the simulator and when it has one of its
own (docs/performance.md, "Busy-polling lockstep"): runs `hil run --lockstep` on harbour, pins the
run's processes (simulator S, autopilot A, hil run's tap T, planner worker P) once they have
started, and prints the loop's speed and the control latency p50 (sensor datagram in -> command out).
Run: python docs/experiments/loop/affinity.py [LAYOUT ...], a layout being CPUs for S,A,T,P, '-' to
leave one to the scheduler, e.g. "0,1,0,0" (the autopilot alone on CPU 1) or "0,0,1,1".
Add `--set sim.lockstep_busy_poll=0 --set autopilot.lockstep_busy_poll=0` after `--` to wait asleep.
The runs take `--cpus off`, so that `hil run`'s own placement (hil/placement.py) leaves the layout
to this script."""
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from hil.placement import children, pin  # noqa: E402

args = sys.argv[1:]
extra = args[args.index("--") + 1:] if "--" in args else []
layouts = (args[:args.index("--")] if "--" in args else args) or ["-,-,-,-", "0,1,0,0", "0,0,1,1"]

for layout in layouts:
    with tempfile.TemporaryDirectory() as tmp:
        run = subprocess.Popen([sys.executable, "-m", "hil", "run", "--lockstep", "--duration", "150", "--no-plot",
                                "--out", tmp, "--cpus", "off", *extra],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(3.0)   # the processes are up and the loop is running (a 150 s run takes ~8-11 s)
        roles = {"T": run.pid}
        for c in children(run.pid):
            cmd = Path(f"/proc/{c}/cmdline").read_bytes().replace(b"\0", b" ")
            roles["S" if b"hil sim" in cmd else "A"] = c
        if "A" in roles and (worker := children(roles["A"])):
            roles["P"] = worker[0]
        for role, cpus in zip("SATP", layout.split(","), strict=True):
            if cpus != "-" and role in roles:
                pin(roles[role], {int(c) for c in cpus.split("+")})
        run.wait()
        s = json.loads((Path(tmp) / "summary.json").read_text())
        print(f"S,A,T,P on {layout:12s} {s['simulator']['stepping']['steps_per_s']:7.0f} steps/s, "
              f"latency p50 {s['control_latency_ms']['p50']:.3f} ms")
