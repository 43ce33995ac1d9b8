"""The meandering-jet current of eq. (13): divergence-free, consistent with its stream function."""

from __future__ import annotations

import numpy as np
import pytest

from common.current_field import CurrentField
from hil.settings import load


@pytest.fixture(scope="module")
def field():
    return CurrentField(load().current)


def test_divergence_is_zero_by_finite_differences(field):
    x, y = np.meshgrid(np.linspace(-200, 200, 41), np.linspace(-100, 200, 31), indexing="ij")
    h = 1e-3
    for t in (0.0, 37.0, 400.0):
        un_p, _ = field.velocity(x + h, y, t)
        un_m, _ = field.velocity(x - h, y, t)
        _, ve_p = field.velocity(x, y + h, t)
        _, ve_m = field.velocity(x, y - h, t)
        div = (un_p - un_m) / (2 * h) + (ve_p - ve_m) / (2 * h)
        grad_scale = np.max(np.abs(un_p - un_m)) / (2 * h)  # a typical velocity gradient, 1/s
        assert grad_scale > 1e-3  # the field is not trivially constant
        assert np.max(np.abs(div)) < 1e-6 * max(1.0, grad_scale) + 1e-7


def test_velocity_comes_from_the_stream_function(field):
    """v_north = -S/sc dpsi/dy and v_east = +S/sc dpsi/dx (psi differentiated numerically in metres)."""
    rng = np.random.default_rng(0)
    x, y, t = rng.uniform(-150, 150, 200), rng.uniform(0, 100, 200), rng.uniform(0, 300, 200)
    h = 1e-4
    dpsi_dx = (field.stream_function(x + h, y, t) - field.stream_function(x - h, y, t)) / (2 * h)
    dpsi_dy = (field.stream_function(x, y + h, t) - field.stream_function(x, y - h, t)) / (2 * h)
    un, ve = field.velocity(x, y, t)
    k = field.speed_scale / field.sc
    np.testing.assert_allclose(un, -k * dpsi_dy, atol=1e-6)
    np.testing.assert_allclose(ve, k * dpsi_dx, atol=1e-6)


def test_scalar_and_vectorised_agree(field):
    rng = np.random.default_rng(1)
    pts = rng.uniform([-300, -300, 0], [300, 300, 1000], (100, 3))
    un, ve = field.velocity(pts[:, 0], pts[:, 1], pts[:, 2])
    for (x, y, t), a, b in zip(pts, un, ve, strict=False):
        assert field.velocity_at(x, y, t) == pytest.approx((a, b), abs=1e-12)


def test_jet_flows_north_at_speed_scale_on_its_axis(field):
    # at X = 0 (sin theta = 0 at T = 0) the axis is at Y = B(0) cos(0) = b + e cos(theta_u)
    B0 = field.b + field.e * np.cos(field.theta_u)
    y_axis = field.origin_y + B0 / field.sc
    un, ve = field.velocity_at(field.origin_x, y_axis, 0.0)
    assert un == pytest.approx(field.speed_scale)
    assert ve == pytest.approx(0.0, abs=1e-12)
    far_n, far_e = field.velocity_at(0.0, y_axis + 2000.0, 0.0)
    assert abs(far_n) < 1e-6 and abs(far_e) < 1e-6


def test_disabled_field_is_zero():
    f = CurrentField(load(None, ["current.enabled=false"]).current)
    assert f.velocity_at(0.0, 50.0, 0.0) == (0.0, 0.0)
    un, ve = f.velocity(np.zeros(3), np.zeros(3), 0.0)
    assert not un.any() and not ve.any()
