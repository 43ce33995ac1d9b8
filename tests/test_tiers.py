"""The test tiers of tests/conftest.py: every module in exactly one, and `slow` is e2e."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import E2E_MODULES, INTEGRATION_MODULES, UNIT_MODULES, tier_of

TESTS = Path(__file__).resolve().parent


def test_every_test_module_is_in_exactly_one_tier():
    modules = {p.stem.removeprefix("test_") for p in TESTS.glob("test_*.py")}
    listed = [UNIT_MODULES, INTEGRATION_MODULES, E2E_MODULES]
    for m in sorted(modules):
        assert sum(m in tier for tier in listed) == 1, m
    assert set().union(*listed) == modules, "a tier lists a module that does not exist"


def test_slow_is_e2e_and_unknown_modules_are_refused():
    assert tier_of("geodesy", slow=False) == "unit"
    assert tier_of("geodesy", slow=True) == "e2e"
    assert tier_of("sim_udp", slow=False) == "integration"
    with pytest.raises(pytest.UsageError, match="no test tier"):
        tier_of("not_a_module", slow=False)
