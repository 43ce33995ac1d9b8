"""Issue 30 point 4: one planner registry (planner.params.REGISTRY). Adding a planner is its class
and one table entry: make_planner, the warm-up, the commands' choices, the campaign's labels and
seeds and the figures' colours all read the table, and the shared solve loop knows no subclass."""

from __future__ import annotations

import ast
import inspect
import typing
from pathlib import Path

import pytest

import planner
from hil import experiment
from hil.commands import plan
from planner import core, registry
from planner.params import ALGORITHM_NAMES, REGISTRY, PlannerParams

REPO = Path(__file__).resolve().parent.parent


def test_every_consumer_reads_the_table():
    assert ALGORITHM_NAMES == tuple(e.name for e in REGISTRY)
    assert planner.ALGORITHMS is ALGORITHM_NAMES and experiment.ALGORITHMS is ALGORITHM_NAMES
    assert plan.ALGORITHMS is ALGORITHM_NAMES
    assert experiment.LABELS == {e.name: e.label for e in REGISTRY}
    assert typing.get_args(typing.get_type_hints(PlannerParams)["algorithm"]) == ALGORITHM_NAMES
    for e in REGISTRY:
        p = planner.make_planner(e.name, PlannerParams(algorithm=e.name), seed=1)
        assert type(p) is registry.planner_class(e.name) and p.name == e.name
    with pytest.raises(ValueError, match="unknown planner"):
        planner.make_planner("rrt-sharp", PlannerParams())


def test_a_new_entry_is_built_and_warmed_up_from_the_table(monkeypatch):
    from planner.rrt_star import RRTStar

    class Twin(RRTStar):
        name = "twin-rrt-star"

    import sys
    import types

    mod = types.ModuleType("twin_planner")
    mod.Twin = Twin  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "twin_planner", mod)
    entry = REGISTRY[0].__class__("twin-rrt-star", "Twin", "green", "twin_planner:Twin")
    monkeypatch.setattr(registry, "REGISTRY", (*REGISTRY, entry))
    monkeypatch.setitem(registry.ENTRIES, entry.name, entry)
    assert isinstance(registry.make_planner("twin-rrt-star", PlannerParams()), Twin)
    built = []
    real = registry.make_planner

    def spy(name, params, seed=None):
        built.append(name)
        return real(name, params, seed)

    monkeypatch.setattr(registry, "_WARM", None)
    monkeypatch.setattr(registry, "make_planner", spy)
    registry.warm_up_info()
    assert set(built) == set(ALGORITHM_NAMES) | {"twin-rrt-star"}


def test_the_solve_loop_imports_no_concrete_planner():
    tree = ast.parse(inspect.getsource(core))
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    concrete = {e.target.split(":")[0] for e in REGISTRY}
    assert not imported & concrete


def test_figures_and_campaigns_have_no_list_of_their_own():
    """No line of theirs names two planners (a list, tuple or mapping of names of its own: the
    figures once left a fourth planner out); naming one, e.g. RRT* as the baseline, is fine."""
    for rel in ("hil/plots.py", "hil/commands/montecarlo.py", "hil/experiment.py", "hil/benches/planner.py",
                "hil/commands/plan.py", "planner/core.py"):
        for line in (REPO / rel).read_text().splitlines():
            assert sum(f'"{n}"' in line for n in ALGORITHM_NAMES) <= 1, (rel, line)
