"""Where a lockstep step's wall time goes: the four legs of each step, from the time stamps of
every datagram the simulator and the vessel computer send and read.

    python docs/experiments/loop/timeline.py [hil run options...]
    python docs/experiments/loop/timeline.py --scenario labyrinth --duration 60

Runs ``hil run --lockstep --no-plot`` (default ``--duration 150``, harbour) with a ``sitecustomize``
(written to a temporary folder put first on ``PYTHONPATH``; nothing of the project changes) that
wraps ``common.udp.UdpEndpoint.send`` and ``_read_one`` to note ``time.perf_counter()`` (one clock
for all processes on Linux) and, through ``gc.callbacks``, every garbage collection over 100 µs.
It then prints, over the steps after the first fifth of the run:

* the legs of a step: simulator sends -> vessel computer reads -> it sends the command -> the
  simulator reads it -> it sends the next frame (p50, mean, p90);
* how the wall time splits between short and long steps;
* the step's phases (its index modulo 10, 20 and 100: the 10 Hz, 5 Hz and 1 Hz work of each end)
  whose mean step is the longest, with each end's turn in them;
* the phases modulo 100 that hold most of the time over 300 µs a step (the planning cycle's), each
  with its four legs and its step, mean and median;
* the four legs and the step of each phase modulo 20 (medians), the planning cycle's phases left
  out (0-2 and 30-31 modulo 100: the request goes out after frame 0's command, the answer is due
  at frame 30);
* the long garbage collections of each process.

The stamps cost ~1 µs each, two a datagram. docs/performance.md has the figures of this machine.
"""

from __future__ import annotations

import bisect
import glob
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]

HOOK = r'''
import gc, json, os, sys, time
import builtins
_stamps, _gcs, _pc, _t = [], [], time.perf_counter, [0.0]
def _on_gc(phase, info):
    if phase == "start":
        _t[0] = _pc()
    elif _pc() - _t[0] > 100e-6:
        _gcs.append((info["generation"], _t[0], _pc()))
gc.callbacks.append(_on_gc)
_import, _done = builtins.__import__, [False]
def _patch():
    E = sys.modules["common.udp"].UdpEndpoint
    send, read = E.send, E._read_one
    def send_(self, data):
        _stamps.append(("s", _pc(), self.address[1]))
        return send(self, data)
    def read_(self, budget=None):
        d = read(self, budget)
        if d is not None:
            _stamps.append(("r", _pc(), self.address[1]))
        return d
    E.send, E._read_one = send_, read_
def _hooked_import(name, *a, **k):
    m = _import(name, *a, **k)
    if not _done[0] and hasattr(sys.modules.get("common.udp"), "UdpEndpoint"):
        _done[0] = True
        _patch()
    return m
builtins.__import__ = _hooked_import
def _dump():
    with open(os.path.join(os.environ["HIL_TIMELINE_DIR"], f"stamps.{os.getpid()}.json"), "w") as fh:
        json.dump({"argv": sys.argv, "stamps": _stamps, "gc": _gcs}, fh)
import atexit
atexit.register(_dump)
_exit = os._exit
def _exit_(code):
    _dump()
    _exit(code)
os._exit = _exit_
'''


def _after(times: list[float], t: float) -> float | None:
    i = bisect.bisect_right(times, t)
    return times[i] if i < len(times) else None


def _q(xs: list[float]) -> str:
    xs = sorted(xs)
    return (f"p50 {1e6 * xs[len(xs) // 2]:7.1f}  mean {1e6 * sum(xs) / len(xs):7.1f}  "
            f"p90 {1e6 * xs[int(0.9 * len(xs))]:7.1f} us")


def _phase_tables(phases: list[tuple[int, float, float, float]], legs: list[list[float]]) -> None:
    rows: dict[int, list[list[float]]] = {}
    for i, (k, *_turns, step) in enumerate(phases):
        rows.setdefault(k, []).append([legs[j][i] for j in range(4)] + [step])
    by100: dict[int, list[list[float]]] = {}
    by20: dict[int, list[list[float]]] = {}
    for k, rs in rows.items():
        by100.setdefault(k % 100, []).extend(rs)
        if k % 100 not in (0, 1, 2, 30, 31):
            by20.setdefault(k % 20, []).extend(rs)
    excess = {ph: sum(max(0.0, r[4] - 300e-6) for r in rs) for ph, rs in by100.items()}
    total = sum(excess.values()) or 1.0

    def cells(rs: list[list[float]], stat: str) -> str:
        cols = [sorted(r[j] for r in rs) for j in range(5)]
        vals = [sum(c) / len(c) if stat == "mean" else c[len(c) // 2] for c in cols]
        return " ".join(f"{1e6 * v:6.0f}" for v in vals)

    print("  legs (sim sends->vc reads, vc turn, command->sim reads, sim turn) and step, us")
    for ph in sorted(excess, key=lambda p: -excess[p])[:6]:
        print(f"    phase {ph:2d} mod 100 ({100 * excess[ph] / total:4.1f} % of the time over 300 us): "
              f"mean {cells(by100[ph], 'mean')}  median {cells(by100[ph], 'median')}")
    for ph in sorted(by20):
        print(f"    phase {ph:2d} mod 20, planning phases left out: median {cells(by20[ph], 'median')}")


def main(argv: list[str]) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, "sitecustomize.py").write_text(HOOK)
        env = dict(os.environ, HIL_TIMELINE_DIR=tmp,
                   PYTHONPATH=os.pathsep.join([tmp, str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        options = argv if "--duration" in argv else ["--duration", "150", *argv]
        out = Path(tmp, "run")
        cmd = [sys.executable, "-m", "hil", "run", "--lockstep", "--no-plot", "--out", str(out), *options]
        done = subprocess.run(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode not in (0, 1):
            print(f"hil run failed ({done.returncode}): {done.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
            return 1
        runs = {}
        for f in glob.glob(os.path.join(tmp, "stamps.*.json")):
            d = json.load(open(f))
            runs[d["argv"][1] if len(d["argv"]) > 1 else "?"] = d
        summary = json.load(open(out / "summary.json"))
    sim, ap = runs["sim"]["stamps"], runs["autopilot"]["stamps"]
    port = next(p for kind, _, p in ap if kind == "r")            # the vessel computer's HIL socket
    sent = [t for kind, t, _ in sim if kind == "s"]
    sim_reads = [t for kind, t, _ in sim if kind == "r"]
    ap_reads = [t for kind, t, p in ap if kind == "r" and p == port]
    commands = [t for kind, t, p in ap if kind == "s" and p == port]
    legs: list[list[float]] = [[], [], [], []]
    steps = []
    phases = []   # (step index, vessel computer's turn, simulator's turn, step)
    for k in range(len(sent) // 5, len(sent) - 10):
        r = _after(ap_reads, sent[k])
        c = _after(commands, r) if r is not None else None
        d = _after(sim_reads, c) if c is not None else None
        s2 = _after(sent, d) if d is not None else None
        if s2 is None:
            continue
        for leg, v in zip(legs, (r - sent[k], c - r, d - c, s2 - d), strict=True):
            leg.append(v)
        steps.append(sent[k + 1] - sent[k])
        phases.append((k, c - r, s2 - d, sent[k + 1] - sent[k]))
    print(f"{len(steps)} steps; hil run: {summary['simulator']['stepping']}")
    for name, leg in zip(("simulator sends -> vessel computer reads", "vessel computer reads -> sends the command",
                          "command -> simulator reads", "simulator reads -> sends the next frame"), legs, strict=True):
        print(f"  {name:44s} {_q(leg)}")
    print(f"  {'a step':44s} {_q(steps)}")
    total = sum(steps)
    for lo, hi in ((0, 300e-6), (300e-6, 500e-6), (500e-6, 1e-3), (1e-3, 3e-3), (3e-3, float("inf"))):
        xs = [s for s in steps if lo <= s < hi]
        print(f"  steps of {1e6 * lo:5.0f}-{1e6 * hi:5.0f} us: {len(xs):6d} ({100 * len(xs) / len(steps):4.1f} %), "
              f"{100 * sum(xs) / total:4.1f} % of the wall time")
    for mod in (10, 20, 100):
        by: dict[int, list[tuple[float, float, float]]] = {}
        for k, ap_turn, sim_turn, step in phases:
            by.setdefault(k % mod, []).append((ap_turn, sim_turn, step))
        means = sorted(((sum(x[2] for x in v) / len(v), ph, sum(x[0] for x in v) / len(v),
                        sum(x[1] for x in v) / len(v)) for ph, v in by.items()), reverse=True)
        median = means[len(means) // 2][0]
        print(f"  steps by phase mod {mod:3d} (median phase {1e6 * median:6.1f} us); the longest: " + "; ".join(
            f"{ph}: step {1e6 * st:.0f}, vessel computer {1e6 * a:.0f}, simulator {1e6 * s:.0f} us"
            for st, ph, a, s in means[:3]))
    _phase_tables(phases, legs)
    first = sent[len(sent) // 5]
    for name, d in sorted(runs.items()):
        long_gcs = [(g, t1 - t0) for g, t0, t1 in d["gc"] if t0 >= first]
        worst = max((dt for _, dt in long_gcs), default=0.0)
        print(f"  {name}: {len(long_gcs)} collections over 100 us, the longest {1e3 * worst:.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
