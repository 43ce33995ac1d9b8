"""Output conventions of `hil` commands: progress on stderr, the summary on stdout."""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:  # hil.settings pulls every component's config (filterpy, scipy): load it only when used
    from hil.settings import HilConfig


def load_settings(args: argparse.Namespace) -> HilConfig:
    """The configuration named by ``--config`` with the ``--set`` overrides applied. A scenario
    whose map is a chart (``--scenario``) puts the NED origin at its map's corner: the overrides
    that say so join ``args.overrides``, so the processes a command starts get them too."""
    from hil import settings
    from hil.charts import geodesy_overrides

    cfg = settings.load(args.config, args.overrides)
    extra = [o for o in geodesy_overrides(getattr(args, "scenario", None), cfg.geodesy) if o not in args.overrides]
    if extra:
        args.overrides = [*args.overrides, *extra]
        cfg = settings.load(args.config, args.overrides)
    return cfg


# The processes' packages log under their own names (``logging.getLogger(__name__)``); a `hil` command
# shows their INFO records as progress lines. User errors stay one line printed by hil.cli.main.
PROCESS_PACKAGES = ("hil", "simulator", "autopilot_bridge", "common")


class _StderrHandler(logging.StreamHandler):
    """Writes each record to the ``sys.stderr`` of the moment (a redirect, pytest's capture)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)
        self.setFormatter(logging.Formatter("%(message)s"))

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, _value: TextIO) -> None:
        pass


def configure_logging(level: int = logging.INFO) -> None:
    """Records of :data:`PROCESS_PACKAGES` at ``level`` and above on stderr, the bare message a line,
    as :func:`progress` writes (idempotent)."""
    for name in PROCESS_PACKAGES:
        logger = logging.getLogger(name)
        if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
            logger.addHandler(_StderrHandler())
        logger.setLevel(level)
        logger.propagate = False  # once on stderr, not again through a root handler


def progress(message: str) -> None:
    """One line of human-readable progress on stderr."""
    print(message, file=sys.stderr, flush=True)


class ProgressBar:
    """Throttled progress for long work: ``done/total``, rate and ETA on stderr. The first item done
    and the last are always reported: the first gives the first ETA, and says the work has begun."""

    def __init__(self, total: int, label: str, every_s: float = 1.0) -> None:
        self.total, self.label, self.every_s = total, label, every_s
        self.start = self.last = time.monotonic()

    def update(self, done: int, extra: str = "") -> None:
        now = time.monotonic()
        if 1 < done < self.total and now - self.last < self.every_s:
            return
        self.last = now
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else math.inf
        eta_s = f"{eta:.0f}s" if math.isfinite(eta) else "?"
        progress(f"{self.label}: {done}/{self.total} ({rate:.1f}/s, ETA {eta_s}){' ' + extra if extra else ''}")


def _jsonable(obj: object) -> object:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return _jsonable(obj.item())
    return obj


def to_json(summary: Mapping[str, object]) -> str:
    """Strict JSON (no NaN/Infinity tokens) of a summary dictionary."""
    return json.dumps(_jsonable(summary), allow_nan=False)


MAX_LINES = 15        # a human summary fits on a screen; everything else is in --json / summary.json
MAX_LINE_CHARS = 160  # and no line of it runs off the screen (an events list once made a 36 KB line)
MAX_LIST_SHOWN = 3


def clip(text: str, limit: int = MAX_LINE_CHARS) -> str:
    """``text`` cut to ``limit`` characters, saying how much was left out."""
    if len(text) <= limit:
        return text
    return text[: limit - 24] + f" ... (+{len(text) - limit + 24} chars)"


def fmt(v: object) -> str:
    """A value for a human line: numbers short, lists capped and counted."""
    if isinstance(v, bool) or v is None:
        return str(v).lower() if isinstance(v, bool) else "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        shown = ", ".join(fmt(x) for x in v[:MAX_LIST_SHOWN])
        return f"[{shown}{', ...' if len(v) > MAX_LIST_SHOWN else ''}] ({len(v)} items)" if len(v) > MAX_LIST_SHOWN \
            else f"[{shown}]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {fmt(x)}" for k, x in list(v.items())[:MAX_LIST_SHOWN]) + \
            (f", ... ({len(v)} keys)}}" if len(v) > MAX_LIST_SHOWN else "}")
    return str(v)


def _empty(v: object) -> bool:
    return v is None or v == "" or (isinstance(v, (list, tuple, dict)) and not v)


def nonzero_counters(d: object, prefix: str = "") -> list[str]:
    """``key=value`` for every non-zero integer counter in a nested summary (booleans excluded)."""
    out = []
    if isinstance(d, dict):
        for k, v in d.items():
            key = f"{prefix}{k}"
            if isinstance(v, dict):
                out += nonzero_counters(v, key + ".")
            elif isinstance(v, int) and not isinstance(v, bool) and v != 0:
                out.append(f"{key}={v}")
    return out


def wrap_items(label: str, items: list[str], max_lines: int) -> list[str]:
    """``label: a, b, c`` over at most ``max_lines`` lines of MAX_LINE_CHARS, the rest counted."""
    lines: list[str] = []
    cur = f"{label}:"
    for i, it in enumerate(items):
        piece = f" {it}" if cur.endswith(":") else f", {it}"
        room = MAX_LINE_CHARS - (16 if len(lines) == max_lines - 1 else 0)  # the last line keeps room for the count
        if len(cur) + len(piece) <= room:
            cur += piece
            continue
        if len(lines) == max_lines - 1:
            lines.append(f"{cur}, ... (+{len(items) - i} more)")
            return lines
        lines.append(cur)
        cur = "  " + it
    lines.append(cur)
    return lines


def brief(summary: Mapping[str, object], max_lines: int = MAX_LINES) -> list[str]:
    """A generic short summary: the top-level values that are set, one line each, nested tables
    as their non-zero counters; capped at ``max_lines`` with a pointer to --json."""
    lines = []
    for k, v in summary.items():
        if _empty(v):
            continue
        if isinstance(v, dict):
            counters = nonzero_counters(v)
            if counters:
                lines.append(clip(f"{k}: " + ", ".join(counters)))
            continue
        lines.append(clip(f"{k}: {fmt(v)}"))
    if len(lines) > max_lines:
        lines = lines[: max_lines - 1] + [f"... {len(lines) - max_lines + 1} more lines: use --json"]
    return lines


def emit(args: argparse.Namespace, summary: Mapping[str, object], human: list[str] | None = None) -> None:
    """Print the summary: one JSON object with ``--json``; otherwise ``human`` lines (a command's
    own short summary) or :func:`brief`, never more than MAX_LINES lines."""
    if getattr(args, "json", False):
        print(to_json(summary), flush=True)
    else:
        lines = human if human is not None else brief(summary)
        print("\n".join(clip(line) for line in lines[:MAX_LINES]), flush=True)
