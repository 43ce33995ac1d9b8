"""The compiled tree core shared by RRT*, Informed RRT* and DDRRT*.

``grow`` runs up to ``max_iter`` iterations (one iteration = one sample drawn) and returns early
at a ``CLOCK_MONOTONIC`` deadline ``deadline_ns`` or a deadline ``cpu_deadline_ns`` on the calling
thread's CPU clock (``CLOCK_THREAD_CPUTIME_ID``; both ns, -1 = none, both checked before every
iteration), at the first exact solution
when asked, or when the tree is full. One iteration is :func:`_sample`, then :func:`_ddrrt_extend`
(DDRRT*: k nearest, dynamic domains, choose-parent by D_C) or :func:`_rrt_extend` (RRT*, Informed
RRT*: nearest, near ball, choose-parent), each ending in :func:`_rewire_through`, then
:func:`_try_goal`.

State layout (everything preallocated by the caller; nothing is allocated per iteration):

* ``world`` (:class:`World`, read only): ``occ`` the occupancy grid (uint8, 1 = obstacle, rows y),
  ``fvx``/``fvy`` the current (m/s) on its grid, or 1 x 1 zeros without a current.
* ``cfg`` (a 1-element structured array of :data:`CONFIG`, read only): the problem and the
  parameters, SI units, map frame (x east, y north, from the map's corner). Geometry: ``step``
  (m), ``max_turn`` (rad, the fan's half-angle of section 2.4), ``goal_tol`` (m), the sampling
  box ``bx0..by1`` and perceptual disc ``dom_cx, dom_cy, dom_r`` (m, ``dom_r`` 0 = none), start
  ``sx, sy`` and goal ``gx, gy`` (m), grid ``res`` (m/cell), buckets ``bucket`` (m) ``nbx`` x ``nby``,
  tree capacity ``cap``. Sampling: ``goal_bias``, ``png_p``, ``png_x, png_y`` (m), ``use_png``,
  ``png_repair``. Cost (eq. (12)): ``use_field``, ``field_res, field_ox, field_oy`` (m),
  ``d_alpha``, ``gamma``, ``f_min``. DDRRT*: ``dr`` (m, DR of eq. (11)), ``k``, ``k_growth``,
  dynamic domains ``dd0`` (m), ``dd_grow``, ``dd_shrink``, ``dd_min`` (m), ``fail_turn``. RRT*:
  ``rewire_gamma`` (m). ``algo`` is one of the algorithm codes below.
* ``tree`` (:class:`Tree`, written by the kernel): per node ``X`` (n x 2, m), ``parent``,
  ``cost`` (cost from the start), ``head`` (heading of the edge from the parent, rad; NaN = none
  at the root), ``dd`` (dynamic-domain radius, m; inf = unbounded), ``nv`` (unit vector of the
  current at the node, or (0, 0); 1 x 2 without a current); the children as linked lists
  ``first_child``/``next_sib``; the grid buckets of side ``bucket`` as linked lists
  ``bucket_head`` (per bucket) / ``node_next`` (per node); ``stack``, scratch of the cost
  propagation.
* ``state`` (a 1-element structured array of :data:`STATE`, written by the kernel): ``n`` nodes,
  ``goal`` (node index, -1 = none), ``closest`` / ``closest_d`` (node nearest the goal, m),
  ``iter`` iterations, ``rejected`` samples, ``checks`` collision checks, ``failed`` failed
  extensions (``failed_turn`` of them refused by the fan), ``png_hit``, ``png_wasted``, and at the
  first exact solution ``first_iter``, ``first_checks``, ``first_ns`` (CLOCK_MONOTONIC, ns),
  ``first_cpu_ns`` (the thread's CPU clock, ns).
* :class:`Scratch` (made per search by :func:`new_scratch`): candidate buffers of the nearest / near / choose-parent
  / rewire steps and the clock buffer; :class:`Derived`: constants derived from ``cfg``.

Nearest and near searches use grid buckets of side ``step``: a near query (radius <= step) scans
3 x 3 buckets, a k-nearest query scans rings of buckets outwards until the k-th distance is
certain. Collision checks are the exact cell traversal of :mod:`planner._kernels`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, NamedTuple, cast

import numpy as np
from numba import njit
from numba.core import cgutils
from numba.extending import intrinsic

from planner._kernels import edge_cost, field_at, monotonic_ns, segment_free, thread_cpu_ns

if TYPE_CHECKING:
    from llvmlite import ir
    from numba.core.base import BaseContext
    from numba.core.types import Type
    from numba.core.typing.context import BaseContext as TypingContext
    from numba.core.typing.templates import Signature

# algorithm codes
RRT_STAR = 0
INFORMED_RRT_STAR = 1
DDRRT_STAR = 2

# grow() return codes
DONE_ITERATIONS = 0
DONE_DEADLINE = 1
DONE_EXACT = 2
DONE_FULL = 3

_F = np.float64
_I = np.int64
CONFIG = np.dtype([
    ("step", _F), ("max_turn", _F), ("goal_tol", _F), ("goal_bias", _F),
    ("png_p", _F), ("png_x", _F), ("png_y", _F),
    ("dr", _F), ("d_alpha", _F), ("gamma", _F), ("rewire_gamma", _F), ("f_min", _F), ("k_growth", _F),
    ("bucket", _F), ("bx0", _F), ("bx1", _F), ("by0", _F), ("by1", _F), ("dom_cx", _F), ("dom_cy", _F),
    ("dom_r", _F), ("gx", _F), ("gy", _F), ("sx", _F), ("sy", _F), ("res", _F),
    ("field_res", _F), ("field_ox", _F), ("field_oy", _F),
    ("dd0", _F), ("dd_grow", _F), ("dd_shrink", _F), ("dd_min", _F),
    ("algo", _I), ("use_field", _I), ("k", _I), ("nbx", _I), ("nby", _I), ("cap", _I), ("use_png", _I),
    ("fail_turn", _I), ("png_repair", _I),
])
STATE = np.dtype([
    ("n", _I), ("goal", _I), ("iter", _I), ("rejected", _I), ("closest", _I), ("first_iter", _I),
    ("checks", _I), ("failed", _I), ("failed_turn", _I), ("png_hit", _I), ("first_checks", _I),
    ("png_wasted", _I), ("closest_d", _F), ("first_ns", _F), ("first_cpu_ns", _F),
])


class World(NamedTuple):
    """What the tree grows in (read only): obstacles and the current."""

    occ: np.ndarray
    fvx: np.ndarray
    fvy: np.ndarray


class Tree(NamedTuple):
    """The tree's node arrays (capacity ``cap``) and its bucket grid; see the module docstring."""

    X: np.ndarray
    parent: np.ndarray
    cost: np.ndarray
    head: np.ndarray
    dd: np.ndarray
    nv: np.ndarray
    first_child: np.ndarray
    next_sib: np.ndarray
    bucket_head: np.ndarray
    node_next: np.ndarray
    stack: np.ndarray


class Scratch(NamedTuple):
    """Per-call candidate buffers: k nearest (kn_i, kn_d), DDRRT*'s extendable nodes (ext_i,
    ext_k), choose-parent candidates (near_i, near_c, near_x), the rewiring set (rw_i)."""

    kn_i: np.ndarray
    kn_d: np.ndarray
    ext_i: np.ndarray
    ext_k: np.ndarray
    near_i: np.ndarray
    near_c: np.ndarray
    near_x: np.ndarray
    rw_i: np.ndarray
    clock: np.ndarray


class Derived(NamedTuple):
    """Constants derived from the configuration once per ``grow`` call."""

    lbf: float            # edge cost >= lbf x length (_edge_lower_factor)
    lb_margin: float      # relative rounding margin of the lower bounds
    lower_bounds: bool    # choose-parent keys start as lower bounds (eq. (12))
    esd_plain: float      # D_alpha DR, eq. (11)'s first factor
    esd_floor: float      # _esd_floor(esd_plain, gamma)
    fan: np.ndarray       # _fan_bounds(max_turn) as (cos_pass, cos_fail, usable)


def new_config() -> np.ndarray:
    """A zeroed configuration record (fill its fields by name: ``cfg["step"] = 4.0``)."""
    return np.zeros(1, dtype=CONFIG)


def new_state() -> np.ndarray:
    """A zeroed state record."""
    return np.zeros(1, dtype=STATE)


def new_scratch() -> Scratch:
    """The candidate buffers of one search."""
    return Scratch(np.empty(K_CAP, np.int64), np.empty(K_CAP, np.float64), np.empty(K_CAP, np.int64),
                   np.empty(K_CAP, np.float64), np.empty(NEAR_CAP, np.int64), np.empty(NEAR_CAP, np.float64),
                   np.empty(NEAR_CAP, np.bool_), np.empty(NEAR_CAP, np.int64), np.zeros(2, np.int64))


def new_tree(cap: int, n_buckets: int, with_field: bool) -> Tree:
    """Node arrays for ``cap`` nodes (np.empty: no page touching for unused capacity), every
    bucket empty."""
    return Tree(X=np.empty((cap, 2)), parent=np.empty(cap, dtype=np.int64), cost=np.empty(cap),
                head=np.empty(cap), dd=np.empty(cap), nv=np.empty((cap, 2)) if with_field else np.zeros((1, 2)),
                first_child=np.empty(cap, dtype=np.int64), next_sib=np.empty(cap, dtype=np.int64),
                bucket_head=-np.ones(n_buckets, dtype=np.int64), node_next=np.empty(cap, dtype=np.int64),
                stack=np.empty(cap, dtype=np.int64))


NEAR_CAP = 1024
K_CAP = 64  # most nearest neighbours DDRRT* examines per sample
LAZY_TRIES = 8  # choose-parent: candidates tried by minimum selection before sorting the rest
TWO_PI = 2.0 * math.pi
# Relative margin of the square-root shortcuts below. math.hypot is a libm call (~17 ns here,
# against ~2 ns for sqrt(dx*dx + dy*dy)); the two differ by a few ulps (~1e-15 relative), so a
# decision taken on the square root outside this margin is the one hypot would take, and inside
# it the exact hypot decides. Results stay bit-identical to the all-hypot code.
_REL = 1e-12


@njit(cache=True)
def _within(dx: float, dy: float, r: float) -> bool:
    """math.hypot(dx, dy) <= r, exactly, mostly without calling hypot (r > 0 finite)."""
    d2 = dx * dx + dy * dy
    r2 = r * r
    if d2 < r2 * (1.0 - _REL):
        return True
    if d2 > r2 * (1.0 + _REL):
        return False
    return math.hypot(dx, dy) <= r


@njit(cache=True)
def seed_rng(seed: int) -> None:
    np.random.seed(seed)


@njit(cache=True)
def _wrap(a: float) -> float:
    if a > 8.0 * math.pi or a < -8.0 * math.pi:  # a huge angle (1e300): one modulo, never a long loop
        a = a % TWO_PI  # numba has no math.fmod; % gives [0, 2 pi), inf gives nan
    while a > math.pi:
        a -= TWO_PI
    while a < -math.pi:
        a += TWO_PI
    return a


@njit(cache=True)
def _fan_ok(head: float, dx: float, dy: float, max_turn: float) -> bool:
    """Section 2.4: the new edge must lie in the fan of half-angle max_turn about the heading."""
    if math.isnan(head) or max_turn >= math.pi:
        return True
    return abs(_wrap(math.atan2(dy, dx) - head)) <= max_turn + 1e-9


@njit(cache=True)
def _fan_bounds(max_turn: float) -> tuple[float, float, bool]:
    """(cos_pass, cos_fail, usable) for _fan_ok_cos: a direction whose cosine with the heading is
    >= cos_pass is inside the fan, <= cos_fail outside, whatever the rounding of _fan_ok's atan2
    (1e-7 rad and 1e-12 of slack, far above both computations' errors)."""
    t = max_turn + 1e-9
    if t - 1e-7 <= 0.0 or t + 1e-7 >= math.pi:
        return 2.0, -2.0, False
    return math.cos(t - 1e-7) + 1e-12, math.cos(t + 1e-7) - 1e-12, True


@njit(cache=True)
def _fan_ok_cos(head: float, hx: float, hy: float, dx: float, dy: float, max_turn: float, fb: np.ndarray) -> bool:
    """_fan_ok(head, dx, dy, max_turn), exactly, with (hx, hy) = (cos head, sin head): decided on
    a dot product and a square root (no atan2) unless the direction lies within 1e-7 rad of the
    fan's edge."""
    if math.isnan(head) or max_turn >= math.pi:
        return True
    if fb[2] != 0.0:
        d2 = dx * dx + dy * dy
        if d2 > 1e-200:
            c = (dx * hx + dy * hy) / math.sqrt(d2)
            if c >= fb[0]:
                return True
            if c <= fb[1]:
                return False
    return _fan_ok(head, dx, dy, max_turn)


@njit(cache=True, inline="always")
def _bucket(x: float, y: float, cfg: np.record) -> tuple[int, int]:
    bx = int(x / cfg.bucket)  # buckets cover the whole map from (0, 0)
    by = int(y / cfg.bucket)
    bx = min(max(bx, 0), cfg.nbx - 1)
    by = min(max(by, 0), cfg.nby - 1)
    return bx, by


@njit(cache=True, inline="always")
def _insert_bucket(i: int, cfg: np.record, tree: Tree) -> None:
    bx, by = _bucket(tree.X[i, 0], tree.X[i, 1], cfg)
    b = by * cfg.nbx + bx
    tree.node_next[i] = tree.bucket_head[b]
    tree.bucket_head[b] = i


@njit(cache=True)
def _knn(qx: float, qy: float, k: int, cfg: np.record, tree: Tree, out_i: np.ndarray, out_d: np.ndarray) -> int:
    """k nearest nodes (Euclidean), ascending; returns how many were found (<= k). Squared
    distances while scanning (no square root per candidate), roots of the k results at the end.

    The scan stops after the ring whose block of buckets is certain to hold every node nearer
    than the k-th found: the distance from the query to the nearest side of the block (sides on
    the map's border do not count; 1e-6 m of slack for bucket rounding), or ring x bucket side.
    Nodes beyond are at least as far as the k-th, and an equal distance never displaces a node
    found earlier, so the result is that of a full scan."""
    X = tree.X
    bucket_head = tree.bucket_head
    node_next = tree.node_next
    cx, cy = _bucket(qx, qy, cfg)
    nbx = cfg.nbx
    nby = cfg.nby
    m = 0
    rmax = max(nbx, nby)
    B = cfg.bucket
    for ring in range(rmax + 1):
        for by in range(cy - ring, cy + ring + 1):
            if by < 0 or by >= nby:
                continue
            edge_row = by == cy - ring or by == cy + ring
            bx = cx - ring
            while bx <= cx + ring:
                if 0 <= bx < nbx:
                    j = bucket_head[by * nbx + bx]
                    while j >= 0:
                        ex = X[j, 0] - qx
                        ey = X[j, 1] - qy
                        d = ex * ex + ey * ey
                        if m < k or d < out_d[m - 1]:
                            p = m if m < k else k - 1
                            while p > 0 and out_d[p - 1] > d:
                                out_d[p] = out_d[p - 1]
                                out_i[p] = out_i[p - 1]
                                p -= 1
                            out_d[p] = d
                            out_i[p] = j
                            if m < k:
                                m += 1
                        j = node_next[j]
                if edge_row or ring == 0:
                    bx += 1
                else:
                    bx += 2 * ring  # interior rows: only the two edge columns
        if m == k:
            lim = ring * B
            side = 1e300
            if cx - ring > 0:
                side = min(side, qx - (cx - ring) * B)
            if cx + ring < nbx - 1:
                side = min(side, (cx + ring + 1) * B - qx)
            if cy - ring > 0:
                side = min(side, qy - (cy - ring) * B)
            if cy + ring < nby - 1:
                side = min(side, (cy + ring + 1) * B - qy)
            side -= 1e-6
            if side > lim:
                lim = side
            if out_d[m - 1] <= lim * lim:
                break
    for a in range(m):
        out_d[a] = math.sqrt(out_d[a])
    return m


@njit(cache=True)
def _near_pos(qx: float, qy: float, radius: float, cfg: np.record, tree: Tree, out_i: np.ndarray,
              mark: int) -> tuple[int, int]:
    """Nodes within ``radius`` (at most NEAR_CAP of them), and how many it had found when it
    reached bucket ``mark`` (NEAR_CAP if it never did)."""
    X = tree.X
    bucket_head = tree.bucket_head
    node_next = tree.node_next
    B = cfg.bucket
    nbx = cfg.nbx
    nby = cfg.nby
    bx0 = int(math.floor((qx - radius) / B))
    bx1 = int(math.floor((qx + radius) / B))
    by0 = int(math.floor((qy - radius) / B))
    by1 = int(math.floor((qy + radius) / B))
    r2 = radius * radius
    m = 0
    pos = NEAR_CAP
    for by in range(max(by0, 0), min(by1, nby - 1) + 1):
        for bx in range(max(bx0, 0), min(bx1, nbx - 1) + 1):
            if by * nbx + bx == mark:
                pos = m
            j = bucket_head[by * nbx + bx]
            while j >= 0:
                ex = X[j, 0] - qx
                ey = X[j, 1] - qy
                if m < NEAR_CAP and ex * ex + ey * ey <= r2:
                    out_i[m] = j
                    m += 1
                j = node_next[j]
    return m, pos


@njit(cache=True, inline="always")
def _in_domain(x: float, y: float, cfg: np.record) -> bool:
    if x < cfg.bx0 or x > cfg.bx1 or y < cfg.by0 or y > cfg.by1:
        return False
    if cfg.dom_r > 0.0:
        return _within(x - cfg.dom_cx, y - cfg.dom_cy, cfg.dom_r)
    return True


@njit(cache=True)
def _uniform(cfg: np.record) -> tuple[float, float]:
    x = 0.0
    y = 0.0
    for _ in range(64):
        x = cfg.bx0 + np.random.random() * (cfg.bx1 - cfg.bx0)
        y = cfg.by0 + np.random.random() * (cfg.by1 - cfg.by0)
        if _in_domain(x, y, cfg):
            break
    return x, y


@njit(cache=True)
def _in_ellipse(x: float, y: float, sx: float, sy: float, gx: float, gy: float, cb: float) -> bool:
    """math.hypot(x - sx, y - sy) + math.hypot(x - gx, y - gy) <= cb, exactly (see _REL)."""
    ax = x - sx
    ay = y - sy
    bx = x - gx
    by = y - gy
    t = math.sqrt(ax * ax + ay * ay) + math.sqrt(bx * bx + by * by)
    if t < cb * (1.0 - _REL):
        return True
    if t > cb * (1.0 + _REL):
        return False
    return math.hypot(ax, ay) + math.hypot(bx, by) <= cb


@njit(cache=True)
def _informed(cfg: np.record, c_best: float) -> tuple[float, float]:
    """Gammell et al. 2014: uniform sample of the prolate hyperspheroid (an ellipse in 2-D) with
    foci start and goal and transverse diameter c_best / f_min (f_min D_C <= Ed keeps it a lower
    bound of the cost through a point), intersected with the sampling domain."""
    sx = cfg.sx
    sy = cfg.sy
    gx = cfg.gx
    gy = cfg.gy
    c_min = math.hypot(gx - sx, gy - sy)
    cb = c_best / cfg.f_min
    if cb <= c_min:
        cb = c_min * (1.0 + 1e-9)
    a = 0.5 * cb                                  # semi-major axis
    b = 0.5 * math.sqrt(max(cb * cb - c_min * c_min, 0.0))  # semi-minor axis
    th = math.atan2(gy - sy, gx - sx)             # rotation to the world frame (C in Gammell)
    ct = math.cos(th)
    st = math.sin(th)
    mx = 0.5 * (sx + gx)
    my = 0.5 * (sy + gy)
    box = (cfg.bx1 - cfg.bx0) * (cfg.by1 - cfg.by0)
    x = mx
    y = my
    if math.pi * a * b < box:
        # direct sampling: uniform in the unit disc, scaled by L = diag(a, b), rotated by C
        for _ in range(64):
            r = math.sqrt(np.random.random())
            phi = TWO_PI * np.random.random()
            ex = a * r * math.cos(phi)
            ey = b * r * math.sin(phi)
            x = mx + ct * ex - st * ey
            y = my + st * ex + ct * ey
            if _in_domain(x, y, cfg):
                return x, y
        return _uniform(cfg)
    # the ellipse covers more than the box: sample the box, keep points inside the ellipse
    for _ in range(64):
        x, y = _uniform(cfg)
        if _in_ellipse(x, y, sx, sy, gx, gy, cb):
            return x, y
    return x, y


@njit(cache=True, inline="always")
def _children_fan_ok(j: int, new_head: float, tree: Tree, max_turn: float) -> bool:
    if max_turn >= math.pi:
        return True
    X = tree.X
    next_sib = tree.next_sib
    c = tree.first_child[j]
    while c >= 0:
        if not _fan_ok(new_head, X[c, 0] - X[j, 0], X[c, 1] - X[j, 1], max_turn):
            return False
        c = next_sib[c]
    return True


@njit(cache=True)
def _reparent(j: int, p: int, new_cost: float, tree: Tree) -> None:
    """Make p the parent of j and propagate the cost change to j's subtree."""
    X = tree.X
    first_child = tree.first_child
    next_sib = tree.next_sib
    cost = tree.cost
    stack = tree.stack
    old = tree.parent[j]
    if old >= 0:
        if first_child[old] == j:
            first_child[old] = next_sib[j]
        else:
            c = first_child[old]
            while next_sib[c] != j:
                c = next_sib[c]
            next_sib[c] = next_sib[j]
    tree.parent[j] = p
    next_sib[j] = first_child[p]
    first_child[p] = j
    tree.head[j] = math.atan2(X[j, 1] - X[p, 1], X[j, 0] - X[p, 0])
    delta = new_cost - cost[j]
    top = 0
    stack[top] = j
    top += 1
    while top > 0:
        top -= 1
        n = stack[top]
        cost[n] += delta
        c = first_child[n]
        while c >= 0:
            stack[top] = c
            top += 1
            c = next_sib[c]


@njit(cache=True, inline="always")
def _set_direction(i: int, x: float, y: float, nv: np.ndarray, world: World, cfg: np.record) -> None:
    """nv[i] = the unit vector of the current at (x, y), or (0, 0) where there is none."""
    vx, vy = field_at(world.fvx, world.fvy, cfg.field_res, cfg.field_ox, cfg.field_oy, x, y)
    v = math.hypot(vx, vy)
    if v < 1e-9:
        nv[i, 0] = 0.0
        nv[i, 1] = 0.0
    else:
        nv[i, 0] = vx / v
        nv[i, 1] = vy / v


@njit(cache=True, inline="always")
def _add_node(x: float, y: float, p: int, c: float, world: World, cfg: np.record, tree: Tree, state: np.record) -> int:
    """Append node (x, y) with parent p and cost c; returns its index."""
    X = tree.X
    i = state.n
    X[i, 0] = x
    X[i, 1] = y
    if cfg.use_field != 0:
        _set_direction(i, x, y, tree.nv, world, cfg)
    tree.parent[i] = p
    tree.cost[i] = c
    tree.head[i] = math.atan2(y - X[p, 1], x - X[p, 0])
    tree.dd[i] = np.inf
    tree.first_child[i] = -1
    tree.next_sib[i] = tree.first_child[p]
    tree.first_child[p] = i
    _insert_bucket(i, cfg, tree)
    state.n = i + 1
    return i


@njit(cache=True, inline="always")
def _cost(x0: float, y0: float, x1: float, y1: float, fvx: np.ndarray, fvy: np.ndarray, cfg: np.record) -> float:
    """The edge cost (m): its length, or eq. (12) with a current (fvx, fvy)."""
    return edge_cost(x0, y0, x1, y1, cfg.use_field != 0, fvx, fvy, cfg.field_res, cfg.field_ox,
                     cfg.field_oy, cfg.step, cfg.d_alpha, cfg.gamma)


@njit(cache=True, inline="always")
def _free(world: World, cfg: np.record, state: np.record, x0: float, y0: float, x1: float, y1: float) -> bool:
    state.checks += 1
    return segment_free(world.occ, cfg.res, x0, y0, x1, y1)


@njit(cache=True, inline="always")
def _dd_failed(i: int, dd: np.ndarray, cfg: np.record) -> None:
    """A failed (colliding) extension from node i: its dynamic domain becomes bounded (DD0), or,
    already bounded, shrinks by the adaptive factor (Jaillet et al. 2005), never below DDMIN."""
    if math.isinf(dd[i]):
        dd[i] = cfg.dd0
    else:
        dd[i] = max(dd[i] * cfg.dd_shrink, cfg.dd_min)


@njit(cache=True, inline="always")
def _extension_refused(j: int, by_fan: bool, cfg: np.record, tree: Tree, state: np.record) -> None:
    """DDRRT*: the extension from node j failed, by collision or (by_fan) by the turning-radius fan
    of section 2.4. A collision always counts as a failed extension; the fan only with the
    paper's reading (failed_extension = "collision+turn": it counts constraint violations too)."""
    if by_fan:
        if cfg.fail_turn == 0:
            return
        state.failed_turn += 1
    state.failed += 1
    _dd_failed(j, tree.dd, cfg)


@njit(cache=True)
def _sort_by(keys: np.ndarray, idx: np.ndarray, m: int) -> None:
    """Insertion sort of idx[:m] by keys[:m] (m is small)."""
    for a in range(1, m):
        kk = keys[a]
        ii = idx[a]
        b = a - 1
        while b >= 0 and keys[b] > kk:
            keys[b + 1] = keys[b]
            idx[b + 1] = idx[b]
            b -= 1
        keys[b + 1] = kk
        idx[b + 1] = ii


@njit(cache=True)
def _stable_argsort(keys: np.ndarray, m: int) -> np.ndarray:
    """The indices of keys[:m] in ascending order, equal keys in index order (NaN last): the
    permutation of ``np.argsort(keys[:m], kind="mergesort")``, by a bottom-up merge sort. numba's
    own merge sort took 1.3 s of CPU to compile cold, this one ~0.2 s (issue 32 point 4)."""
    src = np.empty(m, dtype=np.int64)
    dst = np.empty(m, dtype=np.int64)
    for a in range(m):
        src[a] = a
    width = 1
    while width < m:
        for lo in range(0, m, 2 * width):
            mid = min(lo + width, m)
            hi = min(lo + 2 * width, m)
            a, b = lo, mid
            for o in range(lo, hi):
                if a < mid and b < hi:
                    ka = keys[src[a]]
                    kb = keys[src[b]]
                    # b first only when strictly smaller (numba's float order: NaN above all)
                    take_b = kb < ka or (ka != ka and kb == kb)
                else:
                    take_b = a >= mid
                if take_b:
                    dst[o] = src[b]
                    b += 1
                else:
                    dst[o] = src[a]
                    a += 1
        src, dst = dst, src
        width *= 2
    return src


@njit(cache=True, inline="always")
def _parent_key(j: int, nx: float, ny: float, world: World, cfg: np.record, tree: Tree) -> tuple[float, bool]:
    """(key, exact): the cost to (nx, ny) through node j. With a current, exact. For length, a
    square root instead of math.hypot (exact = False): within 7.2e-16 relative of the exact key,
    which _first_valid_parent computes only for the candidates that can be the minimum."""
    X = tree.X
    if cfg.use_field != 0:
        return tree.cost[j] + _cost(X[j, 0], X[j, 1], nx, ny, world.fvx, world.fvy, cfg), True
    dx = nx - X[j, 0]
    dy = ny - X[j, 1]
    return tree.cost[j] + math.sqrt(dx * dx + dy * dy), False


@njit(cache=True, inline="always")
def _cost_through(i: int, nx: float, ny: float, X: np.ndarray, cost: np.ndarray, fvx: np.ndarray, fvy: np.ndarray,
                  cfg: np.record) -> float:
    """The exact cost to (nx, ny) through node i."""
    return cost[i] + _cost(X[i, 0], X[i, 1], nx, ny, fvx, fvy, cfg)


@njit(cache=True, inline="always")
def _try_parent(j: int, nx: float, ny: float, world: World, cfg: np.record, tree: Tree, state: np.record,
                track_failed: bool) -> bool:
    """True if the edge from node j to (nx, ny) is in j's fan and collision-free; with
    ``track_failed`` (DDRRT*) a refusal counts as a failed extension (_extension_refused)."""
    X = tree.X
    if _fan_ok(tree.head[j], nx - X[j, 0], ny - X[j, 1], cfg.max_turn):
        if _free(world, cfg, state, X[j, 0], X[j, 1], nx, ny):
            return True
        if track_failed:
            _extension_refused(j, False, cfg, tree, state)
    elif track_failed:
        _extension_refused(j, True, cfg, tree, state)
    return False


@njit(cache=True, inline="always")
def _min_key(near_c: np.ndarray, left: int) -> float:
    m = near_c[0]
    for a in range(1, left):
        if near_c[a] < m:
            m = near_c[a]
    return m


# Callers pass np.int64(...) and np.bool_(...), not bare literals or counters: numba compiles a
# function once per argument type, and a literal (1, True) or a counter still typed as its initial
# literal 0 while grow is being typed is a type of its own: _first_valid_parent was compiled three
# times, _knn and _sort_by twice (issue 32 point 4: the cold compile).
@njit(cache=True)
def _first_valid_parent(near_i: np.ndarray, near_c: np.ndarray, near_x: np.ndarray, nc: int, nx: float, ny: float,
                        world: World, cfg: np.record, tree: Tree, state: np.record, track_failed: bool,
                        lower_bounds: bool) -> tuple[int, float]:
    """RRT*'s choose-parent: the first candidate, in ascending cost order, whose edge to (nx, ny)
    is in its fan and collision-free; returns (node, cost through it) or (-1, 0.0). With
    ``track_failed`` (DDRRT*) a refused candidate counts as a failed extension and bounds or
    shrinks its dynamic domain.

    The same candidates are tried in the same order as after a stable sort of near_c (ties in
    buffer order), but only as far as the first valid one: a selection of the minimum per try
    instead of an insertion sort of the whole near set, which is O(nc^2) and dominated Informed
    RRT* once its samples concentrate in a thin ellipse (hundreds of near nodes per sample).

    Keys flagged inexact in near_x (see _parent_key; all keys are >= 0) are made exact where they
    may be the minimum: a key above m (1 + 1e-12) + 1e-12, m the smallest key, is above the
    minimum whatever its rounding, so the chosen candidate and its cost are the exact ones.
    With ``lower_bounds`` (eq. (12): inexact keys are cost[j] + f x length, f from
    _edge_lower_factor, below the exact key by any amount) the pass repeats with the new smallest
    key until every key within its window is exact: an inexact key outside the window is then
    above the minimum, so the choice is again the exact one, and most edges never pay for their
    exp and field look-up. After LAZY_TRIES refused candidates (with the fan limit, the cheapest
    candidates often point backwards), the rest is sorted once instead (exact keys, stable merge
    sort: the same order)."""
    X = tree.X
    cost = tree.cost
    fvx = world.fvx
    fvy = world.fvy
    left = nc
    for _ in range(LAZY_TRIES):
        if left == 0:
            return -1, 0.0
        if lower_bounds:  # make exact every key that may be the minimum, until none is left
            exacted = True
            while exacted:
                window = _min_key(near_c, left) * (1.0 + 1e-12) + 1e-12
                exacted = False
                for a in range(left):
                    if near_c[a] <= window and not near_x[a]:
                        near_c[a] = _cost_through(near_i[a], nx, ny, X, cost, fvx, fvy, cfg)
                        near_x[a] = True
                        exacted = True
        window = _min_key(near_c, left) * (1.0 + 1e-12) + 1e-12
        b = -1
        kb = 0.0
        for a in range(left):
            if near_c[a] <= window:
                if not near_x[a]:  # square-root keys (see above): one pass decides
                    near_c[a] = _cost_through(near_i[a], nx, ny, X, cost, fvx, fvy, cfg)
                    near_x[a] = True
                if b < 0 or near_c[a] < kb:  # strict: the first of equal keys, as the stable sort would
                    kb = near_c[a]
                    b = a
        j = near_i[b]
        if _try_parent(j, nx, ny, world, cfg, tree, state, track_failed):
            return j, kb
        for a in range(b, left - 1):  # drop candidate b, keeping the others' order
            near_c[a] = near_c[a + 1]
            near_i[a] = near_i[a + 1]
            near_x[a] = near_x[a + 1]
        left -= 1
    for a in range(left):
        if not near_x[a]:
            near_c[a] = _cost_through(near_i[a], nx, ny, X, cost, fvx, fvy, cfg)
            near_x[a] = True
    order = _stable_argsort(near_c, left)
    for o in range(left):
        j = near_i[order[o]]
        if _try_parent(j, nx, ny, world, cfg, tree, state, track_failed):
            return j, near_c[order[o]]
    return -1, 0.0


@njit(cache=True, inline="always")
def _first_solution(state: np.record, clock: np.ndarray) -> None:
    """At the first exact solution: the iteration, the collision checks so far, the monotonic and
    the thread's CPU clock, so that time to a first solution can be judged independent of the
    platform (issue 34)."""
    state.first_iter = state.iter
    state.first_ns = monotonic_ns(clock)
    state.first_checks = state.checks
    state.first_cpu_ns = thread_cpu_ns(clock)


@njit(cache=True, inline="always")
def _try_goal(i: int, world: World, cfg: np.record, tree: Tree, state: np.record, clock: np.ndarray) -> None:
    """After node i joined the tree: track the closest node and connect the goal exactly."""
    X = tree.X
    cost = tree.cost
    gx = cfg.gx
    gy = cfg.gy
    d = math.hypot(X[i, 0] - gx, X[i, 1] - gy)
    if d < state.closest_d:
        state.closest_d = d
        state.closest = i
    g = state.goal
    if d > cfg.goal_tol or i == g:
        return
    if d < 1e-9:
        if g < 0:
            state.goal = i
            _first_solution(state, clock)
        return
    c = cost[i] + _cost(X[i, 0], X[i, 1], gx, gy, world.fvx, world.fvy, cfg)
    if g >= 0 and c >= cost[g] - 1e-12:
        return
    dx = gx - X[i, 0]
    dy = gy - X[i, 1]
    if not _fan_ok(tree.head[i], dx, dy, cfg.max_turn):
        return
    if g >= 0 and not _children_fan_ok(g, math.atan2(dy, dx), tree, cfg.max_turn):
        return
    if not _free(world, cfg, state, X[i, 0], X[i, 1], gx, gy):
        return
    if g < 0:
        if state.n >= cfg.cap:
            return
        state.goal = _add_node(gx, gy, i, c, world, cfg, tree, state)
        _first_solution(state, clock)
        state.closest_d = 0.0
        state.closest = state.goal
    else:
        _reparent(g, i, c, tree)


@njit(cache=True, inline="always")
def _rewire(j: int, new: int, hx: float, hy: float, world: World, cfg: np.record, tree: Tree, state: np.record,
            fan: np.ndarray) -> None:
    """Make q_new the parent of node j if that is cheaper and the edge is valid (fan limit for the
    edge and for j's children, collision-free): the rewiring step shared by RRT* and DDRRT*.
    The tests are side-effect free until the collision check, so the cheap ones come first;
    (hx, hy) = (cos, sin) of q_new's heading, fan = _fan_bounds(max_turn). The caller has
    already refused the candidates that _rewire_cannot_pay refuses."""
    X = tree.X
    nx = X[new, 0]
    ny = X[new, 1]
    dx = X[j, 0] - nx
    dy = X[j, 1] - ny
    max_turn = cfg.max_turn
    if not _fan_ok_cos(tree.head[new], hx, hy, dx, dy, max_turn, fan):
        return
    c = tree.cost[new] + _cost(nx, ny, X[j, 0], X[j, 1], world.fvx, world.fvy, cfg)
    if c >= tree.cost[j] - 1e-12:
        return
    if not _children_fan_ok(j, math.atan2(dy, dx), tree, max_turn):
        return
    if _free(world, cfg, state, nx, ny, X[j, 0], X[j, 1]):
        _reparent(j, new, c, tree)


@njit(cache=True, inline="always")
def _rewire_cannot_pay(j: int, new: int, X: np.ndarray, cost: np.ndarray, lbf: float, margin: float) -> bool:
    """True if rewiring node j through q_new cannot lower its cost, decided on a square root:
    lbf * sqrt(...) * (1 - margin) <= the computed edge cost (_edge_lower_factor), and rounding is
    monotone, so this refuses only candidates that _rewire's exact comparison refuses too. Kept
    small so that it is inlined: _rewire's call alone costs tens of ns, and Informed RRT* can have
    a thousand near nodes per sample."""
    if lbf <= 0.0:
        return False
    dx = X[j, 0] - X[new, 0]
    dy = X[j, 1] - X[new, 1]
    return cost[new] + lbf * math.sqrt(dx * dx + dy * dy) * (1.0 - margin) >= cost[j] - 1e-12


@njit(cache=True, inline="always")
def _rewire_through(new: int, p: int, rw_i: np.ndarray, count: int, world: World, cfg: np.record, tree: Tree,
                    state: np.record, dv: Derived) -> None:
    """Rewire step (RRT* and DDRRT* lines 18-21): offer q_new as the parent of rw_i[:count]."""
    X = tree.X
    cost = tree.cost
    lbf = dv.lbf
    lb_margin = dv.lb_margin
    fan = dv.fan
    hx = math.cos(tree.head[new])
    hy = math.sin(tree.head[new])
    for a in range(count):
        j = rw_i[a]
        if j == p or j == new:
            continue
        if _rewire_cannot_pay(j, new, X, cost, lbf, lb_margin):
            continue
        _rewire(j, new, hx, hy, world, cfg, tree, state, fan)


@njit(cache=True)
def _edge_lower_factor(cfg: np.record) -> float:
    """f with edge cost >= f x edge length for every edge: 1 for length; for eq. (12), where each
    piece costs min(1, D_alpha / (1 + exp(cos a - gamma sin a))) x its length and the exponent is
    at most 1 when gamma >= 0, f = min(1, D_alpha / (1 + e)). 0 (no bound used) otherwise."""
    if cfg.use_field == 0:
        return 1.0
    da = cfg.d_alpha
    if da > 0.0 and cfg.gamma >= 0.0:
        return min(1.0, da / (1.0 + math.e))
    return 0.0


@njit(cache=True)
def _esd_floor(a: float, gamma: float) -> float:
    """A value below eq. (11)'s second term a / (1 + exp(-arg)) for every alpha_y, whatever its
    rounding: arg = cos a - gamma sin a >= -1 - gamma when gamma >= 0 (-inf, no floor, otherwise),
    and the term grows with arg."""
    if not (a > 0.0 and gamma >= 0.0):
        return -math.inf
    e = math.exp(-1.0 - gamma)
    return a * e / (1.0 + e) * (1.0 - 1e-12)


@njit(cache=True)
def _derive(cfg: np.record) -> Derived:
    """The Derived constants of a configuration (computed in the kernel, as before: the same floats)."""
    lbf = _edge_lower_factor(cfg)
    use_field = cfg.use_field != 0
    # length: the edge cost is hypot, within 4e-16 of the square root; eq. (12): exp and the sum
    # of pieces round too, so a wider margin
    lb_margin = 2e-15 if cfg.use_field == 0 else 1e-9
    esd_plain = cfg.d_alpha * cfg.dr
    cp, cf, fan_usable = _fan_bounds(cfg.max_turn)
    fan = np.array([cp, cf, 1.0 if fan_usable else 0.0])
    return Derived(lbf, lb_margin, use_field and lbf > 0.0, esd_plain, _esd_floor(esd_plain, cfg.gamma), fan)


def _unowned_typer(typingctx: TypingContext, arr: Type) -> tuple[Signature, Callable[..., ir.Value]]:
    """A view of ``arr`` without its reference count (a null meminfo): taking it out of a named
    tuple then costs no atomic increment and decrement. Only for arrays that the caller of
    ``grow`` keeps alive for the whole call."""
    def codegen(context: BaseContext, builder: ir.IRBuilder, sig: Signature, args: Sequence[ir.Value]) -> ir.Value:
        src = context.make_array(sig.args[0])(context, builder, args[0])
        out = context.make_array(sig.return_type)(context, builder)
        for name in ("parent", "nitems", "itemsize", "data", "shape", "strides"):
            setattr(out, name, getattr(src, name))
        out.meminfo = cgutils.get_null_value(out.meminfo.type)
        return out._getvalue()
    return arr(arr), codegen


_unowned = cast(Callable[[np.ndarray], np.ndarray], intrinsic(_unowned_typer))


@njit(cache=True)
def _borrowed(world: World, tree: Tree, buf: Scratch) -> tuple[World, Tree, Scratch]:
    """world, tree and buf as views without reference counts (see _unowned): the kernel reads
    their members in every step, and numba counts a reference per read otherwise (perf: a fifth
    of DDRRT*'s time in atomic increments and decrements)."""
    w = World(_unowned(world.occ), _unowned(world.fvx), _unowned(world.fvy))
    t = Tree(_unowned(tree.X), _unowned(tree.parent), _unowned(tree.cost), _unowned(tree.head), _unowned(tree.dd),
             _unowned(tree.nv), _unowned(tree.first_child), _unowned(tree.next_sib), _unowned(tree.bucket_head),
             _unowned(tree.node_next), _unowned(tree.stack))
    b = Scratch(_unowned(buf.kn_i), _unowned(buf.kn_d), _unowned(buf.ext_i), _unowned(buf.ext_k),
                _unowned(buf.near_i), _unowned(buf.near_c), _unowned(buf.near_x), _unowned(buf.rw_i),
                _unowned(buf.clock))
    return w, t, b


@njit(cache=True)
def node_direction(i: int, x: float, y: float, world: World, cfg_a: np.ndarray, tree: Tree) -> None:
    """Entry point for the solve loop: the root's current direction (see _set_direction)."""
    _set_direction(i, x, y, tree.nv, world, cfg_a[0])


@njit(cache=True, inline="always")
def _sample(cfg: np.record, tree: Tree, state: np.record) -> tuple[float, float, bool]:
    """A sample (x, y, from_png): the PNG node with probability P (DDRRT*), else the goal with
    the goal bias, else uniform in the domain (Informed RRT* with a solution: in its ellipse)."""
    if cfg.use_png != 0 and state.png_hit == 0 and np.random.random() < cfg.png_p:
        return cfg.png_x, cfg.png_y, True
    if np.random.random() < cfg.goal_bias:
        return cfg.gx, cfg.gy, False
    if cfg.algo == INFORMED_RRT_STAR and state.goal >= 0:
        x, y = _informed(cfg, tree.cost[state.goal])
        return x, y, False
    x, y = _uniform(cfg)
    return x, y, False


@njit(cache=True, inline="always")
def _sample_ddrrt(cfg: np.record, state: np.record) -> tuple[float, float, bool]:
    """:func:`_sample` for DDRRT* (``cfg.algo`` DDRRT_STAR: no informed branch), the same draws. Its
    own function so that ``grow_ddrrt`` does not compile the Informed RRT* sampler it never runs."""
    if cfg.use_png != 0 and state.png_hit == 0 and np.random.random() < cfg.png_p:
        return cfg.png_x, cfg.png_y, True
    if np.random.random() < cfg.goal_bias:
        return cfg.gx, cfg.gy, False
    x, y = _uniform(cfg)
    return x, y, False


@njit(cache=True, inline="always")
def _steer(q0: int, d0: float, sx: float, sy: float, X: np.ndarray, step: float) -> tuple[float, float]:
    """q_new: the sample, or the point a step from node q0 (d0 from it) towards it."""
    if d0 > step:
        return X[q0, 0] + (sx - X[q0, 0]) * step / d0, X[q0, 1] + (sy - X[q0, 1]) * step / d0
    return sx, sy


@njit(cache=True, inline="always")
def _dd_candidates(sx: float, sy: float, cfg: np.record, tree: Tree, state: np.record, buf: Scratch,
                   dv: Derived) -> int:
    """Figure 6 lines 5-11: of the k nearest nodes, those whose dynamic domain (a disc, Yershova
    2005) holds the sample and whose D_C (eq. (12) with one alpha_y, the current at the node, as
    eq. (11)'s) is within ESD (eq. (11)), in distance order: buf.ext_i, their D_C in buf.ext_k;
    returns how many. k is the paper's constant, or (k_growth > 0) grows as k-nearest RRT* needs
    for asymptotic optimality: max(k, ceil(k_growth log n)) (Karaman & Frazzoli 2011)."""
    X = tree.X
    nv = tree.nv
    n = state.n
    k = cfg.k
    if cfg.k_growth > 0.0 and n > 1:
        k = max(cfg.k, min(K_CAP, int(math.ceil(cfg.k_growth * math.log(n)))))
    kn_i = buf.kn_i
    kn_d = buf.kn_d
    ext_i = buf.ext_i
    ext_k = buf.ext_k
    dd = tree.dd
    esd_plain = dv.esd_plain
    esd_floor = dv.esd_floor
    m = _knn(sx, sy, k, cfg, tree, kn_i, kn_d)
    use_field = cfg.use_field != 0
    gamma = cfg.gamma
    ne = 0
    for a in range(m):
        i = kn_i[a]
        ed = kn_d[a]
        if ed > dd[i]:
            continue
        dc = ed
        accept = dc <= esd_plain
        if use_field and ed > 0.0 and (nv[i, 0] != 0.0 or nv[i, 1] != 0.0):
            c = ((sx - X[i, 0]) * nv[i, 0] + (sy - X[i, 1]) * nv[i, 1]) / ed
            c = min(1.0, max(-1.0, c))
            e = math.exp(c - gamma * math.sqrt(max(0.0, 1.0 - c * c)))
            dc = min(ed, cfg.d_alpha * ed / (1.0 + e))
            # D_alpha DR / (1 + exp(-arg)), computed only where esd_floor does not decide
            accept = dc <= esd_floor or dc <= esd_plain * e / (1.0 + e)
        if accept:
            ext_i[ne] = i
            ext_k[ne] = dc
            ne += 1
    return ne


@njit(cache=True, inline="always")
def _first_smallest(keys: np.ndarray, m: int) -> int:
    """Index of the first of the smallest keys[:m] (the head of a stable sort)."""
    b = 0
    for a in range(1, m):
        if keys[a] < keys[b]:
            b = a
    return b


@njit(cache=True, inline="always")
def _dd_choose_parent(nx: float, ny: float, ne: int, world: World, cfg: np.record, tree: Tree, state: np.record,
                      buf: Scratch, dv: Derived) -> tuple[int, float, int]:
    """Figure 6 lines 12-17: the extendable nodes within a step of q_new, in D_C order (a stable
    sort of that subset, keys in buf.kn_d, gives the order sorting all of them would give it),
    into buf.rw_i; returns (parent, its cost, how many), parent -1 if none is valid."""
    X = tree.X
    cost = tree.cost
    ext_i = buf.ext_i
    ext_k = buf.ext_k
    rw_i = buf.rw_i
    keys = buf.kn_d
    near_i = buf.near_i
    near_c = buf.near_c
    near_x = buf.near_x
    lower_bounds = dv.lower_bounds
    lbf = dv.lbf
    lb_margin = dv.lb_margin
    step = cfg.step
    ns = 0
    for a in range(ne):
        i = ext_i[a]
        if _within(nx - X[i, 0], ny - X[i, 1], step * (1.0 + 1e-9)):
            rw_i[ns] = i
            keys[ns] = ext_k[a]
            ns += 1
    _sort_by(keys, rw_i, np.int64(ns))
    for a in range(ns):
        i = rw_i[a]
        near_i[a] = i
        if lower_bounds:
            # a lower bound of the key; _first_valid_parent makes exact only the keys that may be
            # the minimum (an eq. (12) edge costs an exp and a field look-up)
            ex = nx - X[i, 0]
            ey = ny - X[i, 1]
            near_c[a] = cost[i] + lbf * math.sqrt(ex * ex + ey * ey) * (1.0 - lb_margin)
            near_x[a] = False
        else:
            near_c[a], near_x[a] = _parent_key(i, nx, ny, world, cfg, tree)
    p, pc = _first_valid_parent(near_i, near_c, near_x, np.int64(ns), nx, ny, world, cfg, tree, state, np.bool_(True),
                                lower_bounds)
    return p, pc, ns


@njit(cache=True, inline="always")
def _ddrrt_extend(sx: float, sy: float, from_png: bool, world: World, cfg: np.record, tree: Tree, state: np.record,
                  buf: Scratch, dv: Derived) -> int:
    """One DDRRT* extension towards the sample (Figure 6); returns q_new's index or -1."""
    X = tree.X
    ne = _dd_candidates(sx, sy, cfg, tree, state, buf, dv)
    if ne == 0:
        state.rejected += 1
        return -1
    q0 = buf.ext_i[_first_smallest(buf.ext_k, ne)]
    d0 = math.hypot(sx - X[q0, 0], sy - X[q0, 1])
    if d0 < 1e-9:
        if from_png:
            state.png_wasted += 1
            if cfg.png_repair != 0:
                state.png_hit = 1  # a node sits on the PGNode: drawing it again would be wasted
        return -1
    nx, ny = _steer(q0, d0, sx, sy, X, cfg.step)
    p, pc, ns = _dd_choose_parent(nx, ny, ne, world, cfg, tree, state, buf, dv)
    if p < 0:
        return -1
    if not math.isinf(tree.dd[p]):
        tree.dd[p] *= cfg.dd_grow  # a successful extension grows a bounded domain (adaptive form)
    new = _add_node(nx, ny, p, pc, world, cfg, tree, state)
    if from_png and cfg.png_repair != 0 and nx == sx and ny == sy:
        state.png_hit = 1
    _rewire_through(new, p, buf.rw_i, ns, world, cfg, tree, state, dv)
    return new


@njit(cache=True, inline="always")
def _rrt_choose_parent(nx: float, ny: float, q0: int, nn: int, world: World, cfg: np.record, tree: Tree,
                       state: np.record, buf: Scratch, dv: Derived) -> tuple[int, float]:
    """Choose-parent over the near ball buf.near_i[:nn] and the nearest node q0, in ascending cost
    order; the nearest is not required to be valid itself (with the fan limit it often is not).
    Returns (parent, its cost), parent -1 if none is valid."""
    X = tree.X
    cost = tree.cost
    near_i = buf.near_i
    near_c = buf.near_c
    near_x = buf.near_x
    use_field = cfg.use_field != 0
    lower_bounds = dv.lower_bounds
    lbf = dv.lbf
    lb_margin = dv.lb_margin
    nc = 0
    has_q0 = False
    for a in range(nn):
        j = near_i[a]
        if j == q0:
            has_q0 = True
        ex = nx - X[j, 0]
        ey = ny - X[j, 1]
        if not use_field:  # _parent_key's length case, written out: a call per near node is costly
            near_c[nc] = cost[j] + math.sqrt(ex * ex + ey * ey)
            near_x[nc] = False
        elif lower_bounds:  # see _dd_choose_parent
            near_c[nc] = cost[j] + lbf * math.sqrt(ex * ex + ey * ey) * (1.0 - lb_margin)
            near_x[nc] = False
        else:
            near_c[nc], near_x[nc] = _parent_key(j, nx, ny, world, cfg, tree)
        nc += 1
    if not has_q0 and nc < NEAR_CAP:
        near_i[nc] = q0
        near_c[nc], near_x[nc] = _parent_key(q0, nx, ny, world, cfg, tree)
        nc += 1
    return _first_valid_parent(near_i, near_c, near_x, np.int64(nc), nx, ny, world, cfg, tree, state, np.bool_(False),
                               lower_bounds)


@njit(cache=True, inline="always")
def _rrt_extend(sx: float, sy: float, world: World, cfg: np.record, tree: Tree, state: np.record, buf: Scratch,
                dv: Derived) -> int:
    """One RRT* extension towards the sample (Karaman & Frazzoli 2011, radius version); returns
    q_new's index or -1."""
    X = tree.X
    n = state.n
    _knn(sx, sy, np.int64(1), cfg, tree, buf.kn_i, buf.kn_d)
    q0 = buf.kn_i[0]
    d0 = buf.kn_d[0]
    if d0 < 1e-9:
        return -1
    step = cfg.step
    nx, ny = _steer(q0, d0, sx, sy, X, step)
    radius = step
    if n > 1:
        radius = min(step, cfg.rewire_gamma * math.sqrt(math.log(n) / n))
    bx, by = _bucket(nx, ny, cfg)
    nn, pos_new = _near_pos(nx, ny, radius, cfg, tree, buf.near_i, by * cfg.nbx + bx)
    for a in range(nn):
        buf.rw_i[a] = buf.near_i[a]
    p, pc = _rrt_choose_parent(nx, ny, q0, nn, world, cfg, tree, state, buf, dv)
    if p < 0:
        return -1
    new = _add_node(nx, ny, p, pc, world, cfg, tree, state)
    # rewire: the near set as a second scan would give it: the same nodes in the same order with
    # q_new (skipped) first in its bucket; when that scan is cut at NEAR_CAP and q_new comes before
    # the cut, it pushes the last node out
    if nn == NEAR_CAP and pos_new < NEAR_CAP:
        nn -= 1
    _rewire_through(new, p, buf.rw_i, nn, world, cfg, tree, state, dv)
    return new


def grow(world: World, cfg_a: np.ndarray, tree: Tree, state_a: np.ndarray, scratch: Scratch, max_iter: int,
         deadline_ns: int, stop_on_exact: bool, cpu_deadline_ns: int = -1) -> int:
    """Run up to max_iter iterations; see the module docstring for the arguments and the return
    codes. ``cfg_a`` and ``state_a`` are 1-element arrays of CONFIG and STATE; the caller keeps
    world, tree and scratch alive during the call. DDRRT* runs :func:`grow_ddrrt`, RRT* and
    Informed RRT* :func:`grow_rrt`: two kernels, so that a process compiles only the extension
    step its algorithm uses (each is about half of the tree core's compile)."""
    kernel = grow_kernel(int(cfg_a[0]["algo"]))
    return kernel(world, cfg_a, tree, state_a, scratch, max_iter, deadline_ns, stop_on_exact, cpu_deadline_ns)


def grow_kernel(algo: int) -> Callable[..., int]:
    """The compiled kernel :func:`grow` runs for an algorithm code."""
    return cast(Callable[..., int], grow_ddrrt if algo == DDRRT_STAR else grow_rrt)


@njit(cache=True, inline="always")
def _stop_before(deadline_ns: int, cpu_deadline_ns: int, cfg: np.record, state: np.record, buf: Scratch) -> int:
    """The return code that ends the search before the next iteration, or -1 to go on."""
    if deadline_ns >= 0 and monotonic_ns(buf.clock) >= deadline_ns:
        return DONE_DEADLINE
    if cpu_deadline_ns >= 0 and thread_cpu_ns(buf.clock) >= cpu_deadline_ns:
        return DONE_DEADLINE
    if state.n + 2 > cfg.cap:
        return DONE_FULL
    return -1


@njit(cache=True)
def grow_ddrrt(world: World, cfg_a: np.ndarray, tree: Tree, state_a: np.ndarray, scratch: Scratch, max_iter: int,
               deadline_ns: int, stop_on_exact: bool, cpu_deadline_ns: int = -1) -> int:
    """:func:`grow` for DDRRT* (``cfg.algo`` DDRRT_STAR)."""
    cfg = cfg_a[0]
    state = state_a[0]
    world, tree, buf = _borrowed(world, tree, scratch)
    dv = _derive(cfg)
    for _ in range(max_iter):
        code = _stop_before(deadline_ns, cpu_deadline_ns, cfg, state, buf)
        if code >= 0:
            return code
        state.iter += 1
        sx, sy, from_png = _sample_ddrrt(cfg, state)
        new = _ddrrt_extend(sx, sy, from_png, world, cfg, tree, state, buf, dv)
        if new < 0:
            continue
        _try_goal(new, world, cfg, tree, state, buf.clock)
        if stop_on_exact and state.goal >= 0:
            return DONE_EXACT
    return DONE_ITERATIONS


@njit(cache=True)
def grow_rrt(world: World, cfg_a: np.ndarray, tree: Tree, state_a: np.ndarray, scratch: Scratch, max_iter: int,
             deadline_ns: int, stop_on_exact: bool, cpu_deadline_ns: int = -1) -> int:
    """:func:`grow` for RRT* and Informed RRT* (``cfg.algo`` RRT_STAR or INFORMED_RRT_STAR)."""
    cfg = cfg_a[0]
    state = state_a[0]
    world, tree, buf = _borrowed(world, tree, scratch)
    dv = _derive(cfg)
    for _ in range(max_iter):
        code = _stop_before(deadline_ns, cpu_deadline_ns, cfg, state, buf)
        if code >= 0:
            return code
        state.iter += 1
        sx, sy, from_png = _sample(cfg, tree, state)
        new = _rrt_extend(sx, sy, world, cfg, tree, state, buf, dv)
        if new < 0:
            continue
        _try_goal(new, world, cfg, tree, state, buf.clock)
        if stop_on_exact and state.goal >= 0:
            return DONE_EXACT
    return DONE_ITERATIONS


@njit(cache=True)
def seed_tree(world: World, cfg_a: np.ndarray, tree: Tree, state_a: np.ndarray, clock: np.ndarray, nodes: np.ndarray,
              parents: np.ndarray) -> int:
    """Start the search from a reused tree (section 3.5, line 3): append ``nodes[1:]`` (m, 2) to
    a tree that holds only its root, ``nodes[0]`` being that root's place and ``parents`` (m,)
    each node's parent index into ``nodes`` (smaller than its own; -1 for the root). A node is
    kept only if its parent was kept, it lies in the sampling domain, its edge lies in its
    parent's turning fan and is collision free on this search's map (a collision check each,
    counted). Costs are recomputed from the root with this search's objective, dynamic domains
    start unbounded, and each kept node is offered the goal as a grown node is. Returns the
    number of nodes kept (the root not counted)."""
    cfg = cfg_a[0]
    state = state_a[0]
    m = nodes.shape[0]
    where = np.full(m, -1, dtype=np.int64)
    where[0] = 0
    X = tree.X
    kept = 0
    for i in range(1, m):
        p = parents[i]
        if p < 0 or p >= i or where[p] < 0:
            continue
        if state.n + 2 > cfg.cap:
            break
        q = where[p]
        x = nodes[i, 0]
        y = nodes[i, 1]
        if not _in_domain(x, y, cfg):
            continue
        dx = x - X[q, 0]
        dy = y - X[q, 1]
        if dx * dx + dy * dy < 1e-18 or not _fan_ok(tree.head[q], dx, dy, cfg.max_turn):
            continue
        if not _free(world, cfg, state, X[q, 0], X[q, 1], x, y):
            continue
        c = tree.cost[q] + _cost(X[q, 0], X[q, 1], x, y, world.fvx, world.fvy, cfg)
        j = _add_node(x, y, q, c, world, cfg, tree, state)
        where[i] = j
        kept += 1
        _try_goal(j, world, cfg, tree, state, clock)
    return kept
