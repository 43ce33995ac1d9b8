"""The parameter microservice's table: the tunables a ground station may read and set, with ranges.

Each parameter has a MAVLink name (at most 16 characters), a getter, a setter and a closed range;
PARAM_SET outside the range (or NaN/inf) changes nothing and the current value is sent back, as
https://mavlink.io/en/services/parameter.html asks. Values travel as MAV_PARAM_TYPE_REAL32.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable


@dataclass(frozen=True)
class Param:
    name: str
    get: Callable[[], float]
    set: Callable[[float], None]
    lo: float
    hi: float
    help: str
    unit: str = ""


class ParamTable:
    def __init__(self, params: list[Param]) -> None:
        for p in params:
            if len(p.name) > 16:
                raise ValueError(f"parameter name {p.name!r} is longer than 16 characters")
        self.params = list(params)
        self.index = {p.name: i for i, p in enumerate(self.params)}
        self.rejected = 0

    def __len__(self) -> int:
        return len(self.params)

    def get(self, name: str) -> Param | None:
        i = self.index.get(name)
        return None if i is None else self.params[i]

    def set(self, name: str, value: float) -> tuple[bool, str]:
        """Apply ``value`` if it is inside the parameter's range; (ok, why)."""
        p = self.get(name)
        if p is None:
            self.rejected += 1
            return False, f"unknown parameter {name}"
        if not math.isfinite(value) or not p.lo <= value <= p.hi:
            self.rejected += 1
            return False, f"{name}: {value:g} outside {p.lo:g}..{p.hi:g}{' ' + p.unit if p.unit else ''}"
        try:
            p.set(float(value))
        except ValueError as exc:  # a cross-parameter rule of the configuration dataclass
            self.rejected += 1
            return False, f"{name}: {exc}"
        return True, f"{name} = {value:g}"


def autopilot_params(ap: Any, link: Any) -> ParamTable:
    """The tunables that matter for the HIL vessel computer ``ap`` (an ``Autopilot``) and its GCS ``link``."""

    def set_ap(key: str) -> Callable[[float], None]:
        def f(v: float) -> None:
            ap.p = replace(ap.p, **{key: v})  # AutopilotParams.__post_init__ checks deadline < period
        return f

    def set_ctl(key: str) -> Callable[[float], None]:
        def f(v: float) -> None:
            ap.control_params = replace(ap.control_params, **{key: v})
            ap.heading_pid.p = ap.control_params
            ap.speed_ctl.p = ap.control_params
        return f

    def planner(key: str) -> Callable[[], float]:
        return lambda: float(ap.planner_overrides.get(key, getattr(ap.world.params, key)))

    def set_fs_action(v: float) -> None:
        if v != int(v):
            raise ValueError("must be 0, 1 or 2")
        link.failsafe_action = ("none", "hold", "rtl")[int(round(v))]

    def set_radius(v: float) -> None:
        ap.vehicle.default_radius = v

    period = ap.p.planning_period
    return ParamTable([
        Param("PLN_DEADLINE", lambda: ap.p.planning_deadline, set_ap("planning_deadline"), 0.05, 0.95 * period,
              "hard deadline of one local planning cycle", "s"),
        Param("PLN_PERCEPT_RAD", planner("perceptual_radius"),
              lambda v: ap.set_planner_override("perceptual_radius", v), 5.0, 200.0,
              "radius of the perceptual domain (33 m in section 4.2)", "m"),
        Param("PLN_PNG_PROB", planner("png_probability"), lambda v: ap.set_planner_override("png_probability", v),
              0.0, 1.0, "probability of sampling the PNG node (section 3.2)"),
        Param("CRUISE_SPEED", lambda: ap.p.cruise_speed, set_ap("cruise_speed"), 0.2, 3.0,
              "speed set-point along the local path (3 m/s: the hull's top speed)", "m/s"),
        Param("HDG_KP", lambda: ap.control_params.heading_kp, set_ctl("heading_kp"), 0.0, 1000.0,
              "heading PID proportional gain", "N m/rad"),
        Param("HDG_KI", lambda: ap.control_params.heading_ki, set_ctl("heading_ki"), 0.0, 200.0,
              "heading PID integral gain", "N m/(rad s)"),
        Param("HDG_KD", lambda: ap.control_params.heading_kd, set_ctl("heading_kd"), 0.0, 500.0,
              "heading PID derivative gain", "N m s/rad"),
        Param("SPD_BANDWIDTH", lambda: ap.control_params.speed_bandwidth, set_ctl("speed_bandwidth"), 0.05, 5.0,
              "speed loop natural frequency", "rad/s"),
        Param("WP_RADIUS", lambda: ap.vehicle.default_radius, set_radius, 0.5, 50.0,
              "acceptance radius of items that give none (and of RTL/GUIDED)", "m"),
        Param("FS_GCS_TIMEOUT", lambda: link.failsafe_timeout, lambda v: setattr(link, "failsafe_timeout", v),
              1.0, 120.0, "no GCS heartbeat for this long in AUTO triggers the failsafe", "s"),
        Param("FS_GCS_ACTION", lambda: float(("none", "hold", "rtl").index(link.failsafe_action)), set_fs_action,
              0.0, 2.0, "GCS failsafe action: 0 none, 1 hold, 2 return to launch"),
    ])
