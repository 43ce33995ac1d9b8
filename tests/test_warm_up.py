"""The first run's compile in parallel processes (hil/warm_up.py, issue 32 point 4)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hil import warm_up
from hil.hilrun import free_udp_port

REPO = Path(__file__).resolve().parent.parent

HOLD = textwrap.dedent("""
    import fcntl, sys
    fh = open(sys.argv[1], "a")
    fcntl.flock(fh, fcntl.LOCK_EX)
    print("held", flush=True)
    sys.stdin.readline()
""")


def test_wait_for_waits_while_a_group_is_being_compiled(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))   # a lock file of this test's own
    path = warm_up.lock_path("planner")
    path.unlink(missing_ok=True)
    assert warm_up.wait_for("planner") == 0.0               # nobody ever compiled: no wait
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert warm_up.wait_for("planner", timeout_s=0.3) >= 0.3   # still held: gives up at the limit
        assert holder.stdin is not None
        holder.stdin.write("\n")
        holder.stdin.flush()
        assert holder.wait(timeout=30) == 0
        assert warm_up.wait_for("planner", timeout_s=30.0) < 30.0  # released: returns
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.wait()
        path.unlink(missing_ok=True)


def test_lock_files_are_per_numba_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "a"))
    a = warm_up.lock_path("planner")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "b"))
    assert warm_up.lock_path("planner") != a != warm_up.lock_path("vessel-computer")


def test_an_unknown_group_is_a_usage_error():
    r = subprocess.run([sys.executable, "-m", "hil.warm_up", "planer"], cwd=REPO, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "usage" in r.stderr


BUILD = textwrap.dedent("""
    import json, sys
    from numba.core import event
    compiled = []
    class Count(event.Listener):
        def on_start(self, ev):
            d = ev.data["dispatcher"]
            compiled.append(f"{d.py_func.__module__}.{d.py_func.__name__}")
        def on_end(self, ev):
            pass
    event.register("numba:compile", Count())
    from hil import settings
    from hil.assembly import build
    cfg = settings.load(None, sys.argv[1:])
    autopilot, link = build(cfg, "harbour", lockstep=True)
    link.close()
    autopilot.worker.close()
    print(json.dumps(compiled))
""")


@pytest.mark.slow
def test_after_the_groups_the_vessel_computer_compiles_nothing(tmp_path):
    """A cold cache filled by the run's groups: building the vessel computer as `hil run` does
    (planner warm-up, navigation filter, guidance, obstacle map, plan check, global route) loads
    every kernel from the cache, none is compiled again. Several minutes of CPU on a cold cache."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    for group in ("simulator", *warm_up.RUN_GROUPS):   # the simulator's group holds the geodesy
        # as `hil run` starts them: only the configured planner's tree core, its tree reuse (seed_tree)
        # in the vessel computer's group; the build below then compiles nothing (the types match)
        algorithm = ["--algorithm", "ddrrt-star"] if group in ("planner", "vessel-computer") else []
        r = subprocess.run([sys.executable, "-m", "hil.warm_up", "--json", *algorithm, group], cwd=REPO, env=env,
                           capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-2000:]
        figures = json.loads(r.stdout.splitlines()[-1])
        assert figures["group"] == group and figures["cpu_s"] > 0
    sets = [f'autopilot.listen="127.0.0.1:{free_udp_port()}"',
            f'autopilot.actuators_to=["127.0.0.1:{free_udp_port()}"]', "gcs.endpoints=[]"]
    r = subprocess.run([sys.executable, "-c", BUILD, *sets], cwd=REPO, env=env, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    compiled = json.loads(r.stdout.splitlines()[-1])
    assert compiled == [], compiled
    from hil import settings
    assert settings.load().planner.algorithm == "ddrrt-star"   # the default the groups compiled for


def test_kernel_times_count_each_function_and_its_specialisations():
    """`hil warm-up --kernels`: numba's compile events, each function's CPU exclusive of its callees."""
    from numba import njit

    times = warm_up.KernelTimes()
    times.install()
    try:

        @njit
        def inner(x):
            return x + 1

        @njit
        def outer(x):
            return inner(x) * 2

        assert outer(1) == 4 and outer(1.5) == 5.0   # two specialisations of each
        name = f"{__name__}.test_kernel_times_count_each_function_and_its_specialisations.<locals>"
        assert times.count[f"{name}.outer"] == 2 and times.count[f"{name}.inner"] == 2
        assert all(v >= 0.0 for v in times.exclusive.values())
        top = times.top(50)
        assert {r["kernel"] for r in top} >= {f"{name}.outer", f"{name}.inner"}
        assert top[-1]["kernel"].startswith("numba (")
    finally:
        times.uninstall()



def test_the_vessel_computers_kernels_compile_at_numba_opt_1_unless_the_user_sets_another_level(monkeypatch):
    from hil import numba_env

    monkeypatch.delenv("NUMBA_OPT", raising=False)
    numba_env.apply()
    assert os.environ["NUMBA_OPT"] == "1"
    monkeypatch.setenv("NUMBA_OPT", "3")
    numba_env.apply()
    assert os.environ["NUMBA_OPT"] == "3"
    assert numba_env.LOW_OPT_GROUPS == ("planner", "vessel-computer")   # not the simulator's
    # `hil autopilot` sets it before it builds the vessel computer (a bad scenario stops it right after)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_OPT"}
    probe = ("import os; from hil.cli import main; "
             "code = main(['autopilot', '--scenario', 'no-such-scenario']); print(code, os.environ.get('NUMBA_OPT'))")
    r = subprocess.run([sys.executable, "-c", probe], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert r.stdout.splitlines()[-1] == "2 1", (r.stdout, r.stderr)


ONE_PLANNER = textwrap.dedent("""
    import json, sys
    import planner
    from planner import _tree
    planner.warm_up_info((sys.argv[1],))
    print(json.dumps([len(_tree.grow_ddrrt.signatures), len(_tree.grow_rrt.signatures)]))
""")


@pytest.mark.parametrize("algorithm, kernels", [("ddrrt-star", [1, 0]), ("rrt-star", [0, 1]),
                                                ("informed-rrt-star", [0, 1])])
def test_a_run_compiles_only_the_tree_core_of_its_planner(algorithm, kernels):
    """`hil run`'s planner group (`--algorithm`): DDRRT*'s tree core and RRT*'s are two kernels,
    and a process warmed up for one planner loads or compiles only that one."""
    r = subprocess.run([sys.executable, "-c", ONE_PLANNER, algorithm], cwd=REPO, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout.splitlines()[-1]) == kernels


REUSE_ONLY = textwrap.dedent("""
    import json, sys
    import planner
    from planner import _tree
    planner.warm_up_tree_reuse((sys.argv[1],))
    print(json.dumps([len(_tree.grow_ddrrt.signatures), len(_tree.grow_rrt.signatures),
                      len(_tree.seed_tree.signatures)]))
""")


def test_the_tree_reuse_compiles_without_the_tree_core():
    """The vessel computer's group compiles `seed_tree` while the planner's compiles the tree core:
    searches of 0 iterations from a reused tree never call (so never compile) a tree core."""
    r = subprocess.run([sys.executable, "-c", REUSE_ONLY, "ddrrt-star"], cwd=REPO, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout.splitlines()[-1]) == [0, 0, 1]


PNG_ONLY = textwrap.dedent("""
    import json, sys
    import planner
    from planner import _png, _tree
    if sys.argv[2] == "png":
        planner.warm_up_png((sys.argv[1],))
    else:
        planner.warm_up_info((sys.argv[1],), tree_reuse=False, png=False)
    print(json.dumps([len(_tree.grow_ddrrt.signatures), len(_tree.grow_rrt.signatures),
                      len(_png.raw_target.signatures), len(_png.repair.signatures)]))
""")


@pytest.mark.parametrize("algorithm, part, kernels", [("ddrrt-star", "png", [0, 0, 1, 1]),
                                                      ("ddrrt-star", "searches", [1, 0, 0, 0]),
                                                      ("rrt-star", "png", [0, 0, 0, 0])])
def test_the_png_kernels_and_the_tree_core_compile_apart(algorithm, part, kernels):
    """`hil run`'s vessel computer's group compiles the PGNode's kernels (DDRRT* only: RRT* has no
    PGNode) while the planner's compiles the tree core: the PGNode alone never calls a tree core,
    and the planner group's searches without a PGNode never call its kernels."""
    r = subprocess.run([sys.executable, "-c", PNG_ONLY, algorithm, part], cwd=REPO, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout.splitlines()[-1]) == kernels


def test_an_unknown_planner_is_refused():
    import planner

    with pytest.raises(ValueError, match="unknown planner"):
        planner.warm_up_info(("rrt-sharp",))
    r = subprocess.run([sys.executable, "-m", "hil.warm_up", "--algorithm", "rrt-sharp", "planner"], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "usage" in r.stderr
