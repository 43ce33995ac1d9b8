"""The run plot draws the ships' truth and the closest approach (a crash here would lose the picture)."""

from __future__ import annotations

from support.summaries import autopilot_summary

from hil import scenario as scenarios
from hil.encounter_report import ShipTrack
from hil.run_plot import plot_run
from hil.settings import load


def test_plot_with_ships_and_encounters(tmp_path):
    cfg = load()
    scen = scenarios.load("colregs-crossing-right")
    ship = ShipTrack(412000103, "CROSSER", (6.0, 4.0, 1.5, 1.5))
    ship.samples = [(int(t * 1e6), 5.0 + 2.0 * t, 100.0, 0.0, 2.0) for t in range(0, 60)]
    truth = {int(t * 1e6): (60.0, 20.0 + 1.5 * t, 0.0, 1.5) for t in range(0, 100)}
    enc = [{"mmsi": 412000103, "type": "crossing-give-way", "cpa_m": 10.5, "cpa_time_s": 27.0, "compliant": True}]
    out = tmp_path / "plot.png"
    autopilot = autopilot_summary(sensed_cells=((100, 200),), local_paths=None, estimated_track=None)
    plot_run(out, scen, truth, autopilot, cfg, ships={ship.mmsi: ship}, encounters=enc)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
