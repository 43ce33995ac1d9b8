"""Where scenarios live and which exist: a light module (no numpy), for help texts."""

from __future__ import annotations

from hil.config import CONFIG_DIR

SCENARIO_DIR = CONFIG_DIR / "scenarios"


def available(kind: str | None = None) -> list[str]:
    """Names of the scenarios in configs/scenarios/ (the file stems, sorted); ``kind`` ('fixed' or
    'random'): only those whose ``kind`` line says so (read as text: help texts stay light)."""
    import re

    names = []
    for p in SCENARIO_DIR.glob("*.toml"):
        if kind is not None:
            m = re.search(r'^kind\s*=\s*"(\w+)"', p.read_text(encoding="utf-8", errors="replace"), re.M)
            if m is None or m.group(1) != kind:
                continue
        names.append(p.stem)
    return sorted(names)
