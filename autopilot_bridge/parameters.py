"""Tunable parameters, declared by the component that owns them and read live where they are used.

As ArduPilot binds a parameter to its owner's member (``AP_Param``), a component declares each of its
tunables once, as a class attribute::

    class HeadingPID:
        kp = Tunable("HDG_KP", 0.0, 1000.0, "N m/rad", "heading PID proportional gain")

and reads ``self.kp`` where it uses it. The value lives on the instance, nowhere else: the parameter
service (:func:`bind`, :class:`ParamTable`) reads and writes that same attribute, so nothing can hold
a copy that goes stale. Assigning a value outside the declared range (or NaN/inf) raises ValueError,
from the configuration and from a ground station alike.

PARAM_SET outside the range changes nothing and the current value is sent back, as
https://mavlink.io/en/services/parameter.html asks. Values travel as MAV_PARAM_TYPE_REAL32; a
parameter declared ``integer`` (an enumeration or a count) accepts whole numbers only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, overload

# A number, or one computed from the owner (e.g. 0.95 x its period). The owner is whichever class declares
# the tunable (the descriptor serves them all), so the function takes Any.
Bound = float | Callable[[Any], float]


@dataclass(frozen=True)
class Param:
    """One declared parameter bound to its owner: read and write the owner's attribute."""

    name: str
    get: Callable[[], float]
    set: Callable[[float], None]
    lo: float
    hi: float
    help: str
    unit: str = ""


DECLARED: list[tuple[type, Tunable]] = []   # every declaration, with its owner class, as classes are made

# The modules whose classes own parameters (imported by :func:`markdown_table`).
OWNER_MODULES = ("autopilot_bridge.vehicle", "autopilot_bridge.plan_handoff", "autopilot_bridge.planner_tuning",
                 "autopilot_bridge.control", "autopilot_bridge.station_keeping", "autopilot_bridge.geofence",
                 "autopilot_bridge.gcs.failsafe", "autopilot_bridge.gcs.identity")


class Tunable:
    """A data descriptor: a parameter's declaration (name, range, units, doc) on its owner's class."""

    def __init__(self, name: str, lo: Bound, hi: Bound, unit: str, doc: str, *, integer: bool = False,
                 notify: str | None = None) -> None:
        """``notify``: the name of an owner method called with the new value after every change (for a
        value the owner must hand to a library object, such as a codec's system id)."""
        if len(name) > 16:
            raise ValueError(f"parameter name {name!r} is longer than 16 characters (MAVLink param_id)")
        self.name, self.lo, self.hi, self.unit, self.doc, self.integer = name, lo, hi, unit, doc, integer
        self.notify = notify
        self.attr = ""

    def __set_name__(self, owner: type, attr: str) -> None:
        self.attr = attr
        DECLARED.append((owner, self))

    def bounds(self, obj: object) -> tuple[float, float]:
        lo = self.lo(obj) if callable(self.lo) else self.lo
        hi = self.hi(obj) if callable(self.hi) else self.hi
        return float(lo), float(hi)

    @overload
    def __get__(self, obj: None, objtype: type | None = None) -> Tunable: ...

    @overload
    def __get__(self, obj: object, objtype: type | None = None) -> float: ...

    def __get__(self, obj: object | None, objtype: type | None = None) -> Tunable | float:
        if obj is None:
            return self
        try:
            return obj.__dict__[self.attr] 
        except KeyError:
            raise AttributeError(f"{type(obj).__name__}.{self.attr} ({self.name}) was never set") from None

    def __set__(self, obj: object, value: float) -> None:
        why = self.check(obj, value)
        if why is not None:
            raise ValueError(why)
        obj.__dict__[self.attr] = float(value)
        if self.notify is not None:
            getattr(obj, self.notify)(float(value))

    def check(self, obj: object, value: float) -> str | None:
        """Why ``value`` cannot be this parameter's, or None."""
        lo, hi = self.bounds(obj)
        unit = f" {self.unit}" if self.unit else ""
        if not isinstance(value, (int, float)) or not math.isfinite(value) or not lo <= value <= hi:
            return f"{self.name}: {value:g} outside {lo:g}..{hi:g}{unit}" if isinstance(value, (int, float)) \
                else f"{self.name}: not a number"
        if self.integer and value != int(value):
            return f"{self.name}: {value:g} is not a whole number"
        return None


def declarations(owner: object) -> list[Tunable]:
    """The tunables ``owner``'s class declares (base classes first), in declaration order."""
    seen: dict[str, Tunable] = {}
    for cls in reversed(type(owner).__mro__):
        for v in vars(cls).values():
            if isinstance(v, Tunable):
                seen[v.attr] = v
    return list(seen.values())


def bind(*owners: object) -> list[Param]:
    """Every tunable of ``owners`` as a :class:`Param` reading and writing the owner's own attribute."""
    out: list[Param] = []
    for owner in owners:
        for d in declarations(owner):
            lo, hi = d.bounds(owner)

            def get(o: object = owner, a: str = d.attr) -> float:
                return float(getattr(o, a))

            def put(v: float, o: object = owner, a: str = d.attr) -> None:
                setattr(o, a, v)

            out.append(Param(d.name, get, put, lo, hi, d.doc, d.unit))
    return out


class ParamTable:
    """The parameter service's index of every component's bound declarations (names unique)."""

    def __init__(self, params: list[Param]) -> None:
        names = [p.name for p in params]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"parameters declared twice: {', '.join(dup)}")
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
        except ValueError as exc:  # the declaration's own rule (a whole number) or the owner's
            self.rejected += 1
            msg = str(exc)
            return False, msg if msg.startswith(name) else f"{name}: {msg}"
        return True, f"{name} = {value:g}"


def _bound_text(b: Bound) -> str:
    if callable(b):
        code = getattr(b, "__code__", None)
        return "0.95 x planning period" if code is not None and "planning_period" in code.co_names else "(computed)"
    return f"{b:g}"


def markdown_table() -> str:
    """The parameters every component declares, as the Markdown table of docs/gcs.md."""
    import importlib

    for m in OWNER_MODULES:
        importlib.import_module(m)
    rows = ["| name | range | units | owner | what |", "| --- | --- | --- | --- | --- |"]
    order = {m: i for i, m in enumerate(OWNER_MODULES)}
    for owner, d in sorted(DECLARED, key=lambda od: order.get(od[0].__module__, len(order))):
        rng = f"{_bound_text(d.lo)} - {_bound_text(d.hi)}" + (" (whole)" if d.integer else "")
        rows.append(f"| {d.name} | {rng} | {d.unit} | `{owner.__module__.removeprefix('autopilot_bridge.')}."
                    f"{owner.__name__}` | {d.doc} |")
    return "\n".join(rows)


if __name__ == "__main__":
    # Run as a script this file is a second module: the owners' classes register in the imported one.
    from autopilot_bridge import parameters

    print(parameters.markdown_table())
