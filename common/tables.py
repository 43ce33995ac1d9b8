"""Frozen dataclasses to plain TOML/JSON-able tables, for what crosses a process boundary or goes on disk.

:func:`to_table` is the one serialiser of the project's dataclasses (configuration, the autopilot's
and the run's summaries); the strict reader, ``from_table``, lives in :mod:`hil.config`. A field made
with :func:`absent_when_none` is left out of the table while it is None, so that optional sections
of a summary appear only when they exist, as they always have on disk.
"""

from __future__ import annotations

import dataclasses
from typing import Any, TypeAlias

_ABSENT_WHEN_NONE = "absent_when_none"
_DERIVED = "derived"

# A value of a JSON or TOML document: a table, an array, text, a number or a bool (JSON: null too). Its
# shape is the document's: a file's is checked where it is read (hil.config's strict readers); a report
# built to be written (a benchmark's, a soak's) is read back by key. So to mypy it is Any, project-wide.
JsonValue: TypeAlias = Any
JsonTable: TypeAlias = dict[str, JsonValue]


def absent_when_none() -> Any:   # a field specifier: Any, as dataclasses.field's own
    """A field defaulting to None that :func:`to_table` leaves out while it is None (the reader
    then takes the default back)."""
    return dataclasses.field(default=None, metadata={_ABSENT_WHEN_NONE: True})


def derived() -> dict[str, bool]:
    """The metadata of a field computed from the others (``init=False``): :func:`to_table` leaves it
    out, as the reader computes it again."""
    return {_DERIVED: True}


def to_table(obj: object) -> JsonValue:
    """A dataclass instance back to plain TOML-able data (for run folders and --json)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_table(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not f.metadata.get(_DERIVED)
                and not (f.metadata.get(_ABSENT_WHEN_NONE) and getattr(obj, f.name) is None)}
    if isinstance(obj, tuple):
        return [to_table(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_table(v) for k, v in obj.items()}
    return obj
