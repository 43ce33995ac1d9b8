"""Section 3.4: the sampling domain ESD of eq. (11) and the cost distance D_C of eq. (12).

alpha_y is the encounter angle between the direction of motion and the current. Where the
current is zero alpha_y is undefined: the cost is then the Euclidean distance and the ESD's
second term is D_alpha * DR. With no field (or objective "length") every cost is Euclidean.

A segment's cost is eq. (12) summed over pieces of at most ``params.step`` metres, alpha_y taken
at each piece's midpoint (tree edges are at most one step long, so they are one piece).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeGuard

import numpy as np
import numpy.typing as npt

from planner.field import DisturbanceField, GridField

if TYPE_CHECKING:
    from planner.params import PlannerParams

ZERO_CURRENT = 1e-9  # m/s; below this the current has no direction


def _sigmoid_term(alpha_y: float, gamma_alpha: float) -> float:
    return math.cos(alpha_y) - gamma_alpha * math.sin(alpha_y)


def esd(dd: float, alpha_y: float, dr: float, d_alpha: float = 1.0, gamma_alpha: float = 0.1) -> float:
    """Eq. (11): min{DD, D_alpha DR / (1 + exp(-(cos a - gamma sin a)))} (NaN alpha = no current)."""
    if math.isnan(alpha_y):
        return min(dd, d_alpha * dr)
    return min(dd, d_alpha * dr / (1.0 + math.exp(-_sigmoid_term(alpha_y, gamma_alpha))))


def cost_distance(ed: float, alpha_y: float, d_alpha: float = 1.0, gamma_alpha: float = 0.1) -> float:
    """Eq. (12): min{Ed, D_alpha Ed / (1 + exp(cos a - gamma sin a))} (NaN alpha = no current)."""
    if math.isnan(alpha_y):
        return ed
    return min(ed, d_alpha * ed / (1.0 + math.exp(_sigmoid_term(alpha_y, gamma_alpha))))


def min_cost_factor(d_alpha: float = 1.0, gamma_alpha: float = 0.1) -> float:
    """Largest f with D_C >= f * Ed for every alpha_y: cos a - gamma sin a is at most 1 on
    [0, pi] (at a = 0), so f = min(1, D_alpha / (1 + e)). Used by the informed ellipse."""
    del gamma_alpha  # the maximum of cos a - gamma sin a on [0, pi] is 1 for any gamma >= 0
    return min(1.0, d_alpha / (1.0 + math.e))


def _uses_current(field: DisturbanceField | None, params: PlannerParams) -> TypeGuard[DisturbanceField]:
    return field is not None and params.objective == "current"


def _pieces(p: npt.ArrayLike, q: npt.ArrayLike, step: float) -> tuple[np.ndarray, np.ndarray, float, int]:
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    d = q - p
    length = float(math.hypot(d[0], d[1]))
    n = max(1, int(math.ceil(length / step - 1e-12)))
    return p, d, length, n


def segment_cost(p: npt.ArrayLike, q: npt.ArrayLike, field: DisturbanceField | None, params: PlannerParams) -> float:
    """Eq. (12) along the straight segment p -> q (Euclidean length with no field)."""
    p, d, length, n = _pieces(p, q, params.step)
    if not _uses_current(field, params) or length == 0.0:
        return length
    vx: list[float] | np.ndarray   # the current (m/s) at each piece's midpoint, map frame
    vy: list[float] | np.ndarray
    if isinstance(field, GridField):  # one point at a time in Python floats: same values, faster
        vx, vy = [], []
        for i in range(n):
            ti = (i + 0.5) / n
            ax, ay = field.at(float(p[0] + ti * d[0]), float(p[1] + ti * d[1]))
            vx.append(ax)
            vy.append(ay)
    else:
        t = (np.arange(n) + 0.5) / n
        mx = p[0] + t * d[0]
        my = p[1] + t * d[1]
        vx, vy = field(mx, my)
        vx = np.broadcast_to(np.asarray(vx, dtype=np.float64), mx.shape)
        vy = np.broadcast_to(np.asarray(vy, dtype=np.float64), mx.shape)
    piece = length / n
    total = 0.0
    for i in range(n):
        nv = math.hypot(vx[i], vy[i])
        if nv < ZERO_CURRENT:
            total += piece
            continue
        c = (d[0] * vx[i] + d[1] * vy[i]) / (length * nv)
        a = math.acos(max(-1.0, min(1.0, c)))
        total += cost_distance(piece, a, params.d_alpha, params.gamma_alpha)
    return total


def path_cost(path: np.ndarray, field: DisturbanceField | None, params: PlannerParams) -> float:
    """Sum of :func:`segment_cost` over consecutive waypoints."""
    path = np.asarray(path, dtype=np.float64)
    if len(path) < 2:
        return 0.0
    if not _uses_current(field, params):
        return float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
    return _sum_of_segments(path, lambda p, q: segment_cost(p, q, field, params))


def _sum_of_segments(path: np.ndarray, segment: Callable[[np.ndarray, np.ndarray], float]) -> float:
    """``segment(p, q)`` summed over consecutive waypoints, left to right (path has >= 2 points)."""
    return float(sum(segment(path[i], path[i + 1]) for i in range(len(path) - 1)))


def path_cost_fn(field: DisturbanceField | None, params: PlannerParams) -> Callable[[np.ndarray], float]:
    """``lambda p: path_cost(p, field, params)`` that computes each segment's cost once: pruning
    asks for the cost of a sub-path again each time it grows by a waypoint. The same terms summed in
    the same order, so the same floats."""
    if not _uses_current(field, params):
        return lambda path: path_cost(path, field, params)
    seen: dict[tuple[float, float, float, float], float] = {}

    def segment(p: np.ndarray, q: np.ndarray) -> float:
        key = (float(p[0]), float(p[1]), float(q[0]), float(q[1]))
        c = seen.get(key)
        if c is None:
            c = seen[key] = segment_cost(p, q, field, params)
        return c

    def cost(path: np.ndarray) -> float:
        path = np.asarray(path, dtype=np.float64)
        return 0.0 if len(path) < 2 else _sum_of_segments(path, segment)
    return cost


def path_length(path: np.ndarray) -> float:
    """Euclidean length (m) of an (N, 2) polyline; 0 for fewer than two points. The one polyline
    length of the project (the vessel computer uses it too)."""
    path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if len(path) < 2:
        return 0.0
    return float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
