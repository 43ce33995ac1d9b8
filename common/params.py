"""Documented, bounded dataclass fields for configuration schemas (checked by ``hil.config``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeAlias

# A dataclass field's metadata as :func:`param` writes it: ``help`` and ``unit`` (str), ``gt``, ``ge``,
# ``lt``, ``le`` (float or None). typeshed types ``Field.metadata`` as a mapping of Any.
ParamMeta: TypeAlias = Mapping[str, Any]


def param(
    help: str = "",
    unit: str = "",
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    default: object = dataclasses.MISSING,
) -> Any:   # a field specifier: Any, as dataclasses.field's own
    """A dataclass field with its meaning (``help``), SI ``unit`` and bounds checked on load.

    The metadata keys are a plain convention (``help``, ``unit``, ``gt``, ``ge``, ``lt``,
    ``le``), so a library that may not import this module (the planner) can use the same keys.
    """
    meta = {"help": help, "unit": unit, "gt": gt, "ge": ge, "lt": lt, "le": le}
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata=meta)
    return dataclasses.field(default=default, metadata=meta)
