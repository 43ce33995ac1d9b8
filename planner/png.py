"""Section 3.2: the PGNode of proportional navigation guidance, eqs. (7)-(8).

The vessel at U_{k-1} (heading theta_{k-1}) chases a virtual target at P_{k-1} moving along the
reference path (heading psi_t) by s_t per step; the vessel moves u_t = 2 s_t (twice the target's
speed, section 3.2). With theta' = N q', the new heading is theta_k = theta_{k-1} + N dq. The
line-of-sight increment dq is first estimated with the vessel held still (eq. (7), first line),
then corrected by eq. (8) until it changes by less than ``tol``. The PGNode U_k is the point
u_t along the new heading, on the segment U_{k-1} C (similar triangles).

All angles here are signed (counter-clockwise positive); the magnitudes are the arccos
expressions of eqs. (7)-(8) and the signs come from the geometry. Compiled (numba): DDRRT* computes
the PGNode inside its timed search (``pg_node.py_func`` is the same code in Python).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def _split(x: float) -> tuple[float, float]:
    t = x * 134217729.0  # Veltkamp's split: 2^27 + 1
    hi = t - (t - x)
    return hi, x - hi


@njit(cache=True)
def _exact_square(x: float) -> tuple[float, float]:
    """x * x as hi + lo exactly (Dekker's product)."""
    h, lo = _split(x)
    p = h * h
    q = h * lo + lo * h
    z = p + q
    return z, p - z + q + lo * lo


@njit(cache=True)
def hypot(a: float, b: float) -> float:
    """CPython 3.11's math.hypot, bit for bit (its vector_norm: scaled sum of exact squares, one
    differential correction). Compiled code's math.hypot is numba's own and differs in the last
    bit for about 1 % of arguments; this keeps the PGNode that of the Python code before it was
    compiled (tests/test_planner_issue34.py)."""
    a = abs(a)
    b = abs(b)
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if math.isnan(a) or math.isnan(b):
        return math.nan
    mx = max(a, b)
    if mx == 0.0:
        return mx
    e = math.frexp(mx)[1]
    if e < -1020:  # subnormal scale: never metres; plain formula
        return math.sqrt(a * a + b * b)
    scale = math.ldexp(1.0, -e)
    csum = 1.0
    f1 = 0.0
    f2 = 0.0
    for v in (a, b):
        ph, pl = _exact_square(v * scale)
        s = csum + ph
        f2 += ph - (s - csum)
        f1 += pl
        csum = s
    h = math.sqrt(csum - 1.0 + (f1 + f2))
    ph, pl = _exact_square(h)
    ph = -ph
    pl = -pl
    s = csum + ph
    f2 += ph - (s - csum)
    f1 += pl
    csum = s
    h += (csum - 1.0 + (f1 + f2)) / (2.0 * h)
    return h / scale


@njit(cache=True)
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _acos(x: float) -> float:
    return math.acos(max(-1.0, min(1.0, x)))


@njit(cache=True)
def pg_node(usv_pos: tuple[float, float], usv_heading: float, target_pos: tuple[float, float], target_heading: float,
            s_t: float, nav_ratio: float = 3.0, tol: float = 1e-3, max_iter: int = 20) -> tuple[float, float]:
    """The PGNode (x, y) of eqs. (7)-(8) (map frame, metres; headings in rad)."""
    ux, uy = float(usv_pos[0]), float(usv_pos[1])
    px, py = float(target_pos[0]), float(target_pos[1])
    s_t = float(s_t)
    u_t = 2.0 * s_t
    r = hypot(px - ux, py - uy)                     # r_{k-1}
    if s_t <= 0.0 or r < 1e-12:
        return ux + u_t * math.cos(usv_heading), uy + u_t * math.sin(usv_heading)
    q0 = math.atan2(py - uy, px - ux)                    # sight line angle q_{k-1}
    p1x = px + s_t * math.cos(target_heading)            # P_k
    p1y = py + s_t * math.sin(target_heading)
    c_k = hypot(p1x - ux, p1y - uy)
    # eq. (7) line 1 (cosine theorem), signed by the side the target moves to
    sign = 1.0 if _wrap(math.atan2(p1y - uy, p1x - ux) - q0) >= 0.0 else -1.0
    dq = sign * _acos((c_k * c_k + r * r - s_t * s_t) / (2.0 * c_k * r)) if c_k > 1e-12 else 0.0
    # beta_k: angle at P_{k-1} between P_{k-1}U_{k-1} and the target's motion (eq. (7) line 4)
    beta = _acos((s_t * s_t + r * r - c_k * c_k) / (2.0 * s_t * r))
    for _ in range(int(max_iter)):
        theta = usv_heading + nav_ratio * dq              # eq. (7) line 2
        alpha = _wrap(theta - q0)                        # eq. (7) line 3 (signed)
        a = abs(alpha)
        # the triangle U_{k-1} P_{k-1} C exists only if the vessel's ray meets the target's ray
        det = math.sin(theta - target_heading)
        triangle = abs(det) > 1e-12 and a + beta < math.pi - 1e-12
        if triangle:
            ray_u = (-(px - ux) * math.sin(target_heading) + (py - uy) * math.cos(target_heading)) / det
            ray_p = (math.cos(theta) * (py - uy) - math.sin(theta) * (px - ux)) / det
            triangle = ray_u > 0.0 and ray_p >= 0.0
        uc = sc = c3 = 0.0
        if triangle:
            sab = math.sin(a + beta)
            c1 = r * math.sin(beta) / sab                # |U_{k-1} C|
            c2 = r * math.sin(a) / sab                   # |P_{k-1} C|
            uc = c1 - u_t
            sc = c2 - s_t
            c3 = math.sqrt(max(uc * uc + sc * sc + 2.0 * uc * sc * math.cos(a + beta), 0.0))
        if triangle and uc > 1e-12 and sc >= 0.0 and c3 > 1e-12:
            # eq. (8): the corrected sight-line increment
            phi = _acos((uc * uc + c3 * c3 - sc * sc) / (2.0 * uc * c3))  # angle at U_k, C to P_k
            new_dq = (a - phi) if alpha >= 0.0 else (phi - a)
        else:
            # no triangle (the rays do not meet, or U_k / P_k is already past C): the same
            # sight-line increment measured directly between U_k P_k and U_{k-1} P_{k-1}
            ukx = ux + u_t * math.cos(theta)
            uky = uy + u_t * math.sin(theta)
            new_dq = _wrap(math.atan2(p1y - uky, p1x - ukx) - q0)
        converged = abs(new_dq - dq) < tol
        dq = new_dq
        if converged:
            break
    theta = usv_heading + nav_ratio * dq
    return ux + u_t * math.cos(theta), uy + u_t * math.sin(theta)
