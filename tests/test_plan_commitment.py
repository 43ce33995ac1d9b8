"""Plan commitment (autopilot_bridge/plan_commitment.py): no flipping round an obstacle every cycle."""

from __future__ import annotations

import numpy as np
import pytest

from autopilot_bridge.plan_commitment import CommitmentParams, keep_current, obstacle_between, path_length, truncate

RES = 0.5
P = CommitmentParams(compare_length=15.0, min_remaining=6.0, shortcut_ratio=0.8)


def _island() -> np.ndarray:
    """40 m x 40 m (rows north, columns east) with a 4 m x 4 m island centred at (20, 20) NED."""
    occ = np.zeros((80, 80), dtype=bool)
    occ[36:44, 36:44] = True
    return occ


def _around(side: float, start=(20.0, 5.0), end=(20.0, 35.0)) -> np.ndarray:
    """A path from west to east of the island passing it 5 m to the north (side +1) or south (-1)."""
    e = np.linspace(start[1], end[1], 61)
    n = start[0] + side * 5.0 * np.sin(np.pi * (e - start[1]) / (end[1] - start[1]))
    return np.column_stack([n, e])


def test_paths_on_opposite_sides_enclose_the_island():
    occ = _island()
    assert obstacle_between(_around(+1), _around(-1), occ, RES)
    assert not obstacle_between(_around(+1), _around(+1) + [0.5, 0.0], occ, RES)  # a variation
    assert not obstacle_between(_around(+1), _around(-1), np.zeros_like(occ), RES)


def test_the_other_way_round_is_refused_while_the_current_path_lasts():
    occ = _island()
    assert keep_current(_around(+1), _around(-1), occ, RES, P)
    # the same way round (slightly different) is taken at once
    assert not keep_current(_around(+1), _around(+1) * [1.02, 1.0], occ, RES, P)


def test_a_nearly_used_up_current_path_is_replaced():
    occ = _island()
    cur = _around(+1)
    rest = cur[cur[:, 1] > 31.0]                       # past the island, about 4 m left
    assert path_length(rest) < P.min_remaining
    assert not keep_current(rest, _around(-1, start=tuple(rest[0])), occ, RES, P)


def test_a_clearly_shorter_other_way_is_taken():
    occ = _island()
    detour = np.vstack([[20.0, 5.0], [32.0, 12.0], [32.0, 30.0], [20.0, 35.0]])   # wide north loop
    assert path_length(detour) > 1.25 * path_length(_around(-1))
    whole = CommitmentParams(compare_length=40.0, min_remaining=6.0, shortcut_ratio=0.8)
    assert not keep_current(detour, _around(-1), occ, RES, whole)
    assert keep_current(_around(-1), detour, occ, RES, whole)      # and not the other way


@pytest.mark.parametrize("length", [0.0, 3.3, 10.0, 100.0])
def test_truncate_keeps_the_first_metres(length):
    path = _around(+1)
    t = truncate(path, length)
    assert path_length(t) == pytest.approx(min(length, path_length(path)), abs=1e-9)
    assert np.allclose(t[0], path[0])

