"""Positions in latitude/longitude: scenarios with positions = "latlon", `hil geo` conversions, and a
scenario's route written as a QGroundControl .plan."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from common.geodesy import LocalFrame
from hil import scenario as scenarios
from hil.config import CONFIG_DIR
from hil.errors import ConfigError

FRAME = LocalFrame(38.92, 121.65)   # configs/default.toml [geodesy]
METRES = """name = "t"
description = "open water with a ship"
kind = "fixed"
map = "{map}"
resolution = 0.5
start = {start}
goal = {goal}
reference_path = {route}
uncharted = [[{disc}, 2.0]]
{extra}
[current]
enabled = false

[[traffic]]
mmsi = 412000104
start = {ship}
speed = 1.0
waypoints = [{ship_wp}]
"""


def _ll(x: float, y: float) -> list[float]:
    lat, lon = FRAME.sea_level_to_geodetic(y, x)
    return [lat, lon]


def _write(tmp_path: Path, name: str, latlon: bool) -> Path:
    pts = {"start": (20.0, 60.0), "goal": (180.0, 60.0), "disc": (100.0, 30.0), "ship": (100.0, 115.0),
           "ship_wp": (100.0, 5.0)}
    route = [(20.0, 60.0), (100.0, 70.0), (180.0, 60.0)]
    conv = _ll if latlon else (lambda x, y: [x, y])
    fields = {k: json.dumps(conv(*v)) for k, v in pts.items()}
    fields["disc"] = fields["disc"][1:-1]
    fields["route"] = json.dumps([conv(*p) for p in route])
    text = METRES.format(map=CONFIG_DIR / "maps" / "open_water.npy",
                         extra='positions = "latlon"' if latlon else "", **fields)
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_scenario_in_latitude_longitude_is_the_scenario_in_metres(tmp_path):
    a = scenarios.load(str(_write(tmp_path, "m.toml", False)))
    b = scenarios.load(str(_write(tmp_path, "ll.toml", True)))
    assert b.start == pytest.approx(a.start, abs=1e-6) and b.goal == pytest.approx(a.goal, abs=1e-6)
    np.testing.assert_allclose(b.waypoints, a.waypoints, atol=1e-6)
    np.testing.assert_allclose(b.reference_path, a.reference_path, atol=1e-6)
    assert b.uncharted[0] == pytest.approx(a.uncharted[0], abs=1e-6)
    assert b.traffic[0].start == pytest.approx(a.traffic[0].start, abs=1e-6)
    assert b.traffic[0].waypoints[0] == pytest.approx(a.traffic[0].waypoints[0], abs=1e-6)


@pytest.mark.parametrize("start, message", [
    ("[121.65, 38.92]", "not \\[latitude, longitude\\] in degrees"),     # swapped: 121.65 is no latitude
    ("[38.92, 121.0]", "km from the map's origin .* swapped\\?"),
])
def test_latitude_longitude_mistakes_are_one_line(tmp_path, start, message):
    p = _write(tmp_path, "ll.toml", True)
    p.write_text(re.sub(r"^start = .*$", f"start = {start}", p.read_text(), count=1, flags=re.M))
    with pytest.raises(ConfigError, match=message) as err:
        scenarios.load(str(p))
    assert "\n" not in str(err.value)


def test_hil_geo_converts_both_ways(hil_main):
    r = hil_main("geo", "--scenario", "harbour", "--to-latlon", "22,40", "--to-metres", "38.9212611,121.6521332",
                 "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    x, y, lat, lon = out["to_latlon"][0]
    assert (lat, lon) == pytest.approx(FRAME.sea_level_to_geodetic(40.0, 22.0), abs=1e-12)
    assert out["to_metres"][0][2:] == pytest.approx([185.0, 140.0], abs=0.01)   # the harbour's goal
    bad = hil_main("geo", "--to-metres", "1,2,3")
    assert bad.returncode == 2 and "expected LAT,LON" in bad.stderr and "Traceback" not in bad.stderr


def test_hil_geo_writes_the_route_as_a_qgc_plan(hil_main, tmp_path):
    plan = tmp_path / "harbour.plan"
    r = hil_main("geo", "--scenario", "harbour", "--plan", str(plan))
    assert r.returncode == 0, r.stderr
    doc = json.loads(plan.read_text())
    assert doc["fileType"] == "Plan" and doc["groundStation"] == "QGroundControl"
    mission = doc["mission"]
    assert mission["version"] == 2 and mission["vehicleType"] == 11    # MAV_TYPE_SURFACE_BOAT
    scen = scenarios.load("harbour")
    assert len(mission["items"]) == len(scen.reference_path)
    for item, (x, y) in zip(mission["items"], scen.reference_path, strict=True):
        assert item["type"] == "SimpleItem" and item["command"] == 16 and item["frame"] == 3
        n, e = FRAME.geodetic_to_sea_level(item["params"][4], item["params"][5])
        assert (e, n) == pytest.approx((x, y), abs=1e-6)
    home = mission["plannedHomePosition"]
    assert FRAME.geodetic_to_sea_level(home[0], home[1]) == pytest.approx((40.0, 22.0), abs=1e-6)
    bad = hil_main("geo", "--scenario", "harbour", "--plan", str(tmp_path / "x.txt"))
    assert bad.returncode == 2 and "unknown file type .txt" in bad.stderr


def test_the_hil_geo_examples_of_docs_worlds_run(hil_main, tmp_path, monkeypatch):
    """docs/worlds.md's `hil geo` lines, as written (a --plan file lands in a temporary folder)."""
    import shlex

    monkeypatch.chdir(tmp_path)
    text = (Path(__file__).resolve().parent.parent / "docs" / "worlds.md").read_text()
    lines = [ln.split("#")[0].strip() for ln in text.splitlines() if ln.startswith("hil geo ")]
    assert len(lines) >= 4
    for line in lines:
        r = hil_main(*shlex.split(line)[1:])
        assert r.returncode == 0, (line, r.stderr)
    assert (tmp_path / "harbour.plan").is_file()


def test_hil_geo_on_a_chart_says_where_the_positions_count_from(hil_main, tmp_path):
    from support.world_files import harbour_chart

    (tmp_path / "h.geojson").write_text(json.dumps(harbour_chart(FRAME)))
    (tmp_path / "s.toml").write_text('name = "s"\ndescription = "d"\nkind = "fixed"\nmap = "h.geojson"\n'
                                     'start = [30.0, 50.0]\ngoal = [185.0, 130.0]\n'
                                     "extent = [-20.0, -10.0, 200.0, 150.0]\n")
    r = hil_main("geo", "--scenario", str(tmp_path / "s.toml"), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["positions_origin"][:2] == pytest.approx([38.92, 121.65], abs=1e-9)
    assert out["positions_origin"][2:] == pytest.approx([20.0, 10.0], abs=1e-3)   # two tangent planes: 50 um
    assert out["start"][:2] == pytest.approx([50.0, 60.0], abs=0.01)     # 30, 50 m from the origin
    assert out["start"][2:] == pytest.approx(list(FRAME.sea_level_to_geodetic(50.0, 30.0)), abs=1e-9)
