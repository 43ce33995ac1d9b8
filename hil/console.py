"""Output conventions of `hil` commands: progress on stderr, the summary on stdout."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

from hil import settings
from hil.settings import HilConfig


def load_settings(args: argparse.Namespace) -> HilConfig:
    """The configuration named by ``--config`` with the ``--set`` overrides applied."""
    return settings.load(args.config, args.overrides)


def progress(message: str) -> None:
    """One line of human-readable progress on stderr."""
    print(message, file=sys.stderr, flush=True)


class ProgressBar:
    """Throttled progress for long work: ``done/total``, rate and ETA on stderr."""

    def __init__(self, total: int, label: str, every_s: float = 1.0) -> None:
        self.total, self.label, self.every_s = total, label, every_s
        self.start = self.last = time.monotonic()

    def update(self, done: int, extra: str = "") -> None:
        now = time.monotonic()
        if done < self.total and now - self.last < self.every_s:
            return
        self.last = now
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else math.inf
        eta_s = f"{eta:.0f}s" if math.isfinite(eta) else "?"
        progress(f"{self.label}: {done}/{self.total} ({rate:.1f}/s, ETA {eta_s}){' ' + extra if extra else ''}")


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return _jsonable(obj.item())
    return obj


def to_json(summary: dict[str, Any]) -> str:
    """Strict JSON (no NaN/Infinity tokens) of a summary dictionary."""
    return json.dumps(_jsonable(summary), allow_nan=False)


def _human(summary: dict[str, Any], indent: str = "") -> list[str]:
    lines = []
    for k, v in summary.items():
        if isinstance(v, dict):
            lines.append(f"{indent}{k}:")
            lines += _human(v, indent + "  ")
        elif isinstance(v, float):
            lines.append(f"{indent}{k}: {v:.6g}")
        elif isinstance(v, list) and len(v) > 8:
            lines.append(f"{indent}{k}: [{len(v)} items]")
        else:
            lines.append(f"{indent}{k}: {v}")
    return lines


def emit(args: argparse.Namespace, summary: dict[str, Any]) -> None:
    """Print the summary: one JSON object with ``--json``, readable lines otherwise."""
    if getattr(args, "json", False):
        print(to_json(summary), flush=True)
    else:
        print("\n".join(_human(summary)), flush=True)
