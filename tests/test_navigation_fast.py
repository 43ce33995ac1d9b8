"""The two EKF implementations (navigation.filter = "fast" | "filterpy") give the same estimates.

Both filters see the same sequence of predicts and updates - seeded noise, GPS glitches gated out,
a dropout that ends in a position reset, non-finite and out-of-order measurements, an overflow -
and must agree after every call: same accepted/rejected answer, same state and covariance to
1e-9, same counters.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from autopilot_bridge.navigation import NavigationFilter, NavigationParams, wrap_angle
from tests.test_navigation import params, truth


def pair(**kw) -> tuple[NavigationFilter, NavigationFilter]:
    p = params(**kw)
    return NavigationFilter(replace(p, filter="fast")), NavigationFilter(replace(p, filter="filterpy"))


def assert_same(fast: NavigationFilter, ref: NavigationFilter, where: str) -> None:
    assert fast.t == ref.t, where
    if ref.t is None:
        return
    np.testing.assert_allclose(fast.ekf.x, ref.ekf.x, rtol=0, atol=1e-9, err_msg=where)
    np.testing.assert_allclose(fast.ekf.P, ref.ekf.P, rtol=1e-9, atol=1e-12, err_msg=where)


def both(fast: NavigationFilter, ref: NavigationFilter, method: str, *args: float) -> bool:
    a = getattr(fast, method)(*args)
    b = getattr(ref, method)(*args)
    where = f"{method}{args}"
    assert a == b, where
    assert_same(fast, ref, where)
    return a


def test_default_is_fast_and_filterpy_stays_selectable():
    assert NavigationParams.__dataclass_fields__["filter"].default == "fast"
    fast, ref = pair()
    assert fast.fast and not ref.fast
    assert type(ref.ekf).__module__.startswith("filterpy")


@pytest.mark.parametrize("seed", [1, 2024])
def test_same_estimates_on_a_noisy_run_with_glitches_dropout_and_faults(seed):
    rng = np.random.default_rng(seed)
    t, x, y, psi, u, v, r, vn, ve = truth(70.0)
    fast, ref = pair(reset_after_rejections=5)
    glitches = set(rng.choice(np.arange(100, len(t), 10), size=8, replace=False).tolist())
    dropout = (40.0, 6.0)
    for k in range(len(t)):
        tk = float(t[k])
        both(fast, ref, "update_gyro", tk, float(r[k] + 0.004 + rng.normal(0, 0.002)))
        if k % 4 == 0:
            both(fast, ref, "update_compass", tk, wrap_angle(float(psi[k] + rng.normal(0, 0.02))))
        if k % 5 == 0:
            both(fast, ref, "update_dvl", tk, float(u[k] + rng.normal(0, 0.02)), float(v[k] + rng.normal(0, 0.02)))
        if k % 10 == 0 and not dropout[0] <= tk < dropout[0] + dropout[1]:
            gx, gy = float(x[k] + rng.normal(0, 0.5)), float(y[k] + rng.normal(0, 0.5))
            if k in glitches:
                gx += 15.0
            if 60.0 <= tk < 62.0:   # towed: GPS disagrees until the position is reset
                gy += 40.0
            both(fast, ref, "update_gps_position", tk, gx, gy)
            both(fast, ref, "update_gps_velocity", tk, float(vn[k] + rng.normal(0, 0.05)),
                 float(ve[k] + rng.normal(0, 0.05)))
        if k % 997 == 0:   # numeric guards and out-of-order refusals, on both
            both(fast, ref, "update_compass", tk, math.nan)
            both(fast, ref, "update_gyro", tk + 0.001, math.inf)
            both(fast, ref, "update_gps_velocity", tk - 1.0, 1.0, 0.0)
            both(fast, ref, "update_dvl", math.nan, 1.0, 0.0)
        a, b = fast.state(), ref.state()
        assert (a is None) == (b is None)
        if a is not None:
            assert a.position_std == pytest.approx(b.position_std, rel=1e-9)
    for f in (fast, ref):
        assert f.stats.rejected.get("gps_pos", 0) >= 8   # the glitches and the tow were gated out...
        assert f.stats.position_resets >= 1              # ... and the tow ended in a reset
        assert f.stats.rejected.get("numeric_compass", 0) >= 1
    assert fast.stats == ref.stats


def test_same_refusal_of_an_update_that_would_overflow():
    fast, ref = pair()
    for f in (fast, ref):
        f.update_compass(0.0, 0.1)
        f.update_gps_position(0.0, 0.0, 0.0)
    both(fast, ref, "update_gyro", 0.01, 0.0)
    both(fast, ref, "update_gps_velocity", 0.02, 1.0, 0.5)
    for f in (fast, ref):   # a covariance blown up by a fault upstream
        f.ekf.P = f.ekf.P * 1e305
    both(fast, ref, "update_gps_velocity", 0.03, 1.0, 0.5)
    both(fast, ref, "update_dvl", 0.04, 1e300, 0.0)
    assert fast.stats.rejected == ref.stats.rejected
    assert any(k.startswith("numeric_") for k in fast.stats.rejected)


def test_singular_innovation_covariance_is_refused_by_both():
    fast, ref = pair()
    for f in (fast, ref):
        f.update_compass(0.0, 0.1)
        f.update_gps_position(0.0, 0.0, 0.0)
        f.ekf.P = np.zeros((7, 7))
        f._R["dvl"] = np.zeros((2, 2))   # S = H P H^T + R = 0
    assert both(fast, ref, "update_dvl", 0.0, 1.0, 0.0) is False
    assert fast.stats.rejected == ref.stats.rejected == {"numeric_dvl": 1}
