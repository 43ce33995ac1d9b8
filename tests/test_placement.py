"""Where a pipelined lockstep run's processes run (hil.placement): the choice, and one line for a
bad --cpus (a whole placed run: tests/test_hil_loop.py)."""

from __future__ import annotations

import pytest

from hil import placement
from hil.errors import UsageError


def test_auto_places_only_a_pipelined_lockstep_run_on_two_cpus(monkeypatch):
    monkeypatch.setattr(placement, "usable", lambda: [2, 5, 7])
    assert placement.choose("auto", lockstep=True, pipelined=True) == placement.Placement(2, 5)
    assert placement.choose("auto", lockstep=True, pipelined=False) is None
    assert placement.choose("auto", lockstep=False, pipelined=True) is None
    assert placement.choose("off", lockstep=True, pipelined=True) is None
    explicit = placement.Placement(7, 2)
    assert placement.choose(explicit, lockstep=True, pipelined=False) == explicit  # asked for: placed
    assert placement.choose(explicit, lockstep=False, pipelined=False) is None     # real time: never
    monkeypatch.setattr(placement, "usable", lambda: [0])
    assert placement.choose("auto", lockstep=True, pipelined=True) is None         # one CPU


@pytest.mark.parametrize("spec", ["0", "0,0", "1,2,3", "a,b", "0,999", "-1,0", "fast"])
def test_a_bad_cpus_spec_is_one_line(monkeypatch, spec):
    monkeypatch.setattr(placement, "usable", lambda: [0, 1])
    with pytest.raises(UsageError) as e:
        placement.parse(spec)
    assert "--cpus" in str(e.value) and "\n" not in str(e.value)


def test_a_good_cpus_spec(monkeypatch):
    monkeypatch.setattr(placement, "usable", lambda: [0, 1, 3])
    assert placement.parse(" AUTO ") == "auto" and placement.parse("off") == "off"
    assert placement.parse("3,0") == placement.Placement(3, 0)


def test_hil_run_refuses_a_bad_cpus_in_one_line(hil):
    r = hil("run", "--pipeline", "--cpus", "0,0", "--duration", "1", timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--cpus 0,0: two different CPUs" in r.stderr
