"""Each Rover mode: what it needs to be entered, the route it sets, where its thrust comes from; and the
planned/fallback behaviour's state machine."""

from __future__ import annotations

import pytest

from autopilot_bridge.behaviour import Behaviour, BehaviourMachine
from autopilot_bridge.mission_commands import waypoint
from autopilot_bridge.modes import MODES, Mode
from autopilot_bridge.vehicle import Vehicle
from common.mavlink import MAV_TYPE as M


class Driver:
    """Records which thrust source a mode used."""

    def idle(self):
        return "idle"

    def manual(self, stick, s, dt):
        return ("manual", stick)

    def navigate(self, s, dt):
        return "navigate"

    def hold(self, s, dt):
        return "hold"


ONE_WAYPOINT = (waypoint(0.0, 10.0, 2.0),)


def vehicle(mode: Mode = Mode.HOLD, mission=ONE_WAYPOINT) -> Vehicle:
    v = Vehicle(list(mission), armed=True, mode=mode)
    v.update(1.0, 2.0, 0.0)    # home
    return v


def output(v: Vehicle):
    return v.active.output(Driver(), v, None, 0.02)


def test_rover_numbers_and_heartbeat_flags():
    assert {m.name: int(m) for m in MODES} == {"MANUAL": 0, "HOLD": 4, "LOITER": 5, "AUTO": 10, "RTL": 11,
                                               "GUIDED": 15}
    assert MODES[Mode.AUTO].flags & M.MAV_MODE_FLAG_AUTO_ENABLED
    assert MODES[Mode.GUIDED].flags & M.MAV_MODE_FLAG_GUIDED_ENABLED
    assert MODES[Mode.MANUAL].flags == M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED and MODES[Mode.HOLD].flags == 0


def test_manual_drives_from_the_stick_and_hold_drifts():
    v = vehicle()
    assert output(v) == "hold" and v.route is None          # the helm's HOLD: drift, kept off the rocks
    v.manual = (0.5, -0.2, 7.0)
    assert v.set_mode(Mode.MANUAL, None) == (True, "MANUAL")
    assert output(v) == ("manual", (0.5, -0.2, 7.0))


def test_loiter_keeps_station_where_it_was_entered():
    v = vehicle()
    assert v.set_mode(Mode.LOITER, None) == (False, "LOITER: no position yet")
    assert v.set_mode(Mode.LOITER, (3.0, 4.0))[0]
    assert v.route.path.tolist() == [[3.0, 4.0], [3.0, 4.0]] and v.route.loiter and output(v) == "navigate"


def test_auto_needs_a_mission_and_a_refused_mode_leaves_the_old_one():
    v = vehicle(mission=())
    assert v.set_mode(Mode.AUTO, (0.0, 0.0)) == (False, "AUTO: no mission") and v.mode == Mode.HOLD
    v = vehicle()
    assert v.set_mode(Mode.AUTO, (0.0, 0.0))[0] and output(v) == "navigate"
    assert v.route.path.tolist() == [[0.0, 0.0], [0.0, 10.0]]


def test_rtl_goes_home_and_guided_goes_to_its_target():
    v = vehicle()
    assert v.set_mode(Mode.RTL, (20.0, 20.0))[0] and v.route.path.tolist() == [[20.0, 20.0], [1.0, 2.0]]
    assert v.set_mode(Mode.GUIDED, (20.0, 20.0))[0]          # no target: keep station there, as Rover's boats do
    assert v.route.path.tolist() == [[20.0, 20.0], [20.0, 20.0]] and v.route.loiter and output(v) == "navigate"
    assert v.reposition((5.0, 6.0), (20.0, 20.0)) == (True, "GUIDED")
    assert v.route.path.tolist() == [[20.0, 20.0], [5.0, 6.0]] and output(v) == "navigate"
    v.arm(False)
    assert not v.wants_thrust()


def test_guided_entered_again_by_a_mode_change_keeps_station_instead_of_resuming_an_old_target():
    """ArduRover's boats: every entry into GUIDED starts a loiter where the boat is (``ModeGuided::_enter``:
    ``is_boat()`` -> ``start_loiter()``); only a new reposition gives a target. Until now a GUIDED entered by
    a mode change went back to the target of an earlier reposition."""
    v = vehicle()
    assert v.reposition((5.0, 6.0), (20.0, 20.0)) == (True, "GUIDED")
    assert v.set_mode(Mode.LOITER, (15.0, 16.0))[0]
    assert v.set_mode(Mode.GUIDED, (14.0, 15.0))[0]
    assert v.route.path.tolist() == [[14.0, 15.0], [14.0, 15.0]] and v.route.loiter
    assert v.set_mode(Mode.GUIDED, (13.0, 14.0))[0]           # and again from GUIDED itself
    assert v.route.path.tolist() == [[13.0, 14.0], [13.0, 14.0]] and v.route.loiter
    assert v.reposition((1.0, 2.0), (13.0, 14.0)) == (True, "GUIDED")
    assert v.route.path.tolist() == [[13.0, 14.0], [1.0, 2.0]] and not v.route.loiter


def test_behaviour_transitions_are_explicit():
    b = BehaviourMachine()
    assert b.state is Behaviour.WAITING
    with pytest.raises(ValueError):
        b.to(Behaviour.PLANNED)              # no navigation yet: nothing to follow
    b.to(Behaviour.IDLE)
    assert b.resume() is Behaviour.FALLBACK
    b.to(Behaviour.PLANNED)
    b.pause()
    assert b.state is Behaviour.IDLE and b.resume() is Behaviour.PLANNED   # disarm/arm: back where it was
    b.to(Behaviour.COMPLETE)
    b.to(Behaviour.RETURNING)
    with pytest.raises(ValueError):
        b.to(Behaviour.PLANNED)              # station keeping ends only with a new route
    b.new_route()
    assert b.state is Behaviour.FALLBACK
    b.pause()
    b.new_route()
    assert b.resume() is Behaviour.FALLBACK
