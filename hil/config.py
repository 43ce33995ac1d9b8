"""Strict TOML configuration loading into typed, frozen dataclasses.

The section dataclasses live beside the code that uses them (``simulator.config``,
``planner.params`` ...); this module only knows how to fill any frozen dataclass from a TOML
table, strictly:

* an unknown key (with the nearest known one, difflib), a missing key or a value of the wrong
  type is an error;
* every real number is finite; per-field constraints come from the field's metadata (see
  :func:`param`): ``gt``, ``ge``, ``lt``, ``le`` bounds; a real without an upper (lower) bound
  must stay within MAX_MAGNITUDE (MAX_RADIANS for angles);
* cross-field rules live in the dataclass's ``__post_init__``, which raises ``ValueError``
  naming the offending key as ``"key: problem"``.

:func:`load` builds the table in layers (:class:`Layers`): ``configs/default.toml``, then each
``--config`` file (only the keys it changes), then each ``--set``. Every problem becomes one
:class:`~hil.errors.ConfigError` line ``SOURCE: section.key: problem``, SOURCE being the file or
the ``--set`` that gave the offending value.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar, get_args, get_origin

from common.params import ParamMeta
from common.tables import JsonTable, JsonValue
from common.tables import to_table as to_table  # the serialiser, re-exported
from hil.errors import ConfigError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")
D = TypeVar("D")   # a TypedDict

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "configs"
DEFAULT_CONFIG = CONFIG_DIR / "default.toml"


def _describe(tp: object) -> str:
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    return getattr(tp, "__name__", str(tp))


def _typed_table(value: JsonValue, tp: object, key: str) -> dict[str, object]:
    """A JSON table read as the TypedDict ``tp`` (a summary's section): every required key there,
    no unknown key, each value of its annotated type."""
    if not isinstance(value, dict):
        raise ValueError(f"{key}: expected a table, got {type(value).__name__}")
    hints = typing.get_type_hints(tp)
    where = f"{key}." if key else ""
    for k in value:
        if k not in hints:
            raise ValueError(f"{where}{k}: unknown key{suggest(k, list(hints))}")
    # NotRequired read from the hints: with postponed annotations __required_keys__ holds them all.
    marked = typing.get_type_hints(tp, include_extras=True)
    for k in hints:
        if k not in value and get_origin(marked[k]) is not typing.NotRequired:
            raise ValueError(f"{where}{k}: missing key")
    return {k: _convert(v, hints[k], f"{where}{k}") for k, v in value.items()}


def _fit(value: JsonValue, tp: object) -> int:
    """How well a table fits the TypedDict ``tp``: its keys that ``tp`` has less those it has not (a
    union of sections reports the error of the one the table was meant to be)."""
    if not (isinstance(value, dict) and typing.is_typeddict(tp)):
        return -(1 << 30)
    keys = set(typing.get_type_hints(tp))
    return sum(1 if k in keys else -1 for k in value)


def from_typed_table(tp: type[D], table: object, source: str) -> D:
    """A parsed JSON table read strictly as the TypedDict ``tp`` (a process's summary): every required
    key, no unknown key, each value of its type; ConfigError ``SOURCE: key: problem`` otherwise."""
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: expected a JSON object, got {type(table).__name__}")
    try:
        return typing.cast(D, _typed_table(table, tp, ""))
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def _convert(value: JsonValue, tp: object, key: str) -> object:
    """Convert a TOML value to the annotated type ``tp`` or raise ``ValueError('key: problem')``."""
    origin = get_origin(tp)
    if tp is Any or tp is object:   # a value checked where it is used (a scenario's overrides of a section)
        return value
    if tp is type(None):  # JSON's null (summaries); TOML has none
        if value is not None:
            raise ValueError(f"{key}: expected null, got {value!r}")
        return None
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table, got {type(value).__name__}")
        return _build(tp, value, key)
    if typing.is_typeddict(tp):
        return _typed_table(value, tp, key)
    if origin is list:
        if not isinstance(value, list):
            raise ValueError(f"{key}: expected an array, got {type(value).__name__}")
        (item,) = get_args(tp)
        return [_convert(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            raise ValueError(f"{key}: must be one of {', '.join(map(repr, choices))} (got {value!r})")
        return value
    if origin in (typing.Union, types.UnionType):
        errors = []
        alts = get_args(tp)
        for alt in alts:
            try:
                return _convert(value, alt, key)
            except ValueError as exc:
                errors.append(str(exc))
        best = max(range(len(alts)), key=lambda i: (_fit(value, alts[i]), -i))
        raise ValueError(errors[best])
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list):
            raise ValueError(f"{key}: expected an array, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ValueError(f"{key}: expected an array of {len(args)} items, got {len(value)}")
        return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=False)))
    if origin is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table, got {type(value).__name__}")
        kt, vt = get_args(tp)
        return {_convert(k, kt, key): _convert(v, vt, f"{key}.{k}") for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"{key}: must be a finite number (got {value})")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{key}: expected a string, got {value!r}")
        return value
    raise TypeError(f"{key}: unsupported field type {tp!r}")  # a bug in a schema, not user input


# A real number this large in a field without an upper bound is a mistake (and 1e300 radians hangs
# an angle wrap): the whole project lives within a few kilometres and hours. Integers (seeds, ids,
# counts) are exact and keep only their declared bounds.
MAX_MAGNITUDE = 1e9
MAX_RADIANS = 1e3


# Physical ranges (issue 31) that close what a schema leaves open, for the keys where an extreme but
# schema-valid value stalls or overflows a run: time steps, rates, periods and timeouts that set the
# work per simulated or wall second, and iteration and size caps. (low, high) in the key's unit, both
# inclusive. Every other real number keeps its schema bounds and |value| <= MAX_MAGNITUDE; every other
# integer its schema bounds and |value| <= MAX_INTEGER. `range_of` gives a key's effective range and
# docs/configuration-ranges.md lists them all (tests/test_config_ranges.py keeps it in step).
PHYSICAL_RANGES: dict[str, tuple[float, float]] = {
    # RK4 step: finer than 1 ms changes nothing for a boat (time constants >= 1 s) and only slows lockstep
    # (sim.dt = 1e-9 advanced no simulated time in 62 s of wall time)
    "sim.dt": (1e-3, 0.1),
    "sim.duration": (0.0, 1e6),
    "sim.speedup": (1e-3, 1e3),
    "sim.truth_rate_hz": (0.1, 1000.0),
    "sim.stale_command_timeout": (1e-3, 60.0),
    "sim.lockstep_resend": (1e-3, 60.0),
    # one lockstep frame per IMU period: below 1 Hz a single frame is more than a second of RK4 steps
    "sensors.imu.rate_hz": (1.0, 1000.0),
    "sensors.gps.rate_hz": (0.1, 50.0),
    "sensors.gps.latency": (0.0, 10.0),
    "sensors.gps.dropout_rate": (0.0, 100.0),
    "sensors.dvl.rate_hz": (0.1, 50.0),
    "sensors.rangefinder.rate_hz": (0.1, 50.0),
    "waves.correlation_time": (0.1, 1e6),
    "autopilot.planning_period": (0.05, 60.0),
    "autopilot.planning_deadline": (0.01, 60.0),
    "autopilot.watchdog_grace": (0.01, 60.0),
    # the planner does >= 15,000 iterations/s on the slowest map measured (docs/planner.md), so 100,000
    # iterations fit the default 20 s lockstep_planner_timeout with room; 1e12 stalled a run (issue 31)
    "autopilot.lockstep_iterations": (1, 100_000),
    "autopilot.lockstep_planner_timeout": (0.1, 600.0),
    "autopilot.sim_restart_gap": (0.01, 3600.0),
    "autopilot.sensed_confirm_hits": (1, 1000),
    "planner.max_nodes": (2, 2_000_000),
    "planner.png_max_iterations": (1, 1_000_000),
    "navigation.reset_after_rejections": (1, 10_000),
    "tracking.max_targets": (1, 1000),
    "tracking.confirm_reports": (1, 1000),
    "traffic.interval_slow": (0.1, 3600.0),
    "traffic.interval_turning": (0.1, 3600.0),
    "traffic.interval_fast": (0.1, 3600.0),
    "traffic.interval_very_fast": (0.1, 3600.0),
    "colregs.horizon": (1.0, 3600.0),
    "can.lockstep_wait": (1e-3, 60.0),
    "can.socket_rx_buffer": (0, 1 << 26),
    "gcs.pace_speedup": (0.1, 1e3),
    "gcs.failsafe_timeout": (0.1, 3600.0),
    "gcs.mission_timeout": (0.01, 10.0),
    "gcs.mission_retries": (0, 100),
}
MAX_INTEGER = (1 << 63) - 1   # seeds are 64-bit; counts have their own cap in PHYSICAL_RANGES


def range_of(key: str, meta: ParamMeta, tp: object = float) -> tuple[float, float]:
    """The inclusive (low, high) a number at dotted ``key`` may take (an open schema bound ``gt``/``lt``
    is reported as its value); array indices in ``key`` are ignored."""
    base = key.split("[", 1)[0]
    limit = MAX_INTEGER if tp is int else (MAX_RADIANS if meta.get("unit") == "rad" else MAX_MAGNITUDE)
    low = next((meta[k] for k in ("ge", "gt") if meta.get(k) is not None), -limit)
    high = next((meta[k] for k in ("le", "lt") if meta.get(k) is not None), limit)
    if base in PHYSICAL_RANGES:
        lo, hi = PHYSICAL_RANGES[base]
        low, high = max(low, lo), min(high, hi)
    return low, high


def _check_range(value: object, meta: ParamMeta, key: str) -> None:
    """PHYSICAL_RANGES and MAX_INTEGER (the schema's bounds are :func:`_check_bounds`'s)."""
    base = key.split("[", 1)[0]
    values = value if isinstance(value, tuple) else (value,)
    for v in values:
        if isinstance(v, tuple):
            _check_range(v, meta, key)
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        unit = f" {meta['unit']}" if meta.get("unit") else ""
        if base in PHYSICAL_RANGES:
            lo, hi = PHYSICAL_RANGES[base]
            if not lo <= v <= hi:
                raise ValueError(f"{key}: {v:g}{unit} is out of range [{lo:g}, {hi:g}]{unit}")
        elif isinstance(v, int) and abs(v) > MAX_INTEGER:
            raise ValueError(f"{key}: {v} is out of range (|value| <= 2^63 - 1)")


def _check_bounds(value: object, meta: ParamMeta, key: str) -> None:
    values = value if isinstance(value, tuple) else (value,)
    for v in values:
        if isinstance(v, tuple):
            _check_bounds(v, meta, key)
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        unit = f" {meta['unit']}" if meta.get("unit") else ""
        for name, op, text in (
            ("gt", lambda a, b: a > b, ">"),
            ("ge", lambda a, b: a >= b, ">="),
            ("lt", lambda a, b: a < b, "<"),
            ("le", lambda a, b: a <= b, "<="),
        ):
            bound = meta.get(name)
            if bound is not None and not op(v, bound):
                raise ValueError(f"{key}: must be {text} {bound}{unit} (got {v})")
        limit = MAX_RADIANS if meta.get("unit") == "rad" else MAX_MAGNITUDE
        upper = meta.get("lt") is not None or meta.get("le") is not None
        lower = meta.get("gt") is not None or meta.get("ge") is not None
        if isinstance(v, float) and ((v > limit and not upper) or (-v > limit and not lower)):
            raise ValueError(f"{key}: {v:g}{unit} is out of range (|value| <= {limit:g})")


def suggest(word: str, choices: typing.Iterable[str], or_list: bool = True) -> str:
    """" (did you mean 'X'?)" for the nearest of ``choices`` to ``word`` (difflib); without a close
    one, " (expected one of: ...)" (``or_list``) or ""."""
    choices = list(choices)
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if close:
        return f" (did you mean {close[0]!r}?)"
    return f" (expected one of: {', '.join(choices)})" if or_list and choices else ""


def _build(cls: type[T], table: JsonTable, prefix: str) -> T:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for k in table:
        if k not in fields:
            where = f"{prefix}.{k}" if prefix else k
            raise ValueError(f"{where}: unknown key{suggest(k, fields)}")
    kwargs = {}
    for name, f in fields.items():
        where = f"{prefix}.{name}" if prefix else name
        if name not in table:
            if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING:
                continue
            raise ValueError(f"{where}: missing key")
        value = _convert(table[name], hints[name], where)
        _check_bounds(value, f.metadata, where)
        _check_range(value, f.metadata, where)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(f"{prefix}.{msg}" if prefix else msg) from None


def from_table(cls: type[T], table: JsonTable, source: str | typing.Callable[[str], str],
               prefix: str = "") -> T:
    """Build dataclass ``cls`` from a parsed TOML table; errors name the source and the key.

    ``source`` is a file name, or a function from the offending dotted key to the file or
    ``--set`` that gave it (layered configurations).
    """
    try:
        return _build(cls, table, prefix)
    except ValueError as exc:
        msg = str(exc)
        where = source(msg.partition(":")[0]) if callable(source) else source
        raise ConfigError(f"{where}: {msg}") from None


def parse_override(text: str) -> tuple[list[str], JsonValue]:
    """Parse ``section.key=value`` (value in TOML syntax; a bare word is taken as a string)."""
    if "=" not in text:
        raise ConfigError(f"--set {text}: expected section.key=value")
    path, raw = text.split("=", 1)
    keys = [k.strip() for k in path.strip().split(".")]
    if not all(keys):
        raise ConfigError(f"--set {text}: expected section.key=value")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return keys, value


def _schema_names(cls: object, keys: list[str]) -> tuple[int, list[str]]:
    """Walk ``keys`` down dataclass ``cls``: (index of the first unknown key or -1, the names valid there)."""
    tp = cls
    for i, k in enumerate(keys):
        if not dataclasses.is_dataclass(tp):
            return -1, []  # a free-form table (dict) or a value below here
        names = [f.name for f in dataclasses.fields(tp) if f.init]
        if k not in names:
            return i, names
        tp = typing.get_type_hints(tp)[k]
        if get_origin(tp) in (typing.Union, types.UnionType):
            tp = next((a for a in get_args(tp) if dataclasses.is_dataclass(a)), tp)
    return -1, []


class Layers:
    """A configuration table built in layers, remembering which layer gave each key.

    The first layer is the defaults file; each ``--config`` file is laid over it key by key (a
    file holds only the keys it changes; a table merges, any other value replaces), then each
    ``--set`` in order.
    """

    def __init__(self, cls: type[DataclassInstance]) -> None:
        self.cls = cls
        self.table: JsonTable = {}
        self.origin: dict[str, str] = {}

    def _merge(self, node: JsonTable, layer: JsonTable, prefix: str, source: str) -> None:
        for k, v in layer.items():
            key = f"{prefix}{k}"
            if isinstance(v, dict) and isinstance(node.get(k), dict):
                self._merge(node[k], v, key + ".", source)
            else:
                node[k] = v
            self.origin[key] = source

    def add_file(self, path: str | Path, check: bool = True) -> None:
        layer = read_toml(path)
        if check:
            self._check(layer, [], str(path))
        self._merge(self.table, layer, "", str(path))

    def _check(self, layer: JsonTable, keys: list[str], source: str) -> None:
        for k, v in layer.items():
            bad, names = _schema_names(self.cls, keys + [k])
            if bad >= 0:
                raise ConfigError(f"{source}: {'.'.join(keys + [k])}: unknown key{suggest(k, names)}")
            if isinstance(v, dict):
                self._check(v, keys + [k], source)

    def add_override(self, text: str) -> None:
        keys, value = parse_override(text)
        bad, names = _schema_names(self.cls, keys)
        if bad >= 0:
            raise ConfigError(f"--set {text}: unknown key {'.'.join(keys[: bad + 1])}{suggest(keys[bad], names)}")
        node = self.table
        for k in keys[:-1]:
            if not isinstance(node.get(k), dict):
                node[k] = {}
            node = node[k]
        node[keys[-1]] = value
        self.origin[".".join(keys)] = f"--set {text}"

    def source_of(self, key: str) -> str:
        """The file or ``--set`` that gave ``key`` (its nearest given parent for a missing key)."""
        parts = [p.partition("[")[0] for p in key.split(".")]
        for n in range(len(parts), 0, -1):
            src = self.origin.get(".".join(parts[:n]))
            if src is not None:
                return src
        return str(DEFAULT_CONFIG)


def read_toml(path: str | Path) -> JsonTable:
    """Read a TOML file, turning every I/O or syntax problem into a one-line ConfigError."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise ConfigError(f"{p}: is a directory, not a TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read: {exc}") from None


def config_files(path: str | Path | typing.Sequence[str | Path] | None) -> list[Path]:
    """``--config`` as a list of files (one, several in order, or none)."""
    if path is None:
        return []
    if isinstance(path, (str, Path)):
        return [Path(path)]
    return [Path(p) for p in path]


def config_args(path: str | Path | typing.Sequence[str | Path] | None) -> list[str]:
    """``--config`` options that give a child process the same configuration files."""
    return [a for p in config_files(path) for a in ("--config", str(p))]


def load(cls: type[T], path: str | Path | typing.Sequence[str | Path] | None = None,
         overrides: list[str] | None = None) -> T:
    """``configs/default.toml``, then each ``--config`` file laid over it, then the ``--set`` overrides.

    A file need hold only the keys it changes; a complete file (a copy of ``configs/default.toml``)
    works as before. Every error names the file or ``--set`` that gave the offending value, and an
    unknown key the nearest known one.
    """
    layers = Layers(cls)
    layers.add_file(DEFAULT_CONFIG, check=False)
    for p in config_files(path):
        layers.add_file(p)
    for text in overrides or []:
        layers.add_override(text)
    return from_table(cls, layers.table, layers.source_of)


def key_ranges(cls: type, prefix: str = "") -> list[tuple[str, str, float, float, str]]:
    """(key, type, low, high, unit) of every number (or array of numbers) in a config dataclass, recursively."""
    out: list[tuple[str, str, float, float, str]] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp, key = hints[f.name], f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            out += key_ranges(typing.cast(type, tp), key + ".")
            continue
        leaf = tp
        while get_origin(leaf) is tuple:
            leaf = get_args(leaf)[0]
        if leaf in (int, float):
            low, high = range_of(key, f.metadata, leaf)
            out.append((key, leaf.__name__ if leaf is tp else f"array of {leaf.__name__}", low, high,
                        f.metadata.get("unit", "")))
    return out


def _bound_text(value: float, meta: ParamMeta, strict: str, key: str) -> str:
    """``> 0`` where the schema's strict bound is the effective one, else the number."""
    base = key.split("[", 1)[0]
    tightened = base in PHYSICAL_RANGES and value in PHYSICAL_RANGES[base]
    return f"> {value:g}" if strict == "gt" and meta.get("gt") == value and not tightened else (
        f"< {value:g}" if strict == "lt" and meta.get("lt") == value and not tightened else f"{value:g}")


def range_table(cls: type) -> str:
    """The markdown table of :func:`key_ranges` (docs/configuration-ranges.md)."""
    metas = _metas(cls)
    rows = ["| key | type | low | high | unit |", "| --- | --- | ---: | ---: | --- |"]
    rows += [f"| `{k}` | {t} | {_bound_text(lo, metas[k], 'gt', k)} | {_bound_text(hi, metas[k], 'lt', k)} | {u} |"
             for k, t, lo, hi, u in key_ranges(cls)]
    return "\n".join(rows) + "\n"


def _metas(cls: type, prefix: str = "") -> dict[str, ParamMeta]:
    out: dict[str, ParamMeta] = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            out.update(_metas(typing.cast(type, tp), f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = f.metadata
    return out


def field_docs(cls: type[DataclassInstance]) -> list[tuple[str, str, str]]:
    """(key, unit, help) for every field of a config dataclass, recursively, for --help texts."""
    out = []
    for f in dataclasses.fields(cls):
        if not f.init:   # computed from the others (e.g. gcs.connections), never written
            continue
        tp = typing.get_type_hints(cls)[f.name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out += [(f"{f.name}.{k}", u, h) for k, u, h in field_docs(tp)]
        else:
            out.append((f.name, f.metadata.get("unit", ""), f.metadata.get("help", "")))
    return out
