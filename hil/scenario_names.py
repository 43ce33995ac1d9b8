"""Where scenarios live and which exist: a light module (no numpy), for help texts."""

from __future__ import annotations

from hil.config import CONFIG_DIR

SCENARIO_DIR = CONFIG_DIR / "scenarios"


def available() -> list[str]:
    """Names of the scenarios in configs/scenarios/ (the file stems, sorted)."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))
