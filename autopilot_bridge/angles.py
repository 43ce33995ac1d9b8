"""Angles in NED: headings clockwise from north, in radians."""

from __future__ import annotations

import math


def wrap_angle(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi
