"""Fixed-step classic Runge-Kutta (RK4) on plain-float tuples, kept outside the model.

The simulator integrates the hull with ``simulator.vessel.hull_rk4_step``, compiled, which computes
the same operations in the same order; this generic step is its reference
(tests/test_sim_vessel.py) and integrates any other right-hand side. A change here does not change
the simulator: change both, and the test holds them together."""

from __future__ import annotations

from collections.abc import Callable

Vec = tuple[float, ...]


def rk4_step(f: Callable[[Vec], Vec], s: Vec, dt: float) -> Vec:
    """One RK4 step of ds/dt = f(s) (autonomous over the step: inputs held for dt)."""
    k1 = f(s)
    k2 = f(tuple(a + 0.5 * dt * b for a, b in zip(s, k1, strict=False)))
    k3 = f(tuple(a + 0.5 * dt * b for a, b in zip(s, k2, strict=False)))
    k4 = f(tuple(a + dt * b for a, b in zip(s, k3, strict=False)))
    return tuple(a + dt / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                 for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4, strict=False))
