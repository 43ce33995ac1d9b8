"""Navigation fusion: an extended Kalman filter (filterpy) over GPS, gyro, compass and DVL.

State (NED, SI): ``[x, y, psi, u, v, r, b_g]`` — position north/east (m), heading (rad,
clockwise from north), body surge/sway velocity over ground (m/s), yaw rate (rad/s) and the gyro
bias (rad/s).

Why an EKF and not a UKF: the only nonlinearity is the rotation of eq. (2) by the heading, which
is smooth and well linearised over one IMU period (10 ms); the EKF costs one 7x7 update per
measurement (tens of microseconds with filterpy) where the UKF needs 15 sigma points, and the
control loop budget is 2 ms at p99.

Every measurement carries its own time stamp; the filter predicts to that instant with the actual
time step before updating. Each update is gated by its normalised innovation squared (NIS)
against the chi-square quantile of ``gate_probability``: outliers (GPS glitches) are rejected
and counted. Without GPS the filter dead-reckons from gyro and compass with constant body
velocity, and its position covariance grows.

Two interchangeable implementations (``navigation.filter``): ``"filterpy"`` (the prediction below
on numpy, filterpy's ``ExtendedKalmanFilter.update``) and ``"fast"`` (the same equations -
prediction, NIS gate, gain, Joseph-form covariance update - compiled with numba in one call per
measurement, or per pair of them at one time, autopilot_bridge/nav_kernel.py). They agree to
rounding, refusals and counters included (tests/test_navigation_fast.py). ``"fast"`` is the
default: filterpy's path alone costs more per frame than the loop's budget at 3,000 lockstep
steps/s (docs/performance.md).

Numeric faults never escape: a measurement that is not finite, a singular innovation covariance
(``LinAlgError``) or an update or prediction that would leave a NaN/inf in the state or its
covariance is refused, the filter keeps its previous estimate (dead reckoning goes on) and the
refusal is counted in ``stats.rejected`` as ``numeric_<kind>`` (docs/security.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from autopilot_bridge import nav_kernel
from autopilot_bridge.angles import wrap_angle
from common.params import param

if TYPE_CHECKING:
    from filterpy.kalman import ExtendedKalmanFilter

MeasurementModel = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

X, Y, PSI, U, V, R, BG = range(7)
DIM = 7


def chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square quantile (NIS gate) as scipy.stats.chi2.ppf computes it, 2 P^-1(dof / 2, p),
    without importing scipy.stats (~0.6 s of every process start)."""
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2, probability))


def _selector(*rows: tuple[int, ...]) -> np.ndarray:
    H = np.zeros((len(rows), DIM))
    for i, cols in enumerate(rows):
        H[i, list(cols)] = 1.0
    H.flags.writeable = False
    return H


_H_POSITION = _selector((X,), (Y,))
_H_HEADING = _selector((PSI,))
_H_GYRO = _selector((R, BG))
_H_BODY_VELOCITY = _selector((U,), (V,))


@dataclass(frozen=True)
class NavigationParams:
    """Noise model of the navigation filter (the [navigation] TOML section)."""

    accel_noise: float = param("process noise: random-walk acceleration on u and v", "m/s^2", gt=0)
    yaw_accel_noise: float = param("process noise: random-walk angular acceleration on r", "rad/s^2", gt=0)
    gyro_bias_walk: float = param("process noise: gyro bias random walk", "rad/s/sqrt(s)", ge=0)
    gps_pos_std: float = param("assumed GPS position noise per axis", "m", gt=0)
    gps_vel_std: float = param("assumed GPS velocity noise per axis", "m/s", gt=0)
    compass_std: float = param("assumed compass heading noise", "rad", gt=0)
    gyro_std: float = param("assumed gyro noise", "rad/s", gt=0)
    dvl_std: float = param("assumed DVL velocity noise per axis", "m/s", gt=0)
    gate_probability: float = param("NIS gate: chi-square probability of accepting a true measurement", gt=0, lt=1)
    reset_after_rejections: int = param("consecutive rejected GPS fixes after which the position is reset to GPS", ge=1)
    filter: Literal["filterpy", "fast"] = param(
        "implementation of the EKF: filterpy's ExtendedKalmanFilter, or the same equations compiled with numba "
        "(fast; same estimates to rounding; docs/performance.md)", default="fast")


@dataclass
class NavigationStats:
    """Counters of what the filter did, for run summaries."""

    updates: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    position_resets: int = 0
    out_of_order: int = 0


@dataclass(frozen=True)
class NavState:
    """A navigation estimate at time ``t`` (s)."""

    t: float
    x: float
    y: float
    psi: float
    u: float
    v: float
    r: float
    gyro_bias: float
    position_std: float  # m, sqrt of the largest eigenvalue of the position covariance

    @property
    def speed(self) -> float:
        return math.hypot(self.u, self.v)

    def drift_angle(self, min_speed: float) -> float:
        """beta = atan2(v, u) (rad): the course over ground minus the heading (current, sway in
        turns); 0 below ``min_speed`` m/s of surge, where the velocity's direction is noise."""
        return math.atan2(self.v, self.u) if self.u > min_speed else 0.0

    def course(self, min_speed: float) -> float:
        """Course over ground (rad, NED): the heading plus :meth:`drift_angle`."""
        return self.psi + self.drift_angle(min_speed)


class FastEkf:
    """State ``x`` (7x1) and covariance ``P`` (7x7) of the ``"fast"`` filter; each step of
    :func:`autopilot_bridge.nav_kernel.step` assigns new arrays (never in place)."""

    def __init__(self) -> None:
        self.x = np.zeros((DIM, 1))
        self.P = np.eye(DIM)


_KIND = {"gps_pos": nav_kernel.GPS_POS, "gps_vel": nav_kernel.GPS_VEL, "compass": nav_kernel.COMPASS,
         "gyro": nav_kernel.GYRO, "dvl": nav_kernel.DVL}
_warm = False
_NO_SECOND = (nav_kernel.NONE, np.zeros((1, 1)), np.zeros((1, 1)), 0.0)   # nav_kernel.step's unused second measurement


def _warm_up() -> None:
    """Compile (or load from numba's cache) the fast kernel once per process, for both measurement
    sizes, so that no frame pays for it."""
    global _warm
    if not _warm:
        x, P = np.zeros((DIM, 1)), np.eye(DIM)
        one = np.zeros((1, 1))
        nav_kernel.step(x, P, 0.01, 0.1, 0.1, 0.0, nav_kernel.DVL, np.zeros((2, 1)), np.eye(2), 10.0, *_NO_SECOND)
        nav_kernel.step(x, P, 0.01, 0.1, 0.1, 0.0, nav_kernel.COMPASS, one, np.eye(1), 10.0,
                        nav_kernel.GYRO, one, np.eye(1), 10.0)
        _warm = True


class NavigationFilter:
    """EKF fusing GPS position/velocity, gyro, compass and DVL into ``[x, y, psi, u, v, r, b_g]``."""

    def __init__(self, params: NavigationParams) -> None:
        self.p = params
        self.fast = params.filter == "fast"
        # Both expose x (7x1) and P (7x7) (see the module docstring).
        if self.fast:
            self.ekf: ExtendedKalmanFilter | FastEkf = FastEkf()
        else:
            # filterpy imports scipy.stats (~0.6 s): only when it is the filter
            from filterpy.kalman import ExtendedKalmanFilter

            self.ekf = ExtendedKalmanFilter(dim_x=DIM, dim_z=2)
        self.t: float | None = None
        self.stats = NavigationStats()
        self._heading: float | None = None
        self._consecutive_gps_rejections = 0
        # every measurement's dimension (1: compass, gyro; 2: GPS, DVL), now rather than in a frame
        self._gates: dict[int, float] = {dim: chi2_quantile(self.p.gate_probability, dim) for dim in (1, 2)}
        # Per-frame work reuses these (the control loop runs this 100 times a second): F keeps its
        # identity entries and only the Jacobian's entries are rewritten; Q depends on dt only.
        self._F = np.eye(DIM)
        self._Q: dict[float, np.ndarray] = {}
        p = params
        self._q = (p.accel_noise**2, p.yaw_accel_noise**2, p.gyro_bias_walk**2)
        if self.fast:
            _warm_up()
        self._R = {"gps_pos": np.eye(2) * p.gps_pos_std**2, "gps_vel": np.eye(2) * p.gps_vel_std**2,
                   "compass": np.array([[p.compass_std**2]]), "gyro": np.array([[p.gyro_std**2]]),
                   "dvl": np.eye(2) * p.dvl_std**2}

    # -- life cycle ------------------------------------------------------------------------
    @property
    def initialized(self) -> bool:
        return self.t is not None

    def _initialize(self, t: float, north: float, east: float) -> None:
        x = np.zeros((DIM, 1))
        x[X, 0], x[Y, 0] = north, east
        x[PSI, 0] = self._heading if self._heading is not None else 0.0
        self.ekf.x = x
        heading_var = self.p.compass_std**2 if self._heading is not None else math.pi**2
        self.ekf.P = np.diag([self.p.gps_pos_std**2, self.p.gps_pos_std**2, heading_var,
                              1.0, 1.0, 0.1, 0.01**2])
        self.t = t

    # -- prediction --------------------------------------------------------------------------
    def predict_to(self, t: float) -> bool:
        """Propagate eq. (2) with constant body velocities to time ``t`` (s). False if ``t`` is past."""
        if self.t is None:
            return False
        dt = t - self.t
        if dt < 0.0:
            self.stats.out_of_order += 1
            return False
        if dt == 0.0:
            return True
        if not math.isfinite(dt):
            self._numeric("predict")
            return False
        x = self.ekf.x
        psi, u, v = x[PSI, 0], x[U, 0], x[V, 0]
        c, s = math.cos(psi), math.sin(psi)
        F = self._F
        F[X, PSI] = (-u * s - v * c) * dt
        F[X, U] = c * dt
        F[X, V] = -s * dt
        F[Y, PSI] = (u * c - v * s) * dt
        F[Y, U] = s * dt
        F[Y, V] = c * dt
        F[PSI, R] = dt
        Q = self._Q.get(dt)
        if Q is None:
            if len(self._Q) > 64:   # irregular time steps: keep the cache small
                self._Q.clear()
            q_a, q_r, q_b = self.p.accel_noise**2, self.p.yaw_accel_noise**2, self.p.gyro_bias_walk**2
            # Continuous white acceleration integrated over dt (velocity variance q dt, position q dt^3/3).
            Q = np.zeros((DIM, DIM))
            Q[U, U] = Q[V, V] = q_a * dt
            Q[X, X] = Q[Y, Y] = q_a * dt**3 / 3.0
            Q[R, R] = q_r * dt
            Q[PSI, PSI] = q_r * dt**3 / 3.0
            Q[BG, BG] = q_b * dt
            self._Q[dt] = Q
        x_new = x.copy()
        x_new[X, 0] += (u * c - v * s) * dt  # eq. (2)
        x_new[Y, 0] += (u * s + v * c) * dt
        x_new[PSI, 0] = wrap_angle(x[PSI, 0] + x[R, 0] * dt)
        P_new = F @ self.ekf.P @ F.T + Q
        if not (np.isfinite(x_new).all() and np.isfinite(P_new).all()):
            self._numeric("predict")  # keep the last estimate; its time stays, so dt grows next time
            return False
        self.ekf.x = x_new
        self.ekf.P = P_new
        self.t = t
        return True

    def _numeric(self, kind: str) -> None:
        key = f"numeric_{kind}"
        self.stats.rejected[key] = self.stats.rejected.get(key, 0) + 1

    # -- generic gated update --------------------------------------------------------------
    def _gate(self, dim: int) -> float:
        g = self._gates.get(dim)
        if g is None:
            g = self._gates[dim] = chi2_quantile(self.p.gate_probability, dim)
        return g

    def _update(self, kind: str, t: float, z: np.ndarray, model: MeasurementModel,
                angle_rows: tuple[int, ...] = ()) -> bool:
        """Predict to ``t``, gate the innovation by NIS, then update. ``model(x) -> (H, h(x))``."""
        if not (math.isfinite(t) and all(math.isfinite(v) for row in z.tolist() for v in row)):
            self._numeric(kind)
            return False
        if self.fast:
            return self._update_fast(kind, t, z)
        if not self.predict_to(t):
            return False
        x0, P0 = self.ekf.x.copy(), self.ekf.P.copy()
        try:
            with np.errstate(all="ignore"):  # overflow is caught below, as a non-finite result
                ok = self._gated_update(kind, z, model, self._R[kind], angle_rows)
        except (np.linalg.LinAlgError, ArithmeticError, ValueError):
            ok = None
        if ok is None or not (np.isfinite(self.ekf.x).all() and np.isfinite(self.ekf.P).all()):
            self.ekf.x, self.ekf.P = x0, P0
            self._numeric(kind)
            return False
        return ok

    def _update_fast(self, kind: str, t: float, z: np.ndarray) -> bool:
        """:meth:`_update` in one compiled step (autopilot_bridge/nav_kernel.py), with the same
        refusals, counters and roll-backs as :meth:`predict_to` and :meth:`_gated_update`."""
        if self.t is None:
            return False
        dt = t - self.t
        if dt < 0.0:
            self.stats.out_of_order += 1
            return False
        if not math.isfinite(dt):
            self._numeric("predict")
            return False
        q_a, q_r, q_b = self._q
        code, _, x, P = nav_kernel.step(self.ekf.x, self.ekf.P, dt, q_a, q_r, q_b, _KIND[kind], z,
                                        self._R[kind], self._gate(z.shape[0]), *_NO_SECOND)
        self._count(kind, code)
        if code == nav_kernel.NUMERIC_PREDICT:
            return False   # keep the last estimate; its time stays, so dt grows next time
        self.ekf.x, self.ekf.P, self.t = x, P, t
        return code == nav_kernel.OK

    def _gated_update(self, kind: str, z: np.ndarray, model: MeasurementModel, Rm: np.ndarray,
                      angle_rows: tuple[int, ...]) -> bool:
        H, hx = model(self.ekf.x)

        def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            d = a - b
            for i in angle_rows:
                d[i, 0] = wrap_angle(d[i, 0])
            return d

        y = residual(z, hx)
        S = H @ self.ekf.P @ H.T + Rm
        if S.shape[0] == 1:   # compass, gyro: most updates; a scalar division instead of a solve
            nis = float(y[0, 0] * y[0, 0] / S[0, 0])
        else:
            nis = float((y.T @ np.linalg.solve(S, y))[0, 0])
        if not math.isfinite(nis):
            raise ArithmeticError("innovation not finite")
        if nis > self._gate(z.shape[0]):
            self._rejected(kind)
            return False
        assert not isinstance(self.ekf, FastEkf)  # the "fast" filter updates in nav_kernel.step instead
        self.ekf.update(z, lambda _x: H, lambda _x: hx, R=Rm, residual=residual)
        self.ekf.x[PSI, 0] = wrap_angle(self.ekf.x[PSI, 0])
        self.stats.updates[kind] = self.stats.updates.get(kind, 0) + 1
        return True

    def _rejected(self, kind: str) -> None:
        self.stats.rejected[kind] = self.stats.rejected.get(kind, 0) + 1

    # -- measurements (each model returns the Jacobian H and the prediction h(x)) -------------
    # Linear measurements: their Jacobians are constants (neither update writes into H).
    @staticmethod
    def _position_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _H_POSITION, x[[X, Y]]

    @staticmethod
    def _ground_velocity_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        psi, u, v = x[PSI, 0], x[U, 0], x[V, 0]
        c, s = math.cos(psi), math.sin(psi)
        H = np.zeros((2, DIM))
        H[0, PSI], H[0, U], H[0, V] = -u * s - v * c, c, -s
        H[1, PSI], H[1, U], H[1, V] = u * c - v * s, s, c
        return H, np.array([[u * c - v * s], [u * s + v * c]])  # eq. (2)

    @staticmethod
    def _heading_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _H_HEADING, x[[PSI]]

    @staticmethod
    def _gyro_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _H_GYRO, np.array([[x[R, 0] + x[BG, 0]]])

    @staticmethod
    def _body_velocity_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _H_BODY_VELOCITY, x[[U, V]]

    def update_gps_position(self, t: float, north: float, east: float) -> bool:
        """A GPS fix converted to NED metres. Initialises the filter on the first one."""
        if not (math.isfinite(t) and math.isfinite(north) and math.isfinite(east)):
            self._numeric("gps_pos")
            return False
        if self.t is None:
            self._initialize(t, north, east)
            self.stats.updates["gps_pos"] = 1
            return True
        if t < self.t:
            self.stats.out_of_order += 1
            return False
        ok = self._update("gps_pos", t, np.array([[north], [east]]), self._position_model)
        if ok:
            self._consecutive_gps_rejections = 0
            return True
        self._consecutive_gps_rejections += 1
        if self._consecutive_gps_rejections >= self.p.reset_after_rejections:
            # Persistently inconsistent with GPS: trust GPS again rather than diverge forever.
            P = self.ekf.P
            self.ekf.x[X, 0], self.ekf.x[Y, 0] = north, east
            P[[X, Y], :] = 0.0
            P[:, [X, Y]] = 0.0
            P[X, X] = P[Y, Y] = self.p.gps_pos_std**2
            self.stats.position_resets += 1
            self._consecutive_gps_rejections = 0
        return False

    def update_gps_velocity(self, t: float, vn: float, ve: float) -> bool:
        """GPS velocity over ground, north and east (m/s)."""
        if self.t is None:
            return False
        return self._update("gps_vel", t, np.array([[vn], [ve]]), self._ground_velocity_model)

    def update_compass(self, t: float, heading: float) -> bool:
        """Compass heading (rad, true north, clockwise)."""
        if not math.isfinite(heading):
            self._numeric("compass")
            return False
        self._heading = heading
        if self.t is None:
            return False
        return self._update("compass", t, np.array([[heading]]), self._heading_model, angle_rows=(0,))

    def update_heading_and_rate(self, t: float, heading: float, yaw_rate: float) -> None:
        """:meth:`update_compass` then :meth:`update_gyro` at time ``t``: the same estimates,
        refusals and counters. The fast filter does the two in one compiled call
        (``nav_kernel.step`` with a second measurement) where the calls themselves would refuse
        nothing before their kernel (both finite, ``t`` not in the past)."""
        dt = math.inf if self.t is None else t - self.t
        if not (self.fast and dt >= 0.0 and math.isfinite(dt) and math.isfinite(heading)
                and math.isfinite(yaw_rate)):
            self.update_compass(t, heading)
            self.update_gyro(t, yaw_rate)
            return
        self._heading = heading
        q_a, q_r, q_b = self._q
        gate = self._gates[1]
        code_c, code_g, x, P = nav_kernel.step(self.ekf.x, self.ekf.P, dt, q_a, q_r, q_b,
                                               nav_kernel.COMPASS, np.array([[heading]]), self._R["compass"], gate,
                                               nav_kernel.GYRO, np.array([[yaw_rate]]), self._R["gyro"], gate)
        self.ekf.x, self.ekf.P = x, P
        if code_c != nav_kernel.NUMERIC_PREDICT or code_g != nav_kernel.NUMERIC_PREDICT:
            self.t = t
        self._count("compass", code_c)
        self._count("gyro", code_g)

    def _count(self, kind: str, code: int) -> None:
        """Count a kernel outcome: an update, a gated rejection, or a numeric fault of the
        prediction or of the update."""
        if code == nav_kernel.OK:
            self.stats.updates[kind] = self.stats.updates.get(kind, 0) + 1
        elif code == nav_kernel.REJECTED:
            self._rejected(kind)
        else:
            self._numeric("predict" if code == nav_kernel.NUMERIC_PREDICT else kind)

    def update_gyro(self, t: float, yaw_rate: float) -> bool:
        """Gyro yaw rate (rad/s), modelled as r + b_g + noise."""
        if self.t is None:
            return False
        return self._update("gyro", t, np.array([[yaw_rate]]), self._gyro_model)

    def update_dvl(self, t: float, u: float, v: float) -> bool:
        """DVL bottom-lock body velocity over ground (m/s)."""
        if self.t is None:
            return False
        return self._update("dvl", t, np.array([[u], [v]]), self._body_velocity_model)

    # -- output ------------------------------------------------------------------------------
    def state(self) -> NavState | None:
        """The current estimate, or None before the first GPS fix."""
        if self.t is None:
            return None
        x = self.ekf.x[:, 0].tolist()
        P = self.ekf.P
        a, b, d = float(P[X, X]), float(P[X, Y]), float(P[Y, Y])
        largest = 0.5 * (a + d) + math.hypot(0.5 * (a - d), b)   # of the symmetric 2x2 position covariance
        return NavState(t=self.t, x=x[X], y=x[Y], psi=x[PSI], u=x[U], v=x[V], r=x[R], gyro_bias=x[BG],
                        position_std=math.sqrt(max(largest, 0.0)))
