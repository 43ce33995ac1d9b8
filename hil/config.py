"""Strict TOML configuration loading into typed, frozen dataclasses.

The section dataclasses live beside the code that uses them (``simulator.config``,
``planner.params`` ...); this module only knows how to fill any frozen dataclass from a TOML
table, strictly:

* an unknown key, a missing key or a value of the wrong type is an error;
* per-field constraints come from the field's metadata (see :func:`param`): ``gt``, ``ge``,
  ``lt``, ``le`` bounds and ``choices``;
* cross-field rules live in the dataclass's ``__post_init__``, which raises ``ValueError``
  naming the offending key as ``"key: problem"``.

Every problem becomes one :class:`~hil.errors.ConfigError` line ``FILE: section.key: problem``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

from common.params import param  # noqa: F401  (re-exported for schemas)
from hil.errors import ConfigError

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "configs"
DEFAULT_CONFIG = CONFIG_DIR / "default.toml"


def _describe(tp: Any) -> str:
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    return getattr(tp, "__name__", str(tp))


def _convert(value: Any, tp: Any, key: str) -> Any:
    """Convert a TOML value to the annotated type ``tp`` or raise ``ValueError('key: problem')``."""
    origin = get_origin(tp)
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table, got {type(value).__name__}")
        return _build(tp, value, key)
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            raise ValueError(f"{key}: must be one of {', '.join(map(repr, choices))} (got {value!r})")
        return value
    if origin in (typing.Union, types.UnionType):
        errors = []
        for alt in get_args(tp):
            try:
                return _convert(value, alt, key)
            except ValueError as exc:
                errors.append(str(exc))
        raise ValueError(errors[0])
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list):
            raise ValueError(f"{key}: expected an array, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ValueError(f"{key}: expected an array of {len(args)} items, got {len(value)}")
        return tuple(_convert(v, a, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{key}: expected a table, got {type(value).__name__}")
        kt, vt = get_args(tp)
        return {_convert(k, kt, key): _convert(v, vt, f"{key}.{k}") for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key}: expected a number, got {value!r}")
        value = float(value)
        if math.isnan(value):
            raise ValueError(f"{key}: must not be NaN")
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


def _check_bounds(value: Any, meta: typing.Mapping[str, Any], key: str) -> None:
    values = value if isinstance(value, tuple) else (value,)
    for v in values:
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        for name, op, text in (
            ("gt", lambda a, b: a > b, ">"),
            ("ge", lambda a, b: a >= b, ">="),
            ("lt", lambda a, b: a < b, "<"),
            ("le", lambda a, b: a <= b, "<="),
        ):
            bound = meta.get(name)
            if bound is not None and not op(v, bound):
                unit = f" {meta['unit']}" if meta.get("unit") else ""
                raise ValueError(f"{key}: must be {text} {bound}{unit} (got {v})")


def _build(cls: type[T], table: dict[str, Any], prefix: str) -> T:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for k in table:
        if k not in fields:
            where = f"{prefix}.{k}" if prefix else k
            raise ValueError(f"{where}: unknown key (expected one of: {', '.join(fields)})")
    kwargs = {}
    for name, f in fields.items():
        where = f"{prefix}.{name}" if prefix else name
        if name not in table:
            if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING:
                continue
            raise ValueError(f"{where}: missing key")
        value = _convert(table[name], hints[name], where)
        _check_bounds(value, f.metadata, where)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(f"{prefix}.{msg}" if prefix else msg) from None


def from_table(cls: type[T], table: dict[str, Any], source: str, prefix: str = "") -> T:
    """Build dataclass ``cls`` from a parsed TOML table; errors name ``source`` and the key."""
    try:
        return _build(cls, table, prefix)
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def parse_override(text: str) -> tuple[list[str], Any]:
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


def apply_overrides(table: dict[str, Any], overrides: list[str]) -> None:
    """Apply ``--set`` overrides in place; a key that does not exist in the file is an error."""
    for text in overrides:
        keys, value = parse_override(text)
        node = table
        for i, k in enumerate(keys[:-1]):
            if not isinstance(node.get(k), dict):
                raise ConfigError(f"--set {text}: unknown key {'.'.join(keys[: i + 1])}")
            node = node[k]
        if keys[-1] not in node:
            raise ConfigError(f"--set {text}: unknown key {'.'.join(keys)}")
        node[keys[-1]] = value


def read_toml(path: str | Path) -> dict[str, Any]:
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


def load(cls: type[T], path: str | Path | None = None, overrides: list[str] | None = None) -> T:
    """Load a whole configuration file (default ``configs/default.toml``) into ``cls``."""
    p = Path(path) if path is not None else DEFAULT_CONFIG
    table = read_toml(p)
    apply_overrides(table, list(overrides or []))
    return from_table(cls, table, str(p))


def to_table(obj: Any) -> Any:
    """A dataclass instance back to plain TOML-able data (for run folders and --json)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_table(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple):
        return [to_table(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_table(v) for k, v in obj.items()}
    return obj


def field_docs(cls: type) -> list[tuple[str, str, str]]:
    """(key, unit, help) for every field of a config dataclass, recursively, for --help texts."""
    out = []
    for f in dataclasses.fields(cls):
        tp = typing.get_type_hints(cls)[f.name]
        if dataclasses.is_dataclass(tp):
            out += [(f"{f.name}.{k}", u, h) for k, u, h in field_docs(tp)]
        else:
            out.append((f.name, f.metadata.get("unit", ""), f.metadata.get("help", "")))
    return out
