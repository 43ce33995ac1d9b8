"""One gated EKF step of :mod:`autopilot_bridge.navigation` compiled with numba (``navigation.filter = "fast"``).

The same equations as the filterpy path, on the 7-state model ``[x, y, psi, u, v, r, b_g]``:
predict eq. (2) with constant body velocities to the measurement's time, the NIS gate, the gain
``K = P H^T S^-1`` and the Joseph-form covariance update filterpy uses. One call does the
predict and the update of one measurement, or of two at one time (the compass and the gyro of the
usual frame): CPython's per-operation cost on 7x7 arrays (~1 us a numpy call, dozens per update),
and then the calls themselves, were the filter's cost, not the arithmetic.

Outcome codes tell the caller what happened, so that it counts and rolls back exactly as the
filterpy path does: a non-finite prediction keeps the previous estimate; a singular or non-finite
innovation, or an update that would leave a NaN/inf, keeps the predicted one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

OK, REJECTED, NUMERIC_PREDICT, NUMERIC_UPDATE = 0, 1, 2, 3
NONE = -1   # no (second) measurement
# Measurement kinds (the models of NavigationFilter).
GPS_POS, GPS_VEL, COMPASS, GYRO, DVL = 0, 1, 2, 3, 4
_X, _Y, _PSI, _U, _V, _R, _BG = 0, 1, 2, 3, 4, 5, 6
_N = 7


@njit(cache=True, error_model="numpy")
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, error_model="numpy")
def _all_finite(a: np.ndarray) -> bool:
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


@njit(cache=True, error_model="numpy")
def predict(x: np.ndarray, P: np.ndarray, dt: float, q_a: float, q_r: float, q_b: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """(x, P) propagated by ``dt`` s > 0: eq. (2), F P F^T + Q (white acceleration integrated over dt)."""
    psi, u, v = x[_PSI, 0], x[_U, 0], x[_V, 0]
    c, s = math.cos(psi), math.sin(psi)
    F = np.eye(_N)
    F[_X, _PSI] = (-u * s - v * c) * dt
    F[_X, _U] = c * dt
    F[_X, _V] = -s * dt
    F[_Y, _PSI] = (u * c - v * s) * dt
    F[_Y, _U] = s * dt
    F[_Y, _V] = c * dt
    F[_PSI, _R] = dt
    Q = np.zeros((_N, _N))
    Q[_U, _U] = q_a * dt
    Q[_V, _V] = q_a * dt
    Q[_X, _X] = q_a * dt**3 / 3.0
    Q[_Y, _Y] = q_a * dt**3 / 3.0
    Q[_R, _R] = q_r * dt
    Q[_PSI, _PSI] = q_r * dt**3 / 3.0
    Q[_BG, _BG] = q_b * dt
    xn = x.copy()
    xn[_X, 0] += (u * c - v * s) * dt
    xn[_Y, 0] += (u * s + v * c) * dt
    xn[_PSI, 0] = _wrap(x[_PSI, 0] + x[_R, 0] * dt)
    Pn = F @ P @ F.T + Q
    return xn, Pn


@njit(cache=True, error_model="numpy")
def _model(x: np.ndarray, kind: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(H, h(x), index of an angle row or -1) of a measurement kind."""
    if kind == GPS_POS or kind == GPS_VEL or kind == DVL:
        H = np.zeros((2, _N))
        hx = np.zeros((2, 1))
    else:
        H = np.zeros((1, _N))
        hx = np.zeros((1, 1))
    angle = -1
    if kind == GPS_POS:
        H[0, _X] = 1.0
        H[1, _Y] = 1.0
        hx[0, 0], hx[1, 0] = x[_X, 0], x[_Y, 0]
    elif kind == GPS_VEL:
        psi, u, v = x[_PSI, 0], x[_U, 0], x[_V, 0]
        c, s = math.cos(psi), math.sin(psi)
        H[0, _PSI], H[0, _U], H[0, _V] = -u * s - v * c, c, -s
        H[1, _PSI], H[1, _U], H[1, _V] = u * c - v * s, s, c
        hx[0, 0], hx[1, 0] = u * c - v * s, u * s + v * c
    elif kind == COMPASS:
        H[0, _PSI] = 1.0
        hx[0, 0] = x[_PSI, 0]
        angle = 0
    elif kind == GYRO:
        H[0, _R] = 1.0
        H[0, _BG] = 1.0
        hx[0, 0] = x[_R, 0] + x[_BG, 0]
    else:  # DVL
        H[0, _U] = 1.0
        H[1, _V] = 1.0
        hx[0, 0], hx[1, 0] = x[_U, 0], x[_V, 0]
    return H, hx, angle


@njit(cache=True, error_model="numpy")
def _update(xp: np.ndarray, Pp: np.ndarray, kind: int, z: np.ndarray, Rm: np.ndarray, gate: float
            ) -> tuple[int, np.ndarray, np.ndarray]:
    """The gated update of the prediction (xp, Pp) by measurement ``z`` (m x 1) of ``kind`` with
    noise covariance ``Rm`` (m x m): (code, x, P), the prediction itself unless the code is OK."""
    H, hx, angle = _model(xp, kind)
    y = z - hx
    if angle >= 0:
        y[angle, 0] = _wrap(y[angle, 0])
    PHT = Pp @ H.T
    S = H @ PHT + Rm
    m = S.shape[0]
    Sinv = np.empty((m, m))
    if m == 1:
        Sinv[0, 0] = 1.0 / S[0, 0]
        nis = y[0, 0] * y[0, 0] / S[0, 0]
    else:
        a, b, c, d = S[0, 0], S[0, 1], S[1, 0], S[1, 1]
        scale = max(abs(a), abs(b), abs(c), abs(d))
        if not (0.0 < scale < math.inf):
            return NUMERIC_UPDATE, xp, Pp
        a, b, c, d = a / scale, b / scale, c / scale, d / scale
        det = (a * d - b * c) * scale
        if det == 0.0 or not math.isfinite(det):
            return NUMERIC_UPDATE, xp, Pp
        Sinv[0, 0], Sinv[0, 1], Sinv[1, 0], Sinv[1, 1] = d / det, -b / det, -c / det, a / det
        nis = (y.T @ Sinv @ y)[0, 0]
    if not math.isfinite(nis):
        return NUMERIC_UPDATE, xp, Pp
    if nis > gate:
        return REJECTED, xp, Pp
    K = PHT @ Sinv
    xn = xp + K @ y
    xn[_PSI, 0] = _wrap(xn[_PSI, 0])
    I_KH = np.eye(_N) - K @ H
    Pn = I_KH @ Pp @ I_KH.T + K @ Rm @ K.T
    if not (_all_finite(xn) and _all_finite(Pn)):
        return NUMERIC_UPDATE, xp, Pp
    return OK, xn, Pn


@njit(cache=True, error_model="numpy")
def step(x: np.ndarray, P: np.ndarray, dt: float, q_a: float, q_r: float, q_b: float,
         kind: int, z: np.ndarray, Rm: np.ndarray, gate: float,
         kind2: int, z2: np.ndarray, Rm2: np.ndarray, gate2: float) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Predict by ``dt`` s (none when 0), then the gated update by measurement ``z`` (m x 1) of
    ``kind`` with noise covariance ``Rm`` (m x m); then, unless ``kind2`` is :data:`NONE`, the same
    for a second measurement at the same time (``z2``, ``Rm2``, ``gate2``), as a second call would:
    no predict if the first one's was taken, by ``dt`` again if it was refused.

    Returns (code, code2, x, P): the estimate after them (the one given where every prediction was
    refused, a prediction where an update was refused), ``code2`` NONE without a second measurement.
    One entry point on purpose: a second compiled function calling the same code would compile it
    again, and a cold numba cache takes ~5 s for it."""
    codes = [NONE, NONE]
    for i in range(1 if kind2 == NONE else 2):
        k, zi, Ri, gi = (kind, z, Rm, gate) if i == 0 else (kind2, z2, Rm2, gate2)
        if dt > 0.0:
            xp, Pp = predict(x, P, dt, q_a, q_r, q_b)
            if not (_all_finite(xp) and _all_finite(Pp)):
                codes[i] = NUMERIC_PREDICT
                continue
            dt = 0.0   # the estimate is at the measurements' time now
        else:
            xp, Pp = x, P
        codes[i], x, P = _update(xp, Pp, k, zi, Ri, gi)
    return codes[0], codes[1], x, P
