"""Wave forces of eq. (6) against hand-computed values, and the seeded slow variation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.settings import load
from simulator.waves import OrnsteinUhlenbeck, WaveModel, wave_forces


def test_wave_forces_hand_computed():
    # rho = 1025, L = 2, alpha = 0.15, chi = 30 deg, C = (0.05, 0.10, 0.01):
    # 0.5 * 1025 * 2 * 0.0225 = 23.0625; * cos30 * 0.05 = 0.998636; * sin30 * 0.1 = 1.153125;
    # 0.5 * 1025 * 4 * 0.0225 = 46.125; * sin30 * 0.01 = 0.230625
    X, Y, N = wave_forces(1025.0, 2.0, 0.15, math.radians(30), 0.05, 0.10, 0.01)
    assert X == pytest.approx(0.998636, abs=1e-6)
    assert Y == pytest.approx(1.153125, abs=1e-9)
    assert N == pytest.approx(0.230625, abs=1e-9)


def test_encounter_angle_is_direction_minus_heading():
    cfg = load(None, ["waves.amplitude_std=0.0", "waves.direction_std=0.0", "waves.direction=1.0"])
    w = WaveModel(cfg.waves, cfg.vessel, np.random.default_rng(0))
    p = cfg.waves
    assert w.forces(0.4) == pytest.approx(wave_forces(1025.0, 2.0, p.amplitude, 0.6, p.C_X, p.C_Y, p.C_N))
    # following seas push forward, beam seas from port push to starboard
    assert w.forces(1.0)[0] > 0 and w.forces(1.0)[1] == pytest.approx(0.0, abs=1e-12)
    assert w.forces(1.0 - math.pi / 2)[1] > 0


def test_ornstein_uhlenbeck_statistics_and_seed():
    a = OrnsteinUhlenbeck(0.15, 0.03, 30.0, np.random.default_rng(5))
    xs = np.array([a.step(1.0) for _ in range(60000)])
    # 60000 s / 30 s correlation ~ 1000 independent samples: mean within ~4 sigma/sqrt(1000)
    assert xs.mean() == pytest.approx(0.15, abs=4 * 0.03 / math.sqrt(1000))
    assert xs.std() == pytest.approx(0.03, rel=0.15)
    # slowly varying: one-second increments are much smaller than the spread
    assert np.std(np.diff(xs)) < 0.3 * 0.03
    b = OrnsteinUhlenbeck(0.15, 0.03, 30.0, np.random.default_rng(5))
    assert [b.step(1.0) for _ in range(10)] == list(xs[:10])


def test_disabled_waves_exert_nothing():
    cfg = load(None, ["waves.enabled=false"])
    assert WaveModel(cfg.waves, cfg.vessel, np.random.default_rng(0)).forces(0.3) == (0.0, 0.0, 0.0)
