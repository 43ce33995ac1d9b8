"""Section 2.4: sequential redundant-waypoint pruning, Dubins smoothing, constraint re-check.

Dubins paths (shortest curves with bounded curvature between two poses) are computed in closed
form for the six words LSL, RSR, LSR, RSL, RLR, LRL on the pose normalised by the turning radius
(Dubins 1957; the formulas as tabulated by Shkel and Lumelsky 2001).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.gridmap import OccupancyGrid

TWO_PI = 2.0 * math.pi
WORDS = ("LSL", "RSR", "LSR", "RSL", "RLR", "LRL")


def _mod2pi(a: float) -> float:
    return a % TWO_PI


# ---------------------------------------------------------------------------------------------
# pruning
def prune(path: np.ndarray, grid: OccupancyGrid, cost_fn: Callable[[np.ndarray], float]) -> np.ndarray:
    """Sequential redundant-waypoint pruning exactly as in section 2.4.

    Put x_j in S_p; for i = j+2, j+3, ...: while the straight segment x_j x_i is collision free
    and costs no more than the original sub-path x_j..x_i, try the next i; otherwise set
    j = i - 1, put x_j in S_p and start again. When i passes the end, x_N joins S_p.
    ``cost_fn`` is the cost of a polyline (e.g. ``lambda p: path_cost(p, field, params)``).
    Never increases the cost of the path and never makes it collide.
    """
    p = np.asarray(path, dtype=np.float64)
    n = len(p)
    if n <= 2:
        return p.copy()
    out = [p[0]]
    j = 0
    i = j + 2
    while i < n:
        direct = np.stack([p[j], p[i]])
        if grid.segment_free(*p[j], *p[i]) and cost_fn(direct) <= cost_fn(p[j:i + 1]) + 1e-12:
            i += 1
        else:
            j = i - 1
            out.append(p[j])
            i = j + 2
    out.append(p[-1])
    return np.asarray(out)


# ---------------------------------------------------------------------------------------------
# Dubins curves
@dataclass(frozen=True)
class DubinsPath:
    """A Dubins path from pose q0 = (x, y, theta) with turning radius ``radius``: ``word`` names
    the three segments, ``segments`` their lengths in units of the radius."""

    q0: tuple[float, float, float]
    radius: float
    word: str
    segments: tuple[float, float, float]

    @property
    def length(self) -> float:
        return self.radius * sum(self.segments)

    def end(self) -> tuple[float, float, float]:
        x, y, th = self.q0
        for kind, s in zip(self.word, self.segments, strict=False):
            x, y, th = _advance(x, y, th, kind, s * self.radius, self.radius)
        return x, y, th

    def sample(self, step: float) -> np.ndarray:
        """Poses (x, y, theta) every ``step`` metres of arc length, both ends included (N, 3)."""
        total = self.length
        n = max(1, int(math.ceil(total / step)))
        out = np.empty((n + 1, 3))
        for k in range(n + 1):
            out[k] = self._at(total * k / n)
        return out

    def _at(self, s: float) -> tuple[float, float, float]:
        x, y, th = self.q0
        for kind, seg in zip(self.word, self.segments, strict=False):
            L = seg * self.radius
            use = min(s, L)
            x, y, th = _advance(x, y, th, kind, use, self.radius)
            s -= use
            if s <= 0.0:
                break
        return x, y, th


def _advance(x: float, y: float, th: float, kind: str, s: float, r: float) -> tuple[float, float, float]:
    if kind == "S":
        return x + s * math.cos(th), y + s * math.sin(th), th
    if kind == "L":
        th1 = th + s / r
        return x + r * (math.sin(th1) - math.sin(th)), y - r * (math.cos(th1) - math.cos(th)), th1
    th1 = th - s / r
    return x - r * (math.sin(th1) - math.sin(th)), y + r * (math.cos(th1) - math.cos(th)), th1


def _word_segments(word: str, a: float, b: float, d: float) -> tuple[float, float, float] | None:
    """Normalised (t, p, q) of one word, or None when the word does not exist for this pose."""
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    if word == "LSL":
        p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
        if p2 < 0:
            return None
        tmp = math.atan2(cb - ca, d + sa - sb)
        return _mod2pi(-a + tmp), math.sqrt(p2), _mod2pi(b - tmp)
    if word == "RSR":
        p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
        if p2 < 0:
            return None
        tmp = math.atan2(ca - cb, d - sa + sb)
        return _mod2pi(a - tmp), math.sqrt(p2), _mod2pi(-b + tmp)
    if word == "LSR":
        p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
        if p2 < 0:
            return None
        p = math.sqrt(p2)
        tmp = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        return _mod2pi(-a + tmp), p, _mod2pi(-_mod2pi(b) + tmp)
    if word == "RSL":
        p2 = -2 + d * d + 2 * cab - 2 * d * (sa + sb)
        if p2 < 0:
            return None
        p = math.sqrt(p2)
        tmp = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        return _mod2pi(a - tmp), p, _mod2pi(b - tmp)
    if word == "RLR":
        c = (6.0 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8.0
        if abs(c) > 1:
            return None
        p = _mod2pi(TWO_PI - math.acos(c))
        t = _mod2pi(a - math.atan2(ca - cb, d - sa + sb) + p / 2.0)
        return t, p, _mod2pi(a - b - t + p)
    if word == "LRL":
        c = (6.0 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8.0
        if abs(c) > 1:
            return None
        p = _mod2pi(TWO_PI - math.acos(c))
        t = _mod2pi(-a - math.atan2(ca - cb, d + sa - sb) + p / 2.0)
        return t, p, _mod2pi(_mod2pi(b) - a - t + p)
    raise ValueError(f"unknown Dubins word {word!r}")


def dubins_path(q0: tuple[float, float, float], q1: tuple[float, float, float], radius: float,
                word: str | None = None) -> DubinsPath:
    """The shortest Dubins path from pose q0 to q1 (x, y, theta; metres, rad) with turning radius
    ``radius`` (> 0), or the path of the given ``word``. ValueError if ``word`` is impossible."""
    if not radius > 0:
        raise ValueError("dubins_path: radius must be > 0")
    x0, y0, t0 = map(float, q0)
    x1, y1, t1 = map(float, q1)
    dx, dy = x1 - x0, y1 - y0
    d = math.hypot(dx, dy) / radius
    th = math.atan2(dy, dx) if d > 0 else 0.0
    a = _mod2pi(t0 - th)
    b = _mod2pi(t1 - th)
    best = None
    for w in (WORDS if word is None else (word,)):
        seg = _word_segments(w, a, b, d)
        if seg is None:
            continue
        if best is None or sum(seg) < sum(best[1]) - 1e-12:
            best = (w, seg)
    if best is None:
        raise ValueError(f"no Dubins path of word {word!r} between these poses")
    s1, s2, s3 = best[1]
    return DubinsPath((x0, y0, t0), float(radius), best[0], (float(s1), float(s2), float(s3)))


# ---------------------------------------------------------------------------------------------
# smoothing
def waypoint_headings(path: np.ndarray, start_heading: float | None = None) -> np.ndarray:
    """Heading at each waypoint: the given start heading (else the first leg's direction), the
    bisector of the two legs at interior waypoints, the last leg's direction at the end."""
    p = np.asarray(path, dtype=np.float64)
    legs = np.arctan2(np.diff(p[:, 1]), np.diff(p[:, 0]))
    h = np.empty(len(p))
    h[0] = legs[0] if start_heading is None else start_heading
    for i in range(1, len(p) - 1):
        h[i] = math.atan2(math.sin(legs[i - 1]) + math.sin(legs[i]), math.cos(legs[i - 1]) + math.cos(legs[i]))
    h[-1] = legs[-1]
    return h


def smooth_pieces(path: np.ndarray, radius: float, start_heading: float | None = None) -> list[DubinsPath]:
    """One Dubins path per leg of the polyline, poses from :func:`waypoint_headings`."""
    p = np.asarray(path, dtype=np.float64)
    h = waypoint_headings(p, start_heading)
    return [dubins_path((*p[i], h[i]), (*p[i + 1], h[i + 1]), radius) for i in range(len(p) - 1)]


def smooth(path: np.ndarray, radius: float, start_heading: float | None = None, step: float = 0.25) -> np.ndarray:
    """Dense (N, 2) polyline of the Dubins-smoothed path (turning radius ``radius`` metres,
    samples every ``step`` metres). radius <= 0 returns the polyline resampled."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 2:
        return p.copy()
    if radius <= 0:
        return _densify(p, step)
    pts = [p[:1]]
    for piece in smooth_pieces(p, radius, start_heading):
        pts.append(piece.sample(step)[1:, :2])
    return np.vstack(pts)


def _densify(p: np.ndarray, step: float) -> np.ndarray:
    out = [p[:1]]
    for i in range(len(p) - 1):
        n = max(1, int(math.ceil(math.hypot(*(p[i + 1] - p[i])) / step)))
        t = (np.arange(1, n + 1) / n)[:, None]
        out.append(p[i] + t * (p[i + 1] - p[i]))
    return np.vstack(out)


@dataclass
class SmoothResult:
    dense: np.ndarray        # (N, 2) smoothed path
    waypoints: np.ndarray    # the polyline it was built from (after any replanning)
    ok: bool                 # every constraint holds
    replanned: int           # legs that had to be replanned
    reason: str


def _leg_ok(grid: OccupancyGrid, piece: DubinsPath, radius: float, step: float) -> tuple[bool, np.ndarray]:
    poses = piece.sample(step)
    seg_len = piece.length / max(1, len(poses) - 1)
    dth = np.abs((np.diff(poses[:, 2]) + math.pi) % TWO_PI - math.pi)
    curv_ok = bool(np.all(dth <= seg_len / radius + 1e-6))
    return curv_ok and grid.polyline_free(poses[:, :2]), poses


def _try_headings(wp: np.ndarray, heads: np.ndarray, i: int, grid: OccupancyGrid, radius: float, step: float,
                  fixed_start: bool) -> bool:
    """Leg i violates: try the incoming/outgoing leg directions instead of the bisector at its
    end waypoint, then at its start waypoint; keep the first choice that clears the adjacent legs."""
    legs = np.arctan2(np.diff(wp[:, 1]), np.diff(wp[:, 0]))
    for w in (i + 1, i):
        if w == 0 and fixed_start:
            continue
        if w == len(wp) - 1:
            continue
        options = [legs[w]] + ([legs[w - 1]] if w > 0 else [])
        old = heads[w]
        for h in options:
            heads[w] = h
            ok = True
            for leg in (w - 1, w):
                if 0 <= leg < len(wp) - 1:
                    piece = dubins_path((*wp[leg], heads[leg]), (*wp[leg + 1], heads[leg + 1]), radius)
                    if not _leg_ok(grid, piece, radius, step)[0]:
                        ok = False
                        break
            if ok:
                return True
        heads[w] = old
    return False


def check_and_replan(waypoints: np.ndarray, grid: OccupancyGrid, radius: float,
                     start_heading: float | None = None, step: float = 0.25,
                     replan: Callable[[tuple, tuple, float], np.ndarray | None] | None = None,
                     max_rounds: int = 4) -> SmoothResult:
    """Smooth, then re-check each Dubins leg: collision free against ``grid`` (exact traversal
    between samples ``step`` apart) and curvature at most 1 / radius. A violating leg is first
    re-tried with the adjacent leg directions as waypoint headings instead of the bisector; if
    that fails it is replanned: by ``replan(p, q, heading_at_p)`` when given (e.g. a short
    planner run returning a polyline p..q), else by inserting the leg's midpoint so the curve
    hugs the collision-free polyline more tightly. Up to ``max_rounds`` rounds."""
    wp = np.asarray(waypoints, dtype=np.float64).copy()
    replanned = 0
    bad: list[int] = []
    dense = wp.copy()
    checked = wp
    for _ in range(max_rounds + 1):
        if len(wp) < 2:
            return SmoothResult(wp.copy(), wp, grid.path_free(wp), replanned, "trivial path")
        if radius <= 0:
            dense = _densify(wp, step)
            ok = grid.polyline_free(dense)
            return SmoothResult(dense, wp, ok, replanned, "no turning-radius limit" if ok else "polyline collides")
        heads = waypoint_headings(wp, start_heading)
        bad = []
        for i in range(len(wp) - 1):
            piece = dubins_path((*wp[i], heads[i]), (*wp[i + 1], heads[i + 1]), radius)
            if not _leg_ok(grid, piece, radius, step)[0]:
                if not _try_headings(wp, heads, i, grid, radius, step, start_heading is not None):
                    bad.append(i)
        parts = [wp[:1]]
        for i in range(len(wp) - 1):
            piece = dubins_path((*wp[i], heads[i]), (*wp[i + 1], heads[i + 1]), radius)
            parts.append(piece.sample(step)[1:, :2])
        dense = np.vstack(parts)
        checked = wp
        if not bad:
            return SmoothResult(dense, wp, True, replanned, "all legs feasible")
        new = [wp[0]]
        for i in range(len(wp) - 1):
            if i in bad:
                sub = replan(tuple(wp[i]), tuple(wp[i + 1]), float(heads[i])) if replan else None
                if sub is not None and len(sub) >= 2:
                    new.extend(np.asarray(sub, dtype=np.float64)[1:-1])
                else:
                    new.append(0.5 * (wp[i] + wp[i + 1]))
                replanned += 1
            new.append(wp[i + 1])
        wp = np.asarray(new)
    return SmoothResult(dense, checked, False, replanned,
                        f"legs {bad} still violate the constraints after {max_rounds} rounds")
