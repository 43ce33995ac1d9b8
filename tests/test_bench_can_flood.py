"""`hil bench can-flood` (issue 31, point 5): runs, applies only the autopilot's commands, counts the flood.

No timing is asserted (the machine is shared): only what the bench's legs must show whatever the speed.
"""

from __future__ import annotations

import json

from common import dronecan_codec as dc


def test_bench_can_flood_applies_only_the_autopilots_commands_and_counts_the_flood(hil):
    p = hil("bench", "can-flood", "--duration", "0.3", "--rate", "30000", "--json")
    assert p.returncode == 0, p.stderr
    legs = json.loads(p.stdout)["legs"]
    assert [(r["flood_frames_per_s"], r["bound"]) for r in legs] == [
        (0.0, "256 frames + 2 ms"), (8000.0, "256 frames + 2 ms"), (8000.0, "256 frames"),
        (30000.0, "256 frames + 2 ms"), (30000.0, "256 frames")]
    quiet = legs[0]
    assert quiet["commands_applied"] == quiet["commands_sent"] == quiet["steps"] and quiet["rejects"] == {}
    for r in legs:
        assert r["commands_applied"] >= 1
        assert r["last_raw_command"][1] == dc.quantize(0.3)          # the autopilot's, never the flood's -8191
        assert set(r["rejects"]) <= {dc.UNKNOWN_NODE}
    # 300 foreign frames a step against a cap of 256: every poll of the frame-capped leg is cut
    capped = legs[4]
    assert capped["polls_cut"] == {"frames": capped["steps"]}
    assert capped["frames_read"] == 256 * capped["steps"]


def test_bench_can_flood_refuses_numbers_out_of_range(hil_main):
    for args in (("--duration", "0"), ("--duration", "nan"), ("--rate", "-1"), ("--rate", "1e9")):
        p = hil_main("bench", "can-flood", *args)
        assert p.returncode == 2 and "Traceback" not in p.stderr, args
