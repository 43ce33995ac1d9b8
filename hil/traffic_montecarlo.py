"""Monte Carlo over randomised ship traffic: whole HIL runs (lockstep) judged per encounter.

Each run draws its ships from the run's seed (``numpy.random.default_rng([seed, run])``), so a
campaign is repeatable and does not depend on ``--jobs``. A ship is built from three drawn
numbers, in the frame of the USV's nominal voyage along its reference path at cruise speed:

* ``bearing``: the direction (deg, relative to the USV's course at the meeting point, clockwise)
  she comes from; 0 = from ahead (head-on), 90 = from starboard, 180 = from astern;
* ``speed`` (m/s);
* ``miss``: her distance (m, to starboard of her course, negative to port) from the USV's nominal
  position at the meeting time ``meet`` (s), i.e. the CPA both would have without any
  manoeuvre (approximately: exactly when the USV keeps its speed).

She sails at constant velocity through the meeting point offset by ``miss``. Every run's summary
is kept (``runs.csv``, one row per encounter) and the campaign reports the collision rate, the
mean CPA and the COLREGs compliance rate.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from simulator.traffic import ShipSpec

if TYPE_CHECKING:
    from hil.executors import Executor
    from hil.run_summary import RunSummary


@dataclass(frozen=True)
class TrafficDraw:
    """Ranges of the randomised traffic (uniform draws)."""

    ships: int = 1
    bearing: tuple[float, float] = (0.0, 360.0)      # deg
    speed: tuple[float, float] = (0.5, 2.0)          # m/s
    miss: tuple[float, float] = (-6.0, 6.0)          # m
    meet: tuple[float, float] = (45.0, 70.0)         # s
    cruise_speed: float = 1.5                        # m/s of the USV's nominal voyage


def _along(ref: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """Point and unit direction at arc length ``s`` along a polyline (map frame)."""
    seg = np.diff(ref, axis=0)
    lens = np.hypot(seg[:, 0], seg[:, 1])
    acc = np.concatenate([[0.0], np.cumsum(lens)])
    i = int(np.clip(np.searchsorted(acc, s, side="right") - 1, 0, len(seg) - 1))
    u = seg[i] / max(lens[i], 1e-9)
    return ref[i] + u * min(max(s - acc[i], 0.0), lens[i]), u


def draw_ships(reference_path: np.ndarray, draw: TrafficDraw, seed: int, run: int) -> tuple[ShipSpec, ...]:
    """The ships of one run (map frame, as a scenario's [[traffic]])."""
    rng = np.random.default_rng([int(seed), int(run), 0x7AF])
    ref = np.asarray(reference_path, dtype=float)
    ships = []
    for k in range(draw.ships):
        bearing, speed, miss, meet = (rng.uniform(*draw.bearing), rng.uniform(*draw.speed), rng.uniform(*draw.miss),
                                      rng.uniform(*draw.meet))
        meet_pt, u = _along(ref, draw.cruise_speed * meet)
        own_course = math.atan2(u[1], u[0])                          # map angle (ccw from east)
        come_from = own_course - math.radians(bearing)               # clockwise bearing -> ccw angle
        heading = come_from + math.pi                                # she sails towards the meeting point
        h = np.array([math.cos(heading), math.sin(heading)])
        stbd = np.array([h[1], -h[0]])
        start = meet_pt + stbd * miss - h * speed * meet
        course_deg = (90.0 - math.degrees(heading)) % 360.0           # AIS COG: clockwise from north
        ships.append(ShipSpec(mmsi=419000000 + run * 10 + k, start=(float(start[0]), float(start[1])),
                              speed=float(speed), course=float(course_deg), name=f"MC {run}-{k}",
                              bow=4.0, stern=4.0, port=1.5, starboard=1.5))
    return tuple(ships)


@dataclass(frozen=True)
class TrafficJob:
    """One whole lockstep HIL run of a traffic campaign, picklable for any executor: called with
    ``(run, ships)`` it returns the run's summary. The run folder is ``out/runNNNN`` on the host
    that runs it. Each run picks its own UDP ports (:func:`hil.hilrun.free_udp_port` reserves them
    host-wide), so runs sharing a host never collide."""

    scenario: str
    seed: int
    duration: float            # s of simulated time at most
    config: str | None
    overrides: tuple[str, ...]
    out: str                   # campaign folder

    def __call__(self, item: tuple[int, tuple[ShipSpec, ...]]) -> RunSummary:
        from hil import settings
        from hil.hilrun import NO_GCS, RunOptions, run_loop

        i, ships = item
        opts = RunOptions(scenario=self.scenario, lockstep=True, duration=self.duration, seed=self.seed * 1000 + i,
                          config=self.config, overrides=list(self.overrides) + NO_GCS,
                          out=Path(self.out) / f"run{i:04d}", plot=False, traffic=ships,
                          cpus="off")  # runs share the host (hil.placement)
        return run_loop(opts, settings.load(self.config, list(self.overrides) + NO_GCS))


class TrafficRow(TypedDict):
    """One ship of one run of a traffic campaign (a row of runs.csv): where it started (m), its speed
    (m/s) and course (deg), and the judge's verdict (:class:`hil.encounter_report.EncounterVerdict`)."""

    run: int
    outcome: str
    mmsi: int
    start_x: float
    start_y: float
    speed: float
    course_deg: float
    type: str | None
    cpa_m: float | None
    action: str | None
    collision: bool | None
    compliant: bool | None
    note: str


def run_campaign(scenario: str, runs: int, seed: int, draw: TrafficDraw, out: Path, executor: Executor,
                 run_one: Callable[[tuple[int, tuple[ShipSpec, ...]]], RunSummary],
                 progress: Callable[[int, RunSummary], None] = lambda _i, _s: None) -> dict[str, object]:
    """``runs`` HIL runs of ``run_one((run, ships))`` on ``executor`` (:mod:`hil.executors`);
    returns the campaign summary and writes ``runs.csv`` and ``summary.json``. Ctrl-C or SIGTERM keeps
    the finished runs (``interrupted``, ``runs_done``; rates over the runs done)."""
    from hil import scenario as scenarios

    scen = scenarios.load(scenario)
    plans = [(i, draw_ships(scen.reference_path, draw, seed, i)) for i in range(runs)]
    from hil.executors import collect

    results: dict[int, RunSummary] = {}

    def take(i: int, s: RunSummary) -> None:
        results[i] = s
        progress(len(results), s)

    interrupted = collect(executor, run_one, plans, take)
    rows: list[TrafficRow] = []
    for i in sorted(results):       # the same rows in the same order whatever the executor
        s, ships = results[i], plans[i][1]
        for e in s.encounters or ():
            spec = next(sh for sh in ships if sh.mmsi == e["mmsi"])
            rows.append({"run": i, "outcome": s.outcome, "mmsi": e["mmsi"], "start_x": round(spec.start[0], 2),
                         "start_y": round(spec.start[1], 2), "speed": round(spec.speed, 3),
                         "course_deg": round(spec.course, 1), "type": e.get("type"), "cpa_m": e.get("cpa_m"),
                         "action": e.get("action"), "collision": e.get("collision"),
                         "compliant": e.get("compliant"), "note": e.get("note", "")})
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["run"])
        w.writeheader()
        w.writerows(rows)
    risky = [r for r in rows if r["type"] not in ("no risk", "not met", None)]
    cpas = [r["cpa_m"] for r in rows if r["cpa_m"] is not None]
    by_type: dict[str, list[TrafficRow]] = {}
    for r in risky:
        if r["type"] is not None:   # always (``risky`` has a type)
            by_type.setdefault(r["type"], []).append(r)
    summary = {
        "scenario": scenario, "runs": runs, "seed": seed, "interrupted": interrupted, "runs_done": len(results),
        "ships_per_run": draw.ships,
        "draw": {"bearing_deg": draw.bearing, "speed_m_s": draw.speed, "miss_m": draw.miss, "meet_s": draw.meet},
        "outcomes": {k: sum(1 for s in results.values() if s.outcome == k) for k in
                     sorted({s.outcome for s in results.values()})},
        "collision_rate": round(sum(1 for s in results.values() if s.collisions) / max(len(results), 1), 4),
        "mean_cpa_m": round(float(np.mean(cpas)), 2) if cpas else None,
        "min_cpa_m": round(float(np.min(cpas)), 2) if cpas else None,
        "encounters": len(risky),
        "compliance_rate": round(sum(1 for r in risky if r["compliant"]) / len(risky), 4) if risky else None,
        "by_type": {k: {"n": len(v), "compliant": sum(1 for r in v if r["compliant"]),
                        "mean_cpa_m": round(float(np.mean([r["cpa_m"] for r in v])), 2)}
                    for k, v in sorted(by_type.items())},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary
