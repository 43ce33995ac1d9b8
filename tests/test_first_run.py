"""The first-run notice (hil.first_run): cold numba caches are found without importing numba."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

from hil import first_run


def test_an_empty_cache_is_cold_and_the_notice_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert first_run.kernels_cold()
    line = first_run.compile_notice("run")
    assert line is not None and f"compiling numba kernels, first run only, ~{first_run.COLD_COMPILE_S} s of CPU" in line
    assert "shared by 3 processes" in first_run.compile_notice("run", processes=3)
    assert first_run.kernels_cold(first_run.PLANNER_SOURCES)


def _fake_cache(root, newer: bool) -> None:
    tag = f"py{sys.version_info[0]}{sys.version_info[1]}"
    for rel in first_run.KERNEL_SOURCES:
        src = first_run.REPO / rel
        d = root / f"{src.parent.name}_0123abcd"
        d.mkdir(exist_ok=True)
        index = d / f"{src.stem}.kernel-12.{tag}.nbi"
        index.write_bytes(b"")
        t = src.stat().st_mtime + (10 if newer else -10)
        os.utime(index, (t, t))


def test_a_fresh_cache_is_warm_and_a_stale_one_cold(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    _fake_cache(tmp_path, newer=True)
    assert not first_run.kernels_cold() and first_run.compile_notice("run") is None
    _fake_cache(tmp_path, newer=False)      # a source changed since: numba recompiles
    assert first_run.kernels_cold()


def test_the_index_file_names_are_numbas(tmp_path, monkeypatch):
    """A real numba cache entry (a tiny cached function compiled in a subprocess) is found."""
    src = tmp_path / "pkg" / "kern.py"
    src.parent.mkdir()
    src.write_text(textwrap.dedent("""
        from numba import njit

        @njit(cache=True)
        def twice(x):
            return 2 * x
    """))
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(src.parent))
    subprocess.run([sys.executable, "-c", "import kern; kern.twice(2)"], check=True, env=env, timeout=120)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    assert first_run._index_files(src)


def test_hil_plan_asks_only_about_the_planner_kernels(tmp_path, monkeypatch):
    """The planner's cache alone decides `hil plan`'s notice (a run's other kernels may be cold)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    _fake_cache(tmp_path, newer=True)
    for rel in first_run.KERNEL_SOURCES:
        if rel not in first_run.PLANNER_SOURCES:
            for p in first_run._index_files(first_run.REPO / rel):
                p.unlink()
    assert first_run.kernels_cold()
    assert not first_run.kernels_cold(first_run.PLANNER_SOURCES)


def test_a_planner_whose_tree_core_is_not_cached_is_cold(tmp_path, monkeypatch):
    """A run compiles only its planner's tree core (planner._tree.grow_kernel): with DDRRT*'s
    cached, a run with RRT* still compiles, and says so."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    _fake_cache(tmp_path, newer=True)
    tag = f"py{sys.version_info[0]}{sys.version_info[1]}"
    src = first_run.REPO / first_run.TREE_SOURCE
    index = tmp_path / f"{src.parent.name}_0123abcd" / f"{src.stem}.grow_ddrrt-1160.{tag}.nbi"
    index.write_bytes(b"")
    t = src.stat().st_mtime + 10
    os.utime(index, (t, t))
    assert not first_run.kernels_cold() and not first_run.kernels_cold(algorithm="ddrrt-star")
    assert first_run.kernels_cold(algorithm="rrt-star") and first_run.kernels_cold(algorithm="informed-rrt-star")
    assert first_run.compile_notice("run", algorithm="rrt-star") is not None
    assert first_run.compile_notice("run", algorithm="ddrrt-star") is None


def test_the_tree_core_names_are_the_kernels_of_planner_tree():
    from planner import _tree
    from planner.params import ALGORITHM_NAMES

    for name in ALGORITHM_NAMES:
        code = _tree.DDRRT_STAR if name == "ddrrt-star" else _tree.RRT_STAR
        assert getattr(_tree, first_run.tree_core(name)) is _tree.grow_kernel(code)
