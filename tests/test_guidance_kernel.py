"""The compiled guidance of autopilot_bridge.guidance (closest-point search, curvature preview, and
the whole LineOfSight.update in one call) gives, bit for bit, what the numpy expressions it replaced
gave (kept here as the reference), on random paths, positions on vertices and segments, far away,
and with NaN."""

from __future__ import annotations

import math
import struct

import numpy as np

from autopilot_bridge.guidance import WINDOW, LineOfSight


def reference_closest(los: LineOfSight, north: float, east: float) -> tuple[int, float]:
    p = np.array([north, east])
    lo, hi = los.index, min(los.index + WINDOW, len(los.seg))
    a, d, ln = los.path[lo:hi], los.seg[lo:hi], los.seg_len[lo:hi]
    s_all = np.minimum(np.maximum(np.einsum("ij,ij->i", p - a, d) / (ln * ln), 0.0), 1.0)
    gap = a + s_all[:, None] * d - p
    dist = np.einsum("ij,ij->i", gap, gap)
    k = int(np.argmin(dist))
    return lo + k, float(s_all[k])


def reference_curvature_ahead(los: LineOfSight, index: int, along: float, preview: float) -> float:
    start = los.cum[index] + along
    hi = int(np.searchsorted(los.cum, start + preview, side="right"))
    k = los.vertex_curvature[index:max(index, hi - 1)]
    return float(k.max()) if len(k) else 0.0


def reference_curvature_at(los: LineOfSight, index: int, along: float, span: float = 1.0) -> float:
    s = los.cum[index] + along
    lo = int(np.searchsorted(los.cum, s - span, side="left"))
    hi = int(np.searchsorted(los.cum, s + span, side="right"))
    k = los.signed_curvature[max(lo - 1, 0):max(hi - 1, 0)]
    return float(k.sum()) / len(k) if len(k) else 0.0


def reference_update(los: LineOfSight, north: float, east: float, preview: float) -> tuple[float, ...]:
    """LineOfSight.update as it was written in Python and numpy (the kernels before it as above)."""
    p = np.array([north, east])
    i, s = reference_closest(los, north, east)
    d = los.seg[i]
    pi_p = math.atan2(d[1], d[0])
    a = los.path[i]
    e = -(p[0] - a[0]) * math.sin(pi_p) + (p[1] - a[1]) * math.cos(pi_p)
    remaining = float(los.cum[-1] - (los.cum[i] + s * los.seg_len[i]))
    end_dist = float(np.hypot(*(los.path[-1] - p)))
    heading = pi_p - math.atan2(e, los.lookahead)
    if remaining < los.lookahead:
        heading = math.atan2(los.path[-1][1] - east, los.path[-1][0] - north) if end_dist > 1e-6 else pi_p
    return (i, heading, e, remaining, float(end_dist <= los.acceptance_radius),
            reference_curvature_ahead(los, i, s * los.seg_len[i], preview),
            reference_curvature_at(los, i, s * los.seg_len[i]))


def bits(x: float) -> bytes:
    return struct.pack("<d", x)


def random_path(rng: np.random.Generator) -> np.ndarray:
    n = int(rng.integers(2, 200))
    kind = rng.integers(3)
    if kind == 0:      # a smooth sampled curve, as the Dubins smoother writes them
        t = np.linspace(0.0, rng.uniform(5, 300), n)
        return np.c_[t * rng.uniform(0.2, 2), rng.uniform(1, 30) * np.sin(t / rng.uniform(2, 20))]
    if kind == 1:      # a random polyline, on a grid (exact zeros, repeated points, folds)
        return rng.integers(-5, 6, size=(n, 2)).astype(float) * rng.choice([0.5, 1.0, 3.0])
    return np.cumsum(rng.normal(0, rng.uniform(0.01, 20), size=(n, 2)), axis=0) + rng.uniform(-1e5, 1e5, 2)


def test_closest_point_and_curvature_match_numpy_bit_for_bit() -> None:
    rng = np.random.default_rng(2024)
    checked = 0
    for _ in range(400):
        try:
            los = LineOfSight(random_path(rng), float(rng.uniform(1, 10)), 1.0)
        except ValueError:
            continue     # a path of one point
        for _ in range(25):
            los.index = int(rng.integers(0, len(los.seg)))
            j = int(rng.integers(0, len(los.path)))
            pick = rng.integers(4)
            if pick == 0:     # exactly on a vertex
                north, east = float(los.path[j, 0]), float(los.path[j, 1])
            elif pick == 1:   # near the path
                north, east = (float(v) for v in los.path[j] + rng.normal(0, 2, 2))
            elif pick == 2:   # far away
                north, east = (float(v) for v in rng.uniform(-1e6, 1e6, 2))
            else:             # on a segment, at a round fraction
                k = min(j, len(los.seg) - 1)
                f = float(rng.choice([0.0, 0.25, 0.5, 1.0]))
                north, east = (float(v) for v in los.path[k] + f * los.seg[k])
            start = los.index
            want = reference_closest(los, north, east)
            preview = float(rng.uniform(0, 30))
            want_ahead = reference_curvature_ahead(los, want[0], want[1] * float(los.seg_len[want[0]]), preview)
            whole = reference_update(los, north, east, preview)
            out = los.update(north, east, preview)
            assert los.index == want[0], (start, north, east)
            got_whole = (los.index, out.heading, out.cross_track, out.remaining, float(out.finished),
                         out.curvature_ahead, out.curvature)
            assert [bits(v) for v in got_whole] == [bits(v) for v in whole], (start, north, east)
            los.index = start
            from autopilot_bridge.guidance import _closest

            got = _closest(los.path, los.seg, los.seg_len, start, min(start + WINDOW, len(los.seg)), north, east)
            assert got[0] == want[0] and bits(got[1]) == bits(want[1])
            assert bits(out.curvature_ahead) == bits(want_ahead)
            checked += 1
    assert checked > 5000


def test_nan_and_infinite_positions_pick_what_argmin_picks() -> None:
    path = np.c_[np.arange(10.0), np.zeros(10)]
    for north, east in ((math.nan, 0.0), (0.0, math.nan), (math.inf, 0.0), (-math.inf, 1.0), (1e308, -1e308)):
        los = LineOfSight(path, 2.0, 1.0)
        los.index = 3
        want = reference_closest(los, north, east)
        with np.errstate(invalid="ignore", over="ignore"):   # the point here is the index, not the NaN error
            los.update(north, east, 5.0)
        assert los.index == want[0]


def test_a_nan_curvature_wins_the_preview_as_in_numpy() -> None:
    los = LineOfSight(np.c_[np.arange(10.0), np.arange(10.0) ** 2 / 10], 2.0, 1.0)
    los.vertex_curvature = los.vertex_curvature.copy()
    los.vertex_curvature[4] = math.nan
    got, want = los.curvature_ahead(2, 0.0, 20.0), reference_curvature_ahead(los, 2, 0.0, 20.0)
    assert math.isnan(got) and math.isnan(want)
    assert bits(los.curvature_ahead(5, 0.1, 0.0)) == bits(reference_curvature_ahead(los, 5, 0.1, 0.0))


def test_the_compiled_sum_is_numpys_sum_bit_for_bit() -> None:
    """The curvature's mean sums as numpy does (pairwise, 8 accumulators): on slices of every length
    up to 300 and longer ones (several levels of halving), of values over six orders of magnitude,
    signed zeros included."""
    from autopilot_bridge.guidance import _pairwise_sum

    rng = np.random.default_rng(17)
    for _ in range(3000):
        n = int(rng.integers(0, 300))
        a = rng.standard_normal(n + 10) * 10.0 ** rng.uniform(-3, 3, n + 10)
        a[rng.random(n + 10) < 0.05] = -0.0
        lo = int(rng.integers(0, 10))
        assert bits(_pairwise_sum(a, lo, n)) == bits(float(a[lo:lo + n].sum())), (lo, n)
    for n in [*range(120, 1100, 7), 1024, 2047, 2048, 4096, 5000]:   # several levels of halving
        a = rng.standard_normal(n + 10) * 10.0 ** rng.uniform(-3, 3, n + 10)
        lo = int(rng.integers(0, 10))
        assert bits(_pairwise_sum(a, lo, n)) == bits(float(a[lo:lo + n].sum())), (lo, n)


def test_the_yaw_feed_forward_curvature_matches_numpy_around_every_vertex() -> None:
    rng = np.random.default_rng(5)
    for _ in range(200):
        try:
            los = LineOfSight(random_path(rng), 2.0, 1.0)
        except ValueError:
            continue
        for _ in range(10):
            i = int(rng.integers(0, len(los.seg)))
            along = float(rng.uniform(0, 1)) * float(los.seg_len[i])
            span = float(rng.choice([0.0, 0.5, 1.0, 7.0, 1e9]))
            assert bits(los.curvature_at(i, along, span)) == bits(reference_curvature_at(los, i, along, span))


def test_the_compiled_search_is_numpys_searchsorted() -> None:
    from autopilot_bridge.guidance import _search

    rng = np.random.default_rng(7)
    arrays = [np.array([]), np.array([1.0]), np.array([0.0, 0.0, 0.0]), np.array([-np.inf, 0.0, np.inf]),
              np.array([0.0, 1.0, np.nan, np.nan]), np.array([np.nan])]
    arrays += [np.sort(rng.integers(0, 6, n).astype(float)) for n in (2, 5, 17, 64)]
    arrays += [np.cumsum(rng.random(n)) for n in (3, 40, 333)]
    for a in arrays:
        values = [*a, np.nan, np.inf, -np.inf, -1.0, 0.5, 2.5, 1e9, *rng.uniform(-1, 8, 20)]
        for v in values:
            for side in ("left", "right"):
                got = _search(a, float(v), np.bool_(side == "right"))
                assert got == int(np.searchsorted(a, v, side=side)), (a, v, side)
