"""Path-following statistics (autopilot_bridge/tracking_stats.py)."""

from __future__ import annotations

import numpy as np
import pytest

from autopilot_bridge.tracking_stats import TrackingStats


def test_tracking_stats_summarise_the_errors():
    t = TrackingStats()
    assert t.summary() == {"frames": 0}
    for e in (0.3, -0.4, 0.0, 1.2):
        t.add(e, 0.1, 0.1 + 2 * np.pi - 0.05)             # heading error 0.05 rad across the wrap
    s = t.summary()
    assert s["frames"] == 4 and s["cross_track_max_m"] == 1.2
    assert s["cross_track_rms_m"] == pytest.approx(np.sqrt((0.09 + 0.16 + 1.44) / 4), abs=1e-4)
    assert s["heading_error_rms_rad"] == pytest.approx(0.05, abs=1e-4)
