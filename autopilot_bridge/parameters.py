"""Tunable parameters, declared by the component that owns them (see ``parameters()`` methods).

Each parameter has a MAVLink name (at most 16 characters), a getter, a setter and a closed range;
PARAM_SET outside the range (or NaN/inf) changes nothing and the current value is sent back, as
https://mavlink.io/en/services/parameter.html asks. Values travel as MAV_PARAM_TYPE_REAL32.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass


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
