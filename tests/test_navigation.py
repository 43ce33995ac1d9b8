"""Navigation fusion against a known truth trajectory with seeded sensor noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.navigation import NavigationFilter, NavigationParams, chi2_quantile, wrap_angle

GPS_STD = 0.5
COMPASS_STD = 0.02
GYRO_STD = 0.002
GYRO_BIAS = 0.004


def params(**kw) -> NavigationParams:
    base = dict(accel_noise=0.3, yaw_accel_noise=0.3, gyro_bias_walk=1e-4, gps_pos_std=GPS_STD,
                gps_vel_std=0.05, compass_std=COMPASS_STD, gyro_std=GYRO_STD, dvl_std=0.02,
                gate_probability=0.9999, reset_after_rejections=20)
    base.update(kw)
    return NavigationParams(**base)


def truth(duration: float, dt: float = 0.01, start_heading: float = 0.3):
    """A boat at 1.5 m/s weaving (r = 0.15 sin(0.2 t)), with a small sway: arrays t, x, y, psi, u, v, r."""
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    r = 0.15 * np.sin(0.2 * t)
    psi = start_heading + np.concatenate([[0.0], np.cumsum((r[1:] + r[:-1]) / 2 * dt)])
    u = np.full(n, 1.5)
    v = 0.1 * np.sin(0.1 * t)
    vn = u * np.cos(psi) - v * np.sin(psi)
    ve = u * np.sin(psi) + v * np.cos(psi)
    x = np.concatenate([[0.0], np.cumsum((vn[1:] + vn[:-1]) / 2 * dt)])
    y = np.concatenate([[0.0], np.cumsum((ve[1:] + ve[:-1]) / 2 * dt)])
    return t, x, y, psi, u, v, r, vn, ve


def run_filter(duration=120.0, seed=3, dropout=None, glitch_at=None, start_heading=0.3, nav=None):
    rng = np.random.default_rng(seed)
    t, x, y, psi, u, v, r, vn, ve = truth(duration, start_heading=start_heading)
    f = NavigationFilter(nav or params())
    est, errs = [], []
    glitch_result = None
    for k in range(len(t)):
        tk = t[k]
        f.update_gyro(tk, r[k] + GYRO_BIAS + rng.normal(0, GYRO_STD))
        if k % 4 == 0:
            f.update_compass(tk, wrap_angle(psi[k] + rng.normal(0, COMPASS_STD)))
        in_dropout = dropout is not None and dropout[0] <= tk < dropout[0] + dropout[1]
        if k % 10 == 0 and not in_dropout:
            gx, gy = x[k] + rng.normal(0, GPS_STD), y[k] + rng.normal(0, GPS_STD)
            if glitch_at is not None and abs(tk - glitch_at) < 1e-9:
                gx += 15.0
                glitch_result = f.update_gps_position(tk, gx, gy)
            else:
                f.update_gps_position(tk, gx, gy)
            f.update_gps_velocity(tk, vn[k] + rng.normal(0, 0.05), ve[k] + rng.normal(0, 0.05))
        s = f.state()
        if s is not None:
            est.append(s)
            errs.append((tk, math.hypot(s.x - x[k], s.y - y[k]), wrap_angle(s.psi - psi[k]), s.position_std))
    return f, np.array(errs), glitch_result


def test_position_rmse_below_gps_noise():
    f, errs, _ = run_filter()
    settled = errs[errs[:, 0] > 10.0]
    rmse = math.sqrt(np.mean(settled[:, 1] ** 2))
    # The raw GPS horizontal error has RMS sqrt(2) * 0.5 = 0.71 m; fusion must beat the per-axis sigma.
    assert rmse < GPS_STD, rmse
    heading_rmse = math.sqrt(np.mean(settled[:, 2] ** 2))
    assert heading_rmse < COMPASS_STD, heading_rmse
    assert abs(f.state().gyro_bias - GYRO_BIAS) < 0.002


def test_gps_dropout_dead_reckons_with_growing_covariance():
    start, length = 60.0, 10.0
    f, errs, _ = run_filter(dropout=(start, length))
    during = errs[(errs[:, 0] >= start) & (errs[:, 0] < start + length)]
    # Stated bound: after 10 s without GPS at 1.5 m/s the position error stays below 2 m.
    assert during[:, 1].max() < 2.0, during[:, 1].max()
    # The filter knows it is getting worse: its position std grows through the dropout.
    assert during[-1, 3] > 2 * during[0, 3]
    after = errs[errs[:, 0] > start + length + 5.0]
    assert after[:, 1].max() < 2.0


def test_gps_glitch_is_rejected_by_the_gate_and_counted():
    f, errs, accepted = run_filter(glitch_at=50.0)
    assert accepted is False
    assert f.stats.rejected.get("gps_pos", 0) >= 1
    near = errs[(errs[:, 0] >= 50.0) & (errs[:, 0] < 52.0)]
    assert near[:, 1].max() < 1.5  # the 15 m jump never reached the estimate


def test_heading_wraps_across_north():
    # Start heading just west of north while weaving across 0/2pi: no 2pi jumps in the estimate.
    f, errs, _ = run_filter(duration=60.0, start_heading=-0.05)
    assert np.abs(errs[errs[:, 0] > 5.0, 2]).max() < 0.1
    assert -math.pi <= f.state().psi < math.pi


def test_persistent_disagreement_resets_position_instead_of_diverging():
    f = NavigationFilter(params(reset_after_rejections=5))
    f.update_compass(0.0, 0.0)
    f.update_gps_position(0.0, 0.0, 0.0)
    for k in range(1, 30):
        f.update_gyro(k * 0.1, 0.0)
        f.update_compass(k * 0.1, 0.0)
    # The vessel was actually moved 50 m (e.g. towed) while GPS was its only fix source.
    results = [f.update_gps_position(3.0 + 0.1 * k, 50.0, 0.0) for k in range(6)]
    assert not any(results[:5])
    assert f.stats.position_resets == 1
    assert abs(f.state().x - 50.0) < 1.0


def test_out_of_order_measurements_are_counted_not_applied():
    f = NavigationFilter(params())
    f.update_gps_position(1.0, 0.0, 0.0)
    assert f.update_gyro(0.5, 0.1) is False
    assert f.stats.out_of_order == 1


@pytest.mark.parametrize("heading", [0.0, math.pi / 2, -3.0])
def test_ground_velocity_is_rotated_by_heading(heading):
    f = NavigationFilter(params())
    f.update_compass(0.0, heading)
    f.update_gps_position(0.0, 0.0, 0.0)
    for k in range(1, 200):
        t = k * 0.05
        f.update_compass(t, heading)
        f.update_gyro(t, 0.0)
        f.update_gps_velocity(t, 2.0 * math.cos(heading), 2.0 * math.sin(heading))
    s = f.state()
    assert s.u == pytest.approx(2.0, abs=0.05)
    assert s.v == pytest.approx(0.0, abs=0.05)


def test_gate_quantile_equals_scipy_stats_chi2_ppf():
    """The NIS gate's quantile without scipy.stats (a process start pays ~0.6 s for it) is the same
    number scipy.stats.chi2.ppf gives, for every measurement dimension."""
    from scipy.stats import chi2

    for p in [0.5, 0.9, 0.95, 0.99, 0.997, 0.9973, 0.999999, *np.random.default_rng(3).uniform(0.01, 0.99, 50)]:
        for dof in (1, 2, 3, 4):
            assert chi2_quantile(float(p), dof) == float(chi2.ppf(p, dof))


def test_configuration_does_not_import_filterpy_or_scipy_stats():
    """`hil` commands load the configuration; only the vessel computer's set-up pays for filterpy."""
    import subprocess
    import sys

    code = ("import sys, hil.settings, autopilot_bridge.navigation, autopilot_bridge.ais_tracking; "
            "print(sorted(m for m in sys.modules if m.startswith(('filterpy', 'scipy.stats'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def _stats(f: NavigationFilter) -> tuple:
    s = f.stats
    return f.t, dict(s.updates), dict(s.rejected), s.out_of_order, f._heading


def test_heading_and_rate_together_equal_the_two_updates_bit_for_bit():
    # The usual frame's compass and gyro in one compiled call (update_heading_and_rate) against
    # update_compass then update_gyro, on random frames that reach every outcome: accepted, gated
    # (outliers), out of order, non-finite readings, and a prediction or an update that overflows.
    rng = np.random.default_rng(7)
    outcomes: set[str] = set()
    for _ in range(40):
        pair, seq = NavigationFilter(params()), NavigationFilter(params())
        t = 0.0
        for f in (pair, seq):
            f.update_compass(t, 0.3)
            f.update_gps_position(t, 1.0, 2.0)
        for _ in range(60):
            t += rng.choice([0.01, 0.01, 0.01, 0.0, -0.02, 0.05])
            heading = wrap_angle(0.3 + rng.normal(0, 0.02) + (rng.random() < 0.1) * rng.normal(0, 2.0))
            rate = rng.normal(0.004, 0.002) + (rng.random() < 0.1) * rng.normal(0, 1.0)
            if rng.random() < 0.05:
                heading = rng.choice([math.nan, math.inf])
            if rng.random() < 0.05:
                rate = rng.choice([math.nan, -math.inf])
            if rng.random() < 0.03:   # an estimate whose next prediction or update overflows
                scale = rng.choice([1e306, 1e200])
                for f in (pair, seq):
                    with np.errstate(over="ignore"):
                        f.ekf.P = f.ekf.P * scale
            if rng.random() < 0.02:
                for f in (pair, seq):
                    f.ekf.x = f.ekf.x.copy()
                    f.ekf.x[3, 0] = 1e305
            pair.update_heading_and_rate(t, heading, rate)
            seq.update_compass(t, heading)
            seq.update_gyro(t, rate)
            assert np.array_equal(pair.ekf.x, seq.ekf.x, equal_nan=True)
            assert np.array_equal(pair.ekf.P, seq.ekf.P, equal_nan=True)
            assert _stats(pair) == _stats(seq)
        outcomes |= set(seq.stats.updates) | {f"rejected {k}" for k in seq.stats.rejected}
        if seq.stats.out_of_order:
            outcomes.add("out of order")
    # every path the call can take was taken
    assert {"compass", "gyro", "rejected compass", "rejected gyro", "rejected numeric_predict",
            "rejected numeric_compass", "out of order"} <= outcomes, outcomes
