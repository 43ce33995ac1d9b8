"""Eqs. (11)-(12), the encounter angle and the gridded current."""

import math

import numpy as np
import pytest
from numba import njit

from planner import _tree
from planner._kernels import segment_free
from planner.cost import cost_distance, esd, min_cost_factor, path_cost, segment_cost
from planner.field import GridField, encounter_angle
from planner.params import PlannerParams

# Hand values, D_alpha = 1, gamma_alpha = 0.1, Ed = 10 m, DR = 40 m:
#   alpha = 0:    x = cos 0 - 0.1 sin 0 = 1            D_C = 10 / (1 + e)        = 2.689414
#                                                     ESD = 40 / (1 + e^-1)     = 29.242343
#   alpha = pi/3: x = 0.5 - 0.1 * 0.8660254 = 0.4133975
#                                                     D_C = 10 / (1 + 1.511929) = 3.980978
#                                                     ESD = 40 / (1 + 0.661407) = 24.076090
#   alpha = pi/2: x = -0.1                            D_C = 10 / (1 + 0.904837) = 5.249792
#                                                     ESD = 40 / (1 + 1.105171) = 19.000833
#   alpha = pi:   x = -1                              D_C = 10 / (1 + e^-1)     = 7.310586
#                                                     ESD = 40 / (1 + e)        = 10.757657
HAND = [
    (0.0, 2.689414, 29.242343),
    (math.pi / 3, 3.980978, 24.076090),
    (math.pi / 2, 5.249792, 19.000833),
    (math.pi, 7.310586, 10.757657),
]


@pytest.mark.parametrize("alpha,dc,e", HAND)
def test_eq11_eq12_hand_values(alpha, dc, e):
    assert cost_distance(10.0, alpha) == pytest.approx(dc, abs=1e-6)
    assert esd(math.inf, alpha, 40.0) == pytest.approx(e, abs=1e-6)


def test_esd_takes_the_dynamic_domain_when_smaller():
    assert esd(5.0, 0.0, 40.0) == 5.0
    assert esd(math.inf, math.nan, 40.0) == 40.0  # no current: D_alpha * DR


def test_cost_distance_is_euclidean_with_large_d_alpha_or_no_current():
    assert cost_distance(10.0, math.pi, d_alpha=10.0) == 10.0  # the min picks Ed
    assert cost_distance(10.0, math.nan) == 10.0


def test_min_cost_factor_is_a_lower_bound():
    f = min_cost_factor()
    alphas = np.linspace(0, math.pi, 1001)
    ratios = [cost_distance(1.0, a) for a in alphas]
    assert f == pytest.approx(min(ratios), abs=1e-9)


def test_encounter_angle():
    assert encounter_angle(1, 0, 2, 0) == pytest.approx(0.0)
    assert encounter_angle(1, 0, -2, 0) == pytest.approx(math.pi)
    assert encounter_angle(0, 1, 3, 0) == pytest.approx(math.pi / 2)
    assert math.isnan(encounter_angle(1, 0, 0, 0))
    a = encounter_angle(np.array([1.0, 0.0]), np.array([0.0, 1.0]), 1.0, 0.0)
    assert a == pytest.approx([0.0, math.pi / 2])


def test_segment_cost_follows_the_current():
    p = PlannerParams(objective="current")
    east = GridField.uniform(0.5, 0.0)
    down = segment_cost((0, 0), (10, 0), east, p)
    up = segment_cost((10, 0), (0, 0), east, p)
    assert down == pytest.approx(10 / (1 + math.e), rel=1e-9)
    assert up == pytest.approx(10 / (1 + math.exp(-1)), rel=1e-9)
    # long segment: split into pieces <= step, same total in a uniform field
    assert segment_cost((0, 0), (37, 0), east, p) == pytest.approx(37 / (1 + math.e), rel=1e-9)


def test_no_field_or_length_objective_is_euclidean():
    path = np.array([[0, 0], [3, 4], [3, 10]])
    assert path_cost(path, None, PlannerParams()) == pytest.approx(11.0)
    east = GridField.uniform(1.0, 0.0)
    assert path_cost(path, east, PlannerParams(objective="length")) == pytest.approx(11.0)
    zero = GridField.uniform(0.0, 0.0)
    assert path_cost(path, zero, PlannerParams(objective="current")) == pytest.approx(11.0)


def test_grid_field_bilinear_and_sample():
    f = GridField.sample(lambda x, y: (x + 2 * y, -y), 10.0, 10.0, 1.0)
    vx, vy = f(2.5, 3.25)
    assert vx == pytest.approx(2.5 + 6.5)
    assert vy == pytest.approx(-3.25)
    vx, vy = f(np.array([0.0, 100.0]), np.array([0.0, 0.0]))  # clamped outside
    assert vx == pytest.approx([0.0, 10.0])


# -- the tree core's shortcuts take exactly the decisions of the plain computations they replace
# (the references use the compiled core's hypot, libm's, which is not CPython's math.hypot)


@njit(cache=True)
def _hyp(dx, dy):
    return math.hypot(dx, dy)
def test_within_and_ellipse_match_hypot_including_the_boundary():
    rng = np.random.default_rng(5)
    for _ in range(20000):
        dx, dy = rng.normal(scale=20.0, size=2)
        r = _hyp(dx, dy) * (1.0 + rng.choice([-1e-16, 0.0, 1e-16, 1e-13, -1e-13, 0.3, -0.3]))
        assert _tree._within(dx, dy, r) == (_hyp(dx, dy) <= r)
        x, y, sx, sy, gx, gy = rng.uniform(0, 100, size=6)
        cb = (_hyp(x - sx, y - sy) + _hyp(x - gx, y - gy)) * (1.0 + rng.choice([-1e-16, 0.0, 1e-16, 0.1]))
        assert _tree._in_ellipse(x, y, sx, sy, gx, gy, cb) == (_hyp(x - sx, y - sy) + _hyp(x - gx, y - gy) <= cb)


def _setup(rng, n):
    occ = (rng.random((40, 40)) < 0.15).astype(np.uint8)
    X = rng.uniform(0, 20, size=(n, 2))
    # collinear nodes from the origin: keys tied up to rounding, as in a thin informed ellipse
    t = np.sort(rng.uniform(0, 1, size=n // 2))
    X[: n // 2] = np.c_[2.0 + 15.0 * t, 3.0 + 11.0 * t]
    cost = np.hypot(X[:, 0] - 2.0, X[:, 1] - 3.0) * rng.choice([1.0, 1.0, 1.3], size=n)
    cfg = _tree.new_config()
    cfg["res"] = 0.5
    cfg["step"] = 4.0
    cfg["field_res"] = 1.0
    cfg["max_turn"] = math.pi
    return occ, X, cost, cfg


def _tree_of(X, cost):
    """A kernel tree holding nodes X with costs ``cost``, no heading, unbounded domains."""
    n = len(X)
    tree = _tree.new_tree(n, 1, False)
    tree.X[:] = X
    tree.cost[:] = cost
    tree.head[:] = np.nan
    tree.dd[:] = np.inf
    return tree


def _first_free_by_stable_sort(exact, idx, occ, X, nx, ny):
    """The reference choose-parent: the first candidate of a stable sort by exact key whose edge to
    (nx, ny) is free; (node, key) or (-1, 0.0)."""
    for o in np.argsort(exact, kind="stable"):
        j = idx[o]
        if segment_free(occ, 0.5, X[j, 0], X[j, 1], nx, ny):
            return j, exact[o]
    return -1, 0.0


def test_lazy_choose_parent_matches_stable_sort():
    rng = np.random.default_rng(11)
    no_field = np.zeros((1, 1))
    for trial in range(300):
        n = int(rng.integers(1, 120))
        occ, X, cost, cfg = _setup(rng, n)
        nx, ny = (17.0 + 1e-3 * trial, 14.0) if trial % 2 else tuple(rng.uniform(0, 20, size=2))
        idx = rng.permutation(n)
        exact = np.array([cost[j] + _hyp(nx - X[j, 0], ny - X[j, 1]) for j in idx])
        want, want_c = _first_free_by_stable_sort(exact, idx, occ, X, nx, ny)
        near_i = idx.astype(np.int64).copy()
        near_c = np.array([cost[j] + math.sqrt((nx - X[j, 0]) ** 2 + (ny - X[j, 1]) ** 2) for j in idx])
        near_x = np.zeros(n, dtype=np.bool_)
        world = _tree.World(occ, no_field, no_field)
        got, got_c = _tree._first_valid_parent(near_i, near_c, near_x, n, nx, ny, world, cfg[0], _tree_of(X, cost),
                                               _tree.new_state()[0], False, False)
        assert got == want
        if want >= 0:
            assert got_c == want_c  # bit-identical cost, not only close


def test_lazy_choose_parent_on_lower_bounds_matches_stable_sort_of_eq12_costs():
    """With a current (eq. (12)), choose-parent starts from lower bounds cost[j] + f x length and
    makes exact only the keys that may be the minimum: the same parent and the same cost as a
    stable sort of the exact eq. (12) keys, on random fields and near-tied candidates."""
    rng = np.random.default_rng(12)
    lbf = 1.0 / (1.0 + math.e)  # _edge_lower_factor for D_alpha = 1, gamma >= 0
    for trial in range(300):
        n = int(rng.integers(1, 120))
        occ, X, cost, cfg = _setup(rng, n)
        cfg["use_field"] = 1
        cfg["d_alpha"] = 1.0
        cfg["gamma"] = 0.1
        fvx = rng.normal(scale=0.5, size=(25, 25))
        fvy = rng.normal(scale=0.5, size=(25, 25))
        if trial % 3 == 0:
            fvx[:] = 0.4  # a uniform current: many keys that differ by rounding only
            fvy[:] = -0.1
        world = _tree.World(occ, fvx, fvy)
        assert _tree._edge_lower_factor(cfg[0]) == lbf
        nx, ny = (17.0 + 1e-3 * trial, 14.0) if trial % 2 else tuple(rng.uniform(0, 20, size=2))
        idx = rng.permutation(n)
        exact = np.array([cost[j] + _tree._cost(X[j, 0], X[j, 1], nx, ny, fvx, fvy, cfg[0]) for j in idx])
        want, want_c = _first_free_by_stable_sort(exact, idx, occ, X, nx, ny)
        near_i = idx.astype(np.int64).copy()
        near_c = np.array([cost[j] + lbf * math.sqrt((nx - X[j, 0]) ** 2 + (ny - X[j, 1]) ** 2) * (1.0 - 1e-9)
                           for j in idx])
        assert (near_c <= exact).all()
        near_x = np.zeros(n, dtype=np.bool_)
        got, got_c = _tree._first_valid_parent(near_i, near_c, near_x, n, nx, ny, world, cfg[0], _tree_of(X, cost),
                                               _tree.new_state()[0], False, True)
        assert got == want
        if want >= 0:
            assert got_c == want_c


def test_esd_floor_is_below_the_second_term_of_eq11():
    rng = np.random.default_rng(13)
    for a, gamma in ((40.0, 0.1), (40.0, 0.0), (3.0, 2.0), (0.5, 0.1)):
        floor = _tree._esd_floor(a, gamma)
        for c in np.r_[rng.uniform(-1.0, 1.0, 20000), -1.0, 1.0, 0.0]:
            e = math.exp(c - gamma * math.sqrt(max(0.0, 1.0 - c * c)))
            assert floor <= a * e / (1.0 + e)
        assert floor > 0.99 * a * math.exp(-1 - gamma) / (1 + math.exp(-1 - gamma))
    assert _tree._esd_floor(40.0, -0.1) == -math.inf
    assert _tree._esd_floor(40.0, math.nan) == -math.inf


def test_knn_matches_brute_force_with_ties():
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(1, 300))
        X = np.round(rng.uniform(0, 50, size=(n, 2)) * 2) / 2  # on a 0.5 m lattice: many equal distances
        cfg = _tree.new_config()
        cfg["bucket"] = 4.0
        cfg["nbx"] = cfg["nby"] = int(math.ceil(50 / 4.0)) + 1
        tree = _tree.new_tree(n, int(cfg["nbx"][0] * cfg["nby"][0]), False)
        tree.X[:] = X
        for i in range(n):
            _tree._insert_bucket(i, cfg[0], tree)
        qx, qy = np.round(rng.uniform(0, 50, size=2) * 2) / 2
        k = int(rng.integers(1, 12))
        out_i = np.empty(64, np.int64)
        out_d = np.empty(64)
        m = _tree._knn(qx, qy, k, cfg[0], tree, out_i, out_d)
        d = (X[:, 0] - qx) ** 2 + (X[:, 1] - qy) ** 2
        assert m == min(k, n)
        assert np.array_equal(np.sqrt(np.sort(d)[:m]), out_d[:m])


def test_gridfield_at_is_the_vectorised_call():
    rng = np.random.default_rng(7)
    fields = [GridField(rng.normal(size=(31, 41)), rng.normal(size=(31, 41)), 1.0),
              GridField(rng.normal(size=(7, 9)), rng.normal(size=(7, 9)), 0.7, origin=(-1.3, 2.0)),
              GridField.uniform(0.3, 0.1)]
    for f in fields:
        xs = np.r_[rng.uniform(-10, 50, 20000), 0.0, 40.0, 3.9999999999999996]
        ys = np.r_[rng.uniform(-10, 40, 20000), 0.0, 30.0, 1e-300]
        vx, vy = f(xs, ys)
        for i in range(len(xs)):
            assert f.at(float(xs[i]), float(ys[i])) == (vx[i], vy[i])


def test_path_cost_fn_gives_path_cost_bit_for_bit_on_the_sub_paths_prune_asks_for():
    """The memoised cost (each segment computed once) sums the same terms in the same order as
    path_cost: the same floats, with a current field and without, on growing sub-paths and their
    shortcuts as prune asks for them, and on repeated points."""
    from planner.cost import path_cost_fn

    rng = np.random.default_rng(11)
    params = PlannerParams(objective="current")
    fields = [GridField(rng.normal(size=(31, 41)), rng.normal(size=(31, 41)), 1.0),
              GridField.uniform(0.3, -0.2), None]
    for field in fields:
        for _ in range(40):
            n = int(rng.integers(2, 14))
            path = np.cumsum(rng.normal(scale=4.0, size=(n, 2)), axis=0) + 15.0
            if n > 3:
                path[2] = path[1]   # a zero-length segment
            cost = path_cost_fn(field, params)
            for j in range(n - 1):
                for i in range(j + 1, n):
                    sub = path[j:i + 1]
                    assert cost(sub) == path_cost(sub, field, params)
                    shortcut = np.stack([path[j], path[i]])
                    assert cost(shortcut) == path_cost(shortcut, field, params)
            assert cost(path[:1]) == path_cost(path[:1], field, params) == 0.0
    plain = PlannerParams(objective="length")
    path = rng.normal(size=(9, 2))
    assert path_cost_fn(fields[0], plain)(path) == path_cost(path, fields[0], plain)
