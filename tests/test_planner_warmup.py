"""Timing that measures the planner: every worker warms up before its first timed solve, and a
campaign's results do not depend on the number of workers."""

from __future__ import annotations

import math

from hil import experiment


def _signatures():
    from planner import _kernels, _tree

    out = set()
    for mod in (_tree, _kernels):
        for name, obj in vars(mod).items():
            for sig in getattr(obj, "signatures", ()):
                out.add((mod.__name__, name, str(sig)))
    return out


def test_warm_up_compiles_every_specialisation_the_online_loop_uses():
    """After planner.warm_up(), a Table 3 run (every algorithm, current field and length
    objective) compiles nothing new: the first timed search does not pay numba."""
    import planner

    planner.warm_up()
    before = _signatures()
    for alg in experiment.ALGORITHMS:
        for objective in ("length", None):
            task = experiment.Task("labyrinth", 0, alg, 3, (("local_iterations", 200), ("cycle_time", 8.0)),
                                   objective=objective)
            row = experiment.run_task(task)
            assert row["cycles"] > 0
    assert _signatures() - before == set()


def test_each_worker_warms_up_with_the_planner():
    """The campaign's per-worker warm-up (hil.executors runs it once per worker) is planner.warm_up()."""
    import planner.registry as registry
    from hil import executors

    executors._warm_once(experiment.warm_up)
    assert registry._WARM is not None and registry._WARM.seconds >= 0


def test_campaign_rows_identical_for_any_jobs():
    tasks = experiment.make_tasks("labyrinth", 2, experiment.ALGORITHMS, 9,
                                  {"local_iterations": 300, "cycle_time": 8.0}, None, (), 0, "length")
    one = experiment.run_campaign(tasks, 1)
    two = experiment.run_campaign(tasks, 2)

    def key(rows):
        return sorted((tuple(r[k] for k in experiment.DETERMINISTIC) for r in rows), key=lambda t: (t[0], t[1]))

    a, b = key(one.rows), key(two.rows)
    assert len(a) == 6
    for ra, rb in zip(a, b, strict=False):
        for x, y in zip(ra, rb, strict=False):
            assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
