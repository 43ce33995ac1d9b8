"""The compiled tree core shared by RRT*, Informed RRT* and DDRRT*.

Everything lives in preallocated arrays (see :class:`TreeArrays`); ``grow`` runs up to
``max_iter`` iterations (one iteration = one sample drawn) and returns early at a
``CLOCK_MONOTONIC`` deadline (checked before every iteration), at the first exact solution when
asked, or when the tree is full.

Nearest and near searches use grid buckets of side ``step``: a near query (radius <= step) scans
3 x 3 buckets, a k-nearest query scans rings of buckets outwards until the k-th distance is
certain. Collision checks are the exact cell traversal of :mod:`planner._kernels`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner._kernels import edge_cost, field_at, monotonic_ns, segment_free, thread_cpu_ns

# algorithm codes
RRT_STAR = 0
INFORMED_RRT_STAR = 1
DDRRT_STAR = 2

# grow() return codes
DONE_ITERATIONS = 0
DONE_DEADLINE = 1
DONE_EXACT = 2
DONE_FULL = 3

# float config indices
C_STEP, C_MAXTURN, C_GOALTOL, C_GOALBIAS, C_PNGP, C_PNGX, C_PNGY, C_DR, C_DALPHA, C_GAMMA = range(10)
C_RGAMMA, C_FMIN, C_BUCKET, C_BX0, C_BX1, C_BY0, C_BY1, C_DCX, C_DCY, C_DR_DOM = range(10, 20)
C_GX, C_GY, C_SX, C_SY, C_RES, C_FRES, C_FOX, C_FOY, C_KGROW = range(20, 29)
C_DD0, C_DDGROW, C_DDSHRINK, C_DDMIN = range(29, 33)
N_FCFG = 33
# int config indices
I_ALGO, I_FIELD, I_K, I_NBX, I_NBY, I_CAP, I_PNG, I_FAILTURN, I_PNGREPAIR = range(9)
N_ICFG = 9
# int state indices
S_N, S_GOAL, S_ITER, S_REJ, S_CLOSEST, S_FIRST_ITER, S_CHECKS, S_FAILED = range(8)
S_FAILED_TURN, S_PNG_HIT, S_FIRST_CHECKS, S_PNG_WASTED = range(8, 12)
N_ISTATE = 12
# float state indices
F_CLOSEST_D, F_FIRST_NS, F_FIRST_CPU_NS = range(3)
N_FSTATE = 4

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
def _within(dx, dy, r):
    """math.hypot(dx, dy) <= r, exactly, mostly without calling hypot (r > 0 finite)."""
    d2 = dx * dx + dy * dy
    r2 = r * r
    if d2 < r2 * (1.0 - _REL):
        return True
    if d2 > r2 * (1.0 + _REL):
        return False
    return math.hypot(dx, dy) <= r


@njit(cache=True)
def seed_rng(seed):
    np.random.seed(seed)


@njit(cache=True)
def _wrap(a):
    if a > 8.0 * math.pi or a < -8.0 * math.pi:  # a huge angle (1e300): one modulo, never a long loop
        a = a % TWO_PI  # numba has no math.fmod; % gives [0, 2 pi), inf gives nan
    while a > math.pi:
        a -= TWO_PI
    while a < -math.pi:
        a += TWO_PI
    return a


@njit(cache=True)
def _fan_ok(head, dx, dy, max_turn):
    """Section 2.4: the new edge must lie in the fan of half-angle max_turn about the heading."""
    if math.isnan(head) or max_turn >= math.pi:
        return True
    return abs(_wrap(math.atan2(dy, dx) - head)) <= max_turn + 1e-9


@njit(cache=True)
def _fan_bounds(max_turn):
    """(cos_pass, cos_fail, usable) for _fan_ok_cos: a direction whose cosine with the heading is
    >= cos_pass is inside the fan, <= cos_fail outside, whatever the rounding of _fan_ok's atan2
    (1e-7 rad and 1e-12 of slack, far above both computations' errors)."""
    t = max_turn + 1e-9
    if t - 1e-7 <= 0.0 or t + 1e-7 >= math.pi:
        return 2.0, -2.0, False
    return math.cos(t - 1e-7) + 1e-12, math.cos(t + 1e-7) - 1e-12, True


@njit(cache=True)
def _fan_ok_cos(head, hx, hy, dx, dy, max_turn, fb):
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


@njit(cache=True)
def _bucket(x, y, fc, ic):
    bx = int(x / fc[C_BUCKET])  # buckets cover the whole map from (0, 0)
    by = int(y / fc[C_BUCKET])
    bx = min(max(bx, 0), ic[I_NBX] - 1)
    by = min(max(by, 0), ic[I_NBY] - 1)
    return bx, by


@njit(cache=True)
def _insert_bucket(i, X, fc, ic, bucket_head, node_next):
    bx, by = _bucket(X[i, 0], X[i, 1], fc, ic)
    b = by * ic[I_NBX] + bx
    node_next[i] = bucket_head[b]
    bucket_head[b] = i


@njit(cache=True)
def _knn(qx, qy, k, X, fc, ic, bucket_head, node_next, out_i, out_d):
    """k nearest nodes (Euclidean), ascending; returns how many were found (<= k). Squared
    distances while scanning (no square root per candidate), roots of the k results at the end.

    The scan stops after the ring whose block of buckets is certain to hold every node nearer
    than the k-th found: the distance from the query to the nearest side of the block (sides on
    the map's border do not count; 1e-6 m of slack for bucket rounding), or ring x bucket side.
    Nodes beyond are at least as far as the k-th, and an equal distance never displaces a node
    found earlier, so the result is that of a full scan."""
    cx, cy = _bucket(qx, qy, fc, ic)
    nbx = ic[I_NBX]
    nby = ic[I_NBY]
    m = 0
    rmax = max(nbx, nby)
    B = fc[C_BUCKET]
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
def _near(qx, qy, radius, X, fc, ic, bucket_head, node_next, out_i):
    """Nodes within ``radius`` (at most NEAR_CAP of them)."""
    return _near_pos(qx, qy, radius, X, fc, ic, bucket_head, node_next, out_i, -1)[0]


@njit(cache=True)
def _near_pos(qx, qy, radius, X, fc, ic, bucket_head, node_next, out_i, mark):
    """_near, and how many nodes it had found when it reached bucket ``mark`` (NEAR_CAP if it
    never did)."""
    B = fc[C_BUCKET]
    nbx = ic[I_NBX]
    nby = ic[I_NBY]
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


@njit(cache=True)
def _in_domain(x, y, fc):
    if x < fc[C_BX0] or x > fc[C_BX1] or y < fc[C_BY0] or y > fc[C_BY1]:
        return False
    if fc[C_DR_DOM] > 0.0:
        return _within(x - fc[C_DCX], y - fc[C_DCY], fc[C_DR_DOM])
    return True


@njit(cache=True)
def _uniform(fc):
    x = 0.0
    y = 0.0
    for _ in range(64):
        x = fc[C_BX0] + np.random.random() * (fc[C_BX1] - fc[C_BX0])
        y = fc[C_BY0] + np.random.random() * (fc[C_BY1] - fc[C_BY0])
        if _in_domain(x, y, fc):
            break
    return x, y


@njit(cache=True)
def _in_ellipse(x, y, sx, sy, gx, gy, cb):
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
def _informed(fc, c_best):
    """Gammell et al. 2014: uniform sample of the prolate hyperspheroid (an ellipse in 2-D) with
    foci start and goal and transverse diameter c_best / f_min (f_min D_C <= Ed keeps it a lower
    bound of the cost through a point), intersected with the sampling domain."""
    sx = fc[C_SX]
    sy = fc[C_SY]
    gx = fc[C_GX]
    gy = fc[C_GY]
    c_min = math.hypot(gx - sx, gy - sy)
    cb = c_best / fc[C_FMIN]
    if cb <= c_min:
        cb = c_min * (1.0 + 1e-9)
    a = 0.5 * cb                                  # semi-major axis
    b = 0.5 * math.sqrt(max(cb * cb - c_min * c_min, 0.0))  # semi-minor axis
    th = math.atan2(gy - sy, gx - sx)             # rotation to the world frame (C in Gammell)
    ct = math.cos(th)
    st = math.sin(th)
    mx = 0.5 * (sx + gx)
    my = 0.5 * (sy + gy)
    box = (fc[C_BX1] - fc[C_BX0]) * (fc[C_BY1] - fc[C_BY0])
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
            if _in_domain(x, y, fc):
                return x, y
        return _uniform(fc)
    # the ellipse covers more than the box: sample the box, keep points inside the ellipse
    for _ in range(64):
        x, y = _uniform(fc)
        if _in_ellipse(x, y, sx, sy, gx, gy, cb):
            return x, y
    return x, y


@njit(cache=True)
def _children_fan_ok(j, new_head, X, first_child, next_sib, max_turn):
    if max_turn >= math.pi:
        return True
    c = first_child[j]
    while c >= 0:
        if not _fan_ok(new_head, X[c, 0] - X[j, 0], X[c, 1] - X[j, 1], max_turn):
            return False
        c = next_sib[c]
    return True


@njit(cache=True)
def _reparent(j, p, new_cost, X, parent, cost, head, first_child, next_sib, stack):
    """Make p the parent of j and propagate the cost change to j's subtree."""
    old = parent[j]
    if old >= 0:
        if first_child[old] == j:
            first_child[old] = next_sib[j]
        else:
            c = first_child[old]
            while next_sib[c] != j:
                c = next_sib[c]
            next_sib[c] = next_sib[j]
    parent[j] = p
    next_sib[j] = first_child[p]
    first_child[p] = j
    head[j] = math.atan2(X[j, 1] - X[p, 1], X[j, 0] - X[p, 0])
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


@njit(cache=True)
def _set_direction(i, x, y, nv, fvx, fvy, fc):
    """nv[i] = the unit vector of the current at (x, y), or (0, 0) where there is none."""
    vx, vy = field_at(fvx, fvy, fc[C_FRES], fc[C_FOX], fc[C_FOY], x, y)
    v = math.hypot(vx, vy)
    if v < 1e-9:
        nv[i, 0] = 0.0
        nv[i, 1] = 0.0
    else:
        nv[i, 0] = vx / v
        nv[i, 1] = vy / v


@njit(cache=True)
def _add_node(x, y, p, c, X, parent, cost, head, dd, first_child, next_sib, fc, ic, bucket_head,
              node_next, st, nv, fvx, fvy):
    i = st[S_N]
    X[i, 0] = x
    X[i, 1] = y
    if ic[I_FIELD] != 0:
        _set_direction(i, x, y, nv, fvx, fvy, fc)
    parent[i] = p
    cost[i] = c
    head[i] = math.atan2(y - X[p, 1], x - X[p, 0])
    dd[i] = np.inf
    first_child[i] = -1
    next_sib[i] = first_child[p]
    first_child[p] = i
    _insert_bucket(i, X, fc, ic, bucket_head, node_next)
    st[S_N] = i + 1
    return i


@njit(cache=True)
def _cost(x0, y0, x1, y1, fc, ic, fvx, fvy):
    return edge_cost(x0, y0, x1, y1, ic[I_FIELD] != 0, fvx, fvy, fc[C_FRES], fc[C_FOX], fc[C_FOY],
                     fc[C_STEP], fc[C_DALPHA], fc[C_GAMMA])


@njit(cache=True)
def _free(occ, fc, st, x0, y0, x1, y1):
    st[S_CHECKS] += 1
    return segment_free(occ, fc[C_RES], x0, y0, x1, y1)


@njit(cache=True)
def _dd_failed(i, dd, fc):
    """A failed (colliding) extension from node i: its dynamic domain becomes bounded (DD0), or,
    already bounded, shrinks by the adaptive factor (Jaillet et al. 2005), never below DDMIN."""
    if math.isinf(dd[i]):
        dd[i] = fc[C_DD0]
    else:
        dd[i] = max(dd[i] * fc[C_DDSHRINK], fc[C_DDMIN])


@njit(cache=True)
def _turn_failed(i, dd, fc, st):
    """An extension from node i refused by the turning-radius fan (section 2.4), counted as a
    failed extension when the paper's reading is chosen (failed_extension = "collision+turn"): the
    paper counts constraint violations as well as collisions."""
    st[S_FAILED] += 1
    st[S_FAILED_TURN] += 1
    _dd_failed(i, dd, fc)


@njit(cache=True)
def _sort_by(keys, idx, m):
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
def _parent_key(j, nx, ny, X, cost, fc, ic, fvx, fvy):
    """(key, exact): the cost to (nx, ny) through node j. With a current, exact. For length, a
    square root instead of math.hypot (exact = False): within 7.2e-16 relative of the exact key,
    which _first_valid_parent computes only for the candidates that can be the minimum."""
    if ic[I_FIELD] != 0:
        return cost[j] + _cost(X[j, 0], X[j, 1], nx, ny, fc, ic, fvx, fvy), True
    dx = nx - X[j, 0]
    dy = ny - X[j, 1]
    return cost[j] + math.sqrt(dx * dx + dy * dy), False


@njit(cache=True)
def _first_valid_parent(near_i, near_c, near_x, nc, nx, ny, occ, fc, ic, fvx, fvy, st, X, cost, head, max_turn,
                        dd, track_failed, lower_bounds):
    """RRT*'s choose-parent: the first candidate, in ascending cost order, whose edge to (nx, ny)
    is in its fan and collision-free; returns (node, cost through it) or (-1, 0.0). With
    ``track_failed`` (DDRRT*) a colliding candidate counts as a failed extension and bounds or
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
    exp and field look-up. After LAZY_TRIES refused candidates (with the fan limit, the cheapest candidates often point
    backwards), the rest is sorted once instead (exact keys, stable merge sort: the same order)."""
    left = nc
    tries = 0
    while left > 0:
        if tries == LAZY_TRIES:
            for a in range(left):
                if not near_x[a]:
                    i = near_i[a]
                    near_c[a] = cost[i] + _cost(X[i, 0], X[i, 1], nx, ny, fc, ic, fvx, fvy)
                    near_x[a] = True
            order = np.argsort(near_c[:left], kind="mergesort")
            for o in range(left):
                j = near_i[order[o]]
                if _fan_ok(head[j], nx - X[j, 0], ny - X[j, 1], max_turn):
                    if _free(occ, fc, st, X[j, 0], X[j, 1], nx, ny):
                        return j, near_c[order[o]]
                    if track_failed:
                        st[S_FAILED] += 1
                        _dd_failed(j, dd, fc)
                elif track_failed and ic[I_FAILTURN] != 0:
                    _turn_failed(j, dd, fc, st)
            return -1, 0.0
        tries += 1
        if lower_bounds:  # make exact every key that may be the minimum, until none is left
            while True:
                m = near_c[0]
                for a in range(1, left):
                    if near_c[a] < m:
                        m = near_c[a]
                window = m * (1.0 + 1e-12) + 1e-12
                exacted = False
                for a in range(left):
                    if near_c[a] <= window and not near_x[a]:
                        i = near_i[a]
                        near_c[a] = cost[i] + _cost(X[i, 0], X[i, 1], nx, ny, fc, ic, fvx, fvy)
                        near_x[a] = True
                        exacted = True
                if not exacted:
                    break
        m = near_c[0]
        for a in range(1, left):
            if near_c[a] < m:
                m = near_c[a]
        window = m * (1.0 + 1e-12) + 1e-12
        b = -1
        kb = 0.0
        for a in range(left):
            if near_c[a] <= window:
                if not near_x[a]:  # square-root keys (see above): one pass decides
                    i = near_i[a]
                    near_c[a] = cost[i] + _cost(X[i, 0], X[i, 1], nx, ny, fc, ic, fvx, fvy)
                    near_x[a] = True
                if b < 0 or near_c[a] < kb:  # strict: the first of equal keys, as the stable sort would
                    kb = near_c[a]
                    b = a
        j = near_i[b]
        if _fan_ok(head[j], nx - X[j, 0], ny - X[j, 1], max_turn):
            if _free(occ, fc, st, X[j, 0], X[j, 1], nx, ny):
                return j, kb
            if track_failed:
                st[S_FAILED] += 1
                _dd_failed(j, dd, fc)
        elif track_failed and ic[I_FAILTURN] != 0:
            _turn_failed(j, dd, fc, st)
        for a in range(b, left - 1):  # drop candidate b, keeping the others' order
            near_c[a] = near_c[a + 1]
            near_i[a] = near_i[a + 1]
            near_x[a] = near_x[a + 1]
        left -= 1
    return -1, 0.0


@njit(cache=True)
def _first_counts(st, fs, clockbuf):
    """At the first exact solution: the collision checks so far and the thread's CPU clock, so
    that time to a first solution can be judged independent of the platform (issue 34)."""
    st[S_FIRST_CHECKS] = st[S_CHECKS]
    fs[F_FIRST_CPU_NS] = thread_cpu_ns(clockbuf)


@njit(cache=True)
def _try_goal(i, occ, X, parent, cost, head, dd, first_child, next_sib, fc, ic, bucket_head, node_next,
              st, fs, fvx, fvy, stack, clockbuf, nv):
    """After node i joined the tree: track the closest node and connect the goal exactly."""
    gx = fc[C_GX]
    gy = fc[C_GY]
    d = math.hypot(X[i, 0] - gx, X[i, 1] - gy)
    if d < fs[F_CLOSEST_D]:
        fs[F_CLOSEST_D] = d
        st[S_CLOSEST] = i
    g = st[S_GOAL]
    if d > fc[C_GOALTOL] or i == g:
        return
    if d < 1e-9:
        if g < 0:
            st[S_GOAL] = i
            st[S_FIRST_ITER] = st[S_ITER]
            fs[F_FIRST_NS] = monotonic_ns(clockbuf)
            _first_counts(st, fs, clockbuf)
        return
    c = cost[i] + _cost(X[i, 0], X[i, 1], gx, gy, fc, ic, fvx, fvy)
    if g >= 0 and c >= cost[g] - 1e-12:
        return
    dx = gx - X[i, 0]
    dy = gy - X[i, 1]
    if not _fan_ok(head[i], dx, dy, fc[C_MAXTURN]):
        return
    if g >= 0 and not _children_fan_ok(g, math.atan2(dy, dx), X, first_child, next_sib, fc[C_MAXTURN]):
        return
    if not _free(occ, fc, st, X[i, 0], X[i, 1], gx, gy):
        return
    if g < 0:
        if st[S_N] >= ic[I_CAP]:
            return
        g = _add_node(gx, gy, i, c, X, parent, cost, head, dd, first_child, next_sib, fc, ic, bucket_head,
                      node_next, st, nv, fvx, fvy)
        st[S_GOAL] = g
        st[S_FIRST_ITER] = st[S_ITER]
        fs[F_FIRST_NS] = monotonic_ns(clockbuf)
        _first_counts(st, fs, clockbuf)
        fs[F_CLOSEST_D] = 0.0
        st[S_CLOSEST] = g
    else:
        _reparent(g, i, c, X, parent, cost, head, first_child, next_sib, stack)


@njit(cache=True)
def _rewire(j, new, nx, ny, occ, fvx, fvy, fc, ic, st, X, parent, cost, head, first_child, next_sib, stack,
            max_turn, hx, hy, fb):
    """Make q_new the parent of node j if that is cheaper and the edge is valid (fan limit for the
    edge and for j's children, collision-free): the rewiring step shared by RRT* and DDRRT*.
    The tests are side-effect free until the collision check, so the cheap ones come first;
    (hx, hy) = (cos, sin) of q_new's heading, fb = _fan_bounds(max_turn). The caller has
    already refused the candidates that _rewire_cannot_pay refuses."""
    dx = X[j, 0] - nx
    dy = X[j, 1] - ny
    if not _fan_ok_cos(head[new], hx, hy, dx, dy, max_turn, fb):
        return
    c = cost[new] + _cost(nx, ny, X[j, 0], X[j, 1], fc, ic, fvx, fvy)
    if c >= cost[j] - 1e-12:
        return
    if not _children_fan_ok(j, math.atan2(dy, dx), X, first_child, next_sib, max_turn):
        return
    if _free(occ, fc, st, nx, ny, X[j, 0], X[j, 1]):
        _reparent(j, new, c, X, parent, cost, head, first_child, next_sib, stack)


@njit(cache=True)
def _rewire_cannot_pay(j, new, nx, ny, X, cost, lbf, margin):
    """True if rewiring node j through q_new cannot lower its cost, decided on a square root:
    lbf * sqrt(...) * (1 - margin) <= the computed edge cost (_edge_lower_factor), and rounding is
    monotone, so this refuses only candidates that _rewire's exact comparison refuses too. Kept
    small so that it is inlined: _rewire's call alone costs tens of ns, and Informed RRT* can have
    a thousand near nodes per sample."""
    if lbf <= 0.0:
        return False
    dx = X[j, 0] - nx
    dy = X[j, 1] - ny
    return cost[new] + lbf * math.sqrt(dx * dx + dy * dy) * (1.0 - margin) >= cost[j] - 1e-12


@njit(cache=True)
def _edge_lower_factor(fc, ic):
    """f with edge cost >= f x edge length for every edge: 1 for length; for eq. (12), where each
    piece costs min(1, D_alpha / (1 + exp(cos a - gamma sin a))) x its length and the exponent is
    at most 1 when gamma >= 0, f = min(1, D_alpha / (1 + e)). 0 (no bound used) otherwise."""
    if ic[I_FIELD] == 0:
        return 1.0
    da = fc[C_DALPHA]
    if da > 0.0 and fc[C_GAMMA] >= 0.0:
        return min(1.0, da / (1.0 + math.e))
    return 0.0


@njit(cache=True)
def _esd_floor(a, gamma):
    """A value below eq. (11)'s second term a / (1 + exp(-arg)) for every alpha_y, whatever its
    rounding: arg = cos a - gamma sin a >= -1 - gamma when gamma >= 0 (-inf, no floor, otherwise),
    and the term grows with arg."""
    if not (a > 0.0 and gamma >= 0.0):
        return -math.inf
    e = math.exp(-1.0 - gamma)
    return a * e / (1.0 + e) * (1.0 - 1e-12)


@njit(cache=True)
def node_direction(i, x, y, nv, fvx, fvy, fc):
    """Entry point for the solve loop: the root's current direction (see _set_direction)."""
    _set_direction(i, x, y, nv, fvx, fvy, fc)


@njit(cache=True)
def grow(occ, fvx, fvy, fc, ic, X, parent, cost, head, dd, first_child, next_sib, bucket_head, node_next,
         st, fs, stack, nv, max_iter, deadline_ns, stop_on_exact):
    """Run up to max_iter iterations; see the module docstring for the return codes."""
    clockbuf = np.zeros(2, np.int64)
    k_min = ic[I_K]
    k_growth = fc[C_KGROW]
    kn_i = np.empty(K_CAP, np.int64)
    kn_d = np.empty(K_CAP, np.float64)
    ext_i = np.empty(K_CAP, np.int64)
    ext_k = np.empty(K_CAP, np.float64)
    near_i = np.empty(NEAR_CAP, np.int64)
    near_c = np.empty(NEAR_CAP, np.float64)
    near_x = np.empty(NEAR_CAP, np.bool_)
    rw_i = np.empty(NEAR_CAP, np.int64)
    step = fc[C_STEP]
    max_turn = fc[C_MAXTURN]
    algo = ic[I_ALGO]
    lbf = _edge_lower_factor(fc, ic)
    use_field = ic[I_FIELD] != 0
    # length: the edge cost is hypot, within 4e-16 of the square root; eq. (12): exp and the sum
    # of pieces round too, so a wider margin
    lb_margin = 2e-15 if ic[I_FIELD] == 0 else 1e-9
    lower_bounds = use_field and lbf > 0.0  # choose-parent keys start as lower bounds (eq. (12))
    d_alpha = fc[C_DALPHA]
    gamma = fc[C_GAMMA]
    esd_plain = d_alpha * fc[C_DR]
    esd_floor = _esd_floor(esd_plain, gamma)
    cp, cf, fan_usable = _fan_bounds(max_turn)
    fb = np.array([cp, cf, 1.0 if fan_usable else 0.0])
    for _ in range(max_iter):
        if deadline_ns >= 0 and monotonic_ns(clockbuf) >= deadline_ns:
            return DONE_DEADLINE
        if st[S_N] + 2 > ic[I_CAP]:
            return DONE_FULL
        st[S_ITER] += 1
        # ---- sample: PNG node with probability P (DDRRT*), else goal bias, else uniform/informed
        from_png = False
        if ic[I_PNG] != 0 and st[S_PNG_HIT] == 0 and np.random.random() < fc[C_PNGP]:
            sx = fc[C_PNGX]
            sy = fc[C_PNGY]
            from_png = True
        elif np.random.random() < fc[C_GOALBIAS]:
            sx = fc[C_GX]
            sy = fc[C_GY]
        elif algo == INFORMED_RRT_STAR and st[S_GOAL] >= 0:
            sx, sy = _informed(fc, cost[st[S_GOAL]])
        else:
            sx, sy = _uniform(fc)
        n = st[S_N]
        if algo == DDRRT_STAR:
            # ---- Figure 6 lines 5-11: k nearest sorted by D_C, keep those with D_C <= ESD.
            # k is the paper's constant, or (k_growth > 0) grows as k-nearest RRT* needs for
            # asymptotic optimality: k(n) = max(k, ceil(k_growth log n)) (Karaman & Frazzoli 2011).
            k = k_min
            if k_growth > 0.0 and n > 1:
                k = max(k_min, min(K_CAP, int(math.ceil(k_growth * math.log(n)))))
            m = _knn(sx, sy, k, X, fc, ic, bucket_head, node_next, kn_i, kn_d)
            ne = 0
            for a in range(m):
                i = kn_i[a]
                ed = kn_d[a]
                if ed > dd[i]:
                    continue  # outside the node's dynamic domain (a disc of radius DD, Yershova 2005)
                # eq. (12) with one alpha_y, the current at q_i (the same alpha_y as eq. (11)'s)
                dc = ed
                accept = dc <= esd_plain
                if use_field and ed > 0.0 and (nv[i, 0] != 0.0 or nv[i, 1] != 0.0):
                    c = ((sx - X[i, 0]) * nv[i, 0] + (sy - X[i, 1]) * nv[i, 1]) / ed
                    c = min(1.0, max(-1.0, c))
                    e = math.exp(c - gamma * math.sqrt(max(0.0, 1.0 - c * c)))
                    dc = min(ed, d_alpha * ed / (1.0 + e))
                    # D_alpha DR / (1 + exp(-arg)), computed only where esd_floor does not decide
                    accept = dc <= esd_floor or dc <= esd_plain * e / (1.0 + e)
                if accept:
                    ext_i[ne] = i
                    ext_k[ne] = dc
                    ne += 1
            if ne == 0:
                st[S_REJ] += 1
                continue
            # q0: the first of the smallest D_C (the head of a stable sort of ext by D_C)
            b0 = 0
            for a in range(1, ne):
                if ext_k[a] < ext_k[b0]:
                    b0 = a
            q0 = ext_i[b0]
            d0 = math.hypot(sx - X[q0, 0], sy - X[q0, 1])
            if d0 < 1e-9:
                if from_png:
                    st[S_PNG_WASTED] += 1
                    if ic[I_PNGREPAIR] != 0:
                        st[S_PNG_HIT] = 1  # a node sits on the PGNode: drawing it again would be wasted
                continue
            if d0 > step:
                nx = X[q0, 0] + (sx - X[q0, 0]) * step / d0
                ny = X[q0, 1] + (sy - X[q0, 1]) * step / d0
            else:
                nx = sx
                ny = sy
            # ---- lines 12-17: extendable nodes in order of the cost through them. Only those within
            # a step of q_new take part, in D_C order: a stable sort of that subset (kn_d holds its
            # keys) gives the order that sorting all of ext would give it.
            ns = 0
            for a in range(ne):
                i = ext_i[a]
                if _within(nx - X[i, 0], ny - X[i, 1], step * (1.0 + 1e-9)):
                    rw_i[ns] = i
                    kn_d[ns] = ext_k[a]
                    ns += 1
            _sort_by(kn_d, rw_i, ns)
            for a in range(ns):
                i = rw_i[a]
                near_i[a] = i
                if lower_bounds:
                    # a lower bound of the key; _first_valid_parent makes exact only the keys that
                    # may be the minimum (an eq. (12) edge costs an exp and a field look-up)
                    ex = nx - X[i, 0]
                    ey = ny - X[i, 1]
                    near_c[a] = cost[i] + lbf * math.sqrt(ex * ex + ey * ey) * (1.0 - lb_margin)
                    near_x[a] = False
                else:
                    near_c[a], near_x[a] = _parent_key(i, nx, ny, X, cost, fc, ic, fvx, fvy)
            p, pc = _first_valid_parent(near_i, near_c, near_x, ns, nx, ny, occ, fc, ic, fvx, fvy, st, X, cost, head,
                                        max_turn, dd, True, lower_bounds)
            if p < 0:
                continue
            if not math.isinf(dd[p]):
                dd[p] *= fc[C_DDGROW]  # a successful extension grows a bounded domain (adaptive form)
            new = _add_node(nx, ny, p, pc, X, parent, cost, head, dd, first_child, next_sib, fc, ic,
                            bucket_head, node_next, st, nv, fvx, fvy)
            if from_png and ic[I_PNGREPAIR] != 0 and nx == sx and ny == sy:
                st[S_PNG_HIT] = 1
            hx = math.cos(head[new])
            hy = math.sin(head[new])
            # ---- lines 18-21: rewire the other extendable nodes (within a step of q_new) through it
            for a in range(ns):
                j = rw_i[a]
                if j == p or j == new:
                    continue
                if _rewire_cannot_pay(j, new, nx, ny, X, cost, lbf, lb_margin):
                    continue
                _rewire(j, new, nx, ny, occ, fvx, fvy, fc, ic, st, X, parent, cost, head, first_child, next_sib,
                        stack, max_turn, hx, hy, fb)
        else:
            # ---- RRT* (Karaman & Frazzoli 2011), radius version
            m = _knn(sx, sy, 1, X, fc, ic, bucket_head, node_next, kn_i, kn_d)
            q0 = kn_i[0]
            d0 = kn_d[0]
            if d0 < 1e-9:
                continue
            if d0 > step:
                nx = X[q0, 0] + (sx - X[q0, 0]) * step / d0
                ny = X[q0, 1] + (sy - X[q0, 1]) * step / d0
            else:
                nx = sx
                ny = sy
            radius = step
            if n > 1:
                radius = min(step, fc[C_RGAMMA] * math.sqrt(math.log(n) / n))
            nbx_new, nby_new = _bucket(nx, ny, fc, ic)
            nn, pos_new = _near_pos(nx, ny, radius, X, fc, ic, bucket_head, node_next, near_i,
                                    nby_new * ic[I_NBX] + nbx_new)
            for a in range(nn):
                rw_i[a] = near_i[a]
            # choose-parent over the near ball and the nearest node, in ascending cost order; the
            # nearest is not required to be valid itself (with the fan limit it often is not)
            nc = 0
            has_q0 = False
            for a in range(nn):
                j = near_i[a]
                if j == q0:
                    has_q0 = True
                near_i[nc] = j
                ex = nx - X[j, 0]
                ey = ny - X[j, 1]
                if not use_field:  # _parent_key's length case, written out: a call per near node is costly
                    near_c[nc] = cost[j] + math.sqrt(ex * ex + ey * ey)
                    near_x[nc] = False
                elif lower_bounds:  # see DDRRT*'s choose-parent above
                    near_c[nc] = cost[j] + lbf * math.sqrt(ex * ex + ey * ey) * (1.0 - lb_margin)
                    near_x[nc] = False
                else:
                    near_c[nc], near_x[nc] = _parent_key(j, nx, ny, X, cost, fc, ic, fvx, fvy)
                nc += 1
            if not has_q0 and nc < NEAR_CAP:
                near_i[nc] = q0
                near_c[nc], near_x[nc] = _parent_key(q0, nx, ny, X, cost, fc, ic, fvx, fvy)
                nc += 1
            p, pc = _first_valid_parent(near_i, near_c, near_x, nc, nx, ny, occ, fc, ic, fvx, fvy, st, X, cost, head,
                                        max_turn, dd, False, lower_bounds)
            if p < 0:
                continue
            new = _add_node(nx, ny, p, pc, X, parent, cost, head, dd, first_child, next_sib, fc, ic,
                            bucket_head, node_next, st, nv, fvx, fvy)
            hx = math.cos(head[new])
            hy = math.sin(head[new])
            # rewire: the near set as a second scan would give it: the same nodes in the same order
            # with q_new (skipped) first in its bucket; when that scan is cut at NEAR_CAP and q_new
            # comes before the cut, it pushes the last node out
            if nn == NEAR_CAP and pos_new < NEAR_CAP:
                nn -= 1
            for a in range(nn):
                j = rw_i[a]
                if j == p or j == new:
                    continue
                if _rewire_cannot_pay(j, new, nx, ny, X, cost, lbf, lb_margin):
                    continue
                _rewire(j, new, nx, ny, occ, fvx, fvy, fc, ic, st, X, parent, cost, head, first_child, next_sib,
                        stack, max_turn, hx, hy, fb)
        _try_goal(new, occ, X, parent, cost, head, dd, first_child, next_sib, fc, ic, bucket_head, node_next,
                  st, fs, fvx, fvy, stack, clockbuf, nv)
        if stop_on_exact and st[S_GOAL] >= 0:
            return DONE_EXACT
    return DONE_ITERATIONS
