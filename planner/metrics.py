"""The path indicators of Table 3 for any polyline.

* cost: eq. (12) summed (``cost.path_cost``); length in metres;
* sum_cos, sum_sin: sums of cos(alpha_y) and sin(alpha_y) over the legs, alpha_y taken at each
  leg's midpoint (legs where the current is zero are skipped);
* sum_cos_wp, sum_sin_wp (:func:`waypoint_alpha_sums`): the same sums "at waypoints", as section
  4.2 defines them: alpha_y between the current at each waypoint of the planned path and the
  direction of the leg leaving it (the paper's count; the sums above depend on the 2 m spacing);
* cf: eq. (14), the product over waypoints of p_c = P(n/2, c_q^2 / 2), the regularised lower
  incomplete gamma function with n = 2 (planar position), c_q = clearance / sigma where the
  clearance is the distance from the waypoint's cell centre to the nearest obstacle cell centre
  (``OccupancyGrid.clearance``) and sigma the position error (default 0.5 m, the GPS per-axis
  error of the sensor configuration);
* turns: interior vertices whose heading change exceeds ``turn_threshold`` (default 10 deg);
* total_curvature = sum |dtheta_i| over vertices (rad) and bending_energy = sum kappa_i^2 ds_i
  with kappa_i = dtheta_i / ds_i, ds_i = half the sum of the two adjacent legs (1/m). Computed on
  the polyline given: pass the densely sampled Dubins-smoothed path for Table-3-like figures.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.special import gammainc

from planner.cost import path_cost, path_length
from planner.field import DisturbanceField
from planner.gridmap import OccupancyGrid
from planner.params import PlannerParams

DEFAULT_TURN_THRESHOLD = math.radians(10.0)


def collision_free_probability(clearances: np.ndarray, sigma: float, n: int = 2) -> float:
    """Eq. (14): prod P(n/2, (clearance / sigma)^2 / 2)."""
    c = np.asarray(clearances, dtype=np.float64) / sigma
    return float(np.prod(gammainc(n / 2.0, 0.5 * c * c)))


def waypoint_alpha_sums(points: npt.ArrayLike, directions: npt.ArrayLike,
                        field: DisturbanceField | None) -> tuple[float, float]:
    """Σcos alpha_y and Σsin alpha_y at waypoints: alpha_y between the current at each point
    ((N, 2) map-frame metres) and the direction ((N, 2), any length) the vessel leaves it in.
    Points where the current or the direction is zero are skipped; (0, 0) without a field."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 2)
    if field is None or len(p) == 0:
        return 0.0, 0.0
    vx, vy = field(p[:, 0], p[:, 1])
    vx = np.broadcast_to(np.asarray(vx, dtype=np.float64), (len(p),))
    vy = np.broadcast_to(np.asarray(vy, dtype=np.float64), (len(p),))
    nv = np.hypot(vx, vy)
    nd = np.hypot(d[:, 0], d[:, 1])
    ok = (nv > 1e-9) & (nd > 1e-12)
    c = np.clip((d[ok, 0] * vx[ok] + d[ok, 1] * vy[ok]) / (nd[ok] * nv[ok]), -1.0, 1.0)
    return float(np.sum(c)), float(np.sum(np.sqrt(1.0 - c * c)))


def path_metrics(path: npt.ArrayLike, field: DisturbanceField | None, grid: OccupancyGrid | None,
                 params: PlannerParams, clearance_sigma: float = 0.5,
                 turn_threshold: float = DEFAULT_TURN_THRESHOLD) -> dict[str, float]:
    """Table 3 indicators of ``path`` ((N, 2) map-frame metres); see the module docstring."""
    p = np.asarray(path, dtype=np.float64)
    out = {"waypoints": int(len(p)), "length": path_length(p), "cost": path_cost(p, field, params)}
    if len(p) < 2:
        out.update(sum_cos=0.0, sum_sin=0.0, cf=1.0, turns=0, total_curvature=0.0, bending_energy=0.0)
        return out
    d = np.diff(p, axis=0)
    legs = np.hypot(d[:, 0], d[:, 1])
    sum_cos = sum_sin = 0.0
    if field is not None:
        mid = 0.5 * (p[1:] + p[:-1])
        vx, vy = field(mid[:, 0], mid[:, 1])
        vx = np.broadcast_to(np.asarray(vx, dtype=np.float64), legs.shape)
        vy = np.broadcast_to(np.asarray(vy, dtype=np.float64), legs.shape)
        nv = np.hypot(vx, vy)
        ok = (nv > 1e-9) & (legs > 0)
        c = np.clip((d[ok, 0] * vx[ok] + d[ok, 1] * vy[ok]) / (legs[ok] * nv[ok]), -1.0, 1.0)
        sum_cos = float(np.sum(c))
        sum_sin = float(np.sum(np.sqrt(1.0 - c * c)))
    out["sum_cos"] = sum_cos
    out["sum_sin"] = sum_sin
    if grid is not None:
        clear = np.array([grid.clearance_at(x, y) for x, y in p])
        out["cf"] = collision_free_probability(clear, clearance_sigma)
        out["min_clearance"] = float(clear.min())
    else:
        out["cf"] = 1.0
    keep = legs > 1e-12
    headings = np.arctan2(d[keep, 1], d[keep, 0])
    lk = legs[keep]
    if len(headings) >= 2:
        dth = np.abs((np.diff(headings) + math.pi) % (2.0 * math.pi) - math.pi)
        ds = 0.5 * (lk[1:] + lk[:-1])
        out["turns"] = int(np.sum(dth > turn_threshold))
        out["total_curvature"] = float(np.sum(dth))
        out["bending_energy"] = float(np.sum(dth * dth / ds))
    else:
        out.update(turns=0, total_curvature=0.0, bending_energy=0.0)
    out["clearance_sigma"] = clearance_sigma
    return out
