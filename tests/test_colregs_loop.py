"""Figure 12 in the whole HIL loop (lockstep, several seeds): ships sailed by the simulator and
reported by AIS, tracked, classified and avoided by the autopilot, judged from the truth."""

from __future__ import annotations

import json

import pytest

from hil.encounter_report import _corners, hulls_overlap


def _run(hil, tmp_path, scenario: str, seed: int) -> dict:
    out = tmp_path / f"{scenario}-{seed}"
    r = hil("run", "--json", "--out", str(out), "--no-plot", "--scenario", scenario, "--seed", str(seed), timeout=600)
    assert r.stdout.strip(), r.stderr
    s = json.loads(r.stdout.strip().splitlines()[-1])
    assert json.loads((out / "summary.json").read_text())["encounters"] == s["encounters"]
    return s


def _check_common(s: dict) -> dict:
    assert s["outcome"] == "goal" and s["collisions"] == 0, (s["outcome"], s["events"])
    (enc,) = s["encounters"]
    assert not enc["collision"]
    assert enc["cpa_m"] >= enc["safety_radius_m"], enc
    assert enc["compliant"], enc
    # The traffic reached the autopilot by AIS and went on to the ground-station link.
    t = s["traffic"]
    assert t["ais"]["accepted"] >= 5 and not t["ais"]["rejected"] and t["ais_forwarded_to_gcs"] == t["ais"]["accepted"]
    assert any(e.split(" ", 1)[1].startswith(f"COLREG {enc['mmsi']}") for e in s["events"])
    return enc


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_head_on_alters_to_starboard_and_passes_port_to_port(hil, tmp_path, seed):
    enc = _check_common(_run(hil, tmp_path, "colregs-head-on", seed))
    assert enc["type"] == "head-on" and enc["note"] == "port to port"
    assert enc["action"] == "starboard turn" and enc["max_starboard_deg"] >= 20.0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_crossing_from_right_gives_way_and_passes_astern(hil, tmp_path, seed):
    enc = _check_common(_run(hil, tmp_path, "colregs-crossing-right", seed))
    assert enc["type"] == "crossing-give-way" and enc["note"] == "passed astern of her"
    assert enc["action"] in ("starboard turn", "slow down")


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_overtaking_keeps_clear(hil, tmp_path, seed):
    enc = _check_common(_run(hil, tmp_path, "colregs-overtaking", seed))
    assert enc["type"] == "overtaking" and enc["action"] != "stand on"


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_crossing_from_left_stands_on_until_rule_17(hil, tmp_path, seed):
    s = _run(hil, tmp_path, "colregs-crossing-left", seed)
    enc = _check_common(s)
    assert enc["type"] == "crossing-stand-on" and enc["action"] != "port turn"
    # Kept course and speed until the give-way ship clearly failed (TCPA <= rule17_tcpa).
    assert enc["rule17_time_s"] is not None
    assert enc["action_time_s"] is None or enc["action_time_s"] >= enc["rule17_time_s"] - 1.0
    assert any("rule 17" in e for e in s["events"])


def test_hull_overlap_separating_axes():
    own = _corners(0.0, 0.0, 0.0, 1.0, 1.0, 0.5, 0.5)                  # 2 m x 1 m heading north
    assert hulls_overlap(own, _corners(2.9, 0.0, 3.14159, 2.0, 2.0, 1.0, 1.0))   # bows 0.1 m into each other
    assert not hulls_overlap(own, _corners(3.1, 0.0, 3.14159, 2.0, 2.0, 1.0, 1.0))
    # Beside each other 1.6 m apart (0.5 + 1.0 half-beams): no contact; rotated 45 deg it touches.
    assert not hulls_overlap(own, _corners(0.0, 1.6, 0.0, 2.0, 2.0, 1.0, 1.0))
    assert hulls_overlap(own, _corners(0.0, 1.6, 0.785398, 2.0, 2.0, 1.0, 1.0))
