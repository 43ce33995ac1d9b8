"""Where a pipelined lockstep run's processes run (hil.placement): the choice, and one line for a
bad --cpus (a whole placed run: tests/test_hil_loop.py). The CPU locks are real ``flock`` locks:
two open files of one process conflict as two runs do."""

from __future__ import annotations

import pytest

from hil import placement
from hil.errors import UsageError


@pytest.fixture
def four_cpus(monkeypatch, tmp_path):
    monkeypatch.setattr(placement, "usable", lambda: [2, 5, 7, 9])
    monkeypatch.setattr(placement, "_lock_dir", lambda: tmp_path)   # this test's own host-wide locks


def test_auto_places_a_lockstep_run_on_a_pair_no_other_run_holds(four_cpus):
    first = placement.claim("auto", lockstep=True)
    second = placement.claim("auto", lockstep=True)
    assert first is not None and first.placement == placement.Placement(2, 5)
    assert second is not None and second.placement == placement.Placement(7, 9)
    assert placement.claim("auto", lockstep=True) is None          # every pair held: left to the scheduler
    first.release()
    again = placement.claim("auto", lockstep=True)
    assert again is not None and again.placement == placement.Placement(2, 5)
    explicit = placement.Placement(9, 2)   # asked for: placed even where another run holds the CPUs
    held = placement.claim(explicit, lockstep=True)
    assert held is not None and held.placement == explicit
    as_text = placement.claim("9,2", lockstep=True)   # RunOptions(cpus="9,2") from code
    assert as_text is not None and as_text.placement == explicit
    as_text.release()
    for c in (second, again, held):
        c.release()


def test_real_time_off_and_one_cpu_are_never_placed(four_cpus, monkeypatch):
    assert placement.claim("auto", lockstep=False) is None
    assert placement.claim(placement.Placement(2, 5), lockstep=False) is None
    assert placement.claim("off", lockstep=True) is None
    monkeypatch.setattr(placement, "usable", lambda: [0])
    assert placement.claim("auto", lockstep=True) is None


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
