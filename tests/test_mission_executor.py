"""The AUTO mode's mission executor (pure logic): commands as ArduRover runs them."""

from __future__ import annotations

import math

from autopilot_bridge import mission_commands as mc
from autopilot_bridge.mission_commands import MissionCommand, waypoint
from autopilot_bridge.modes import Mode
from autopilot_bridge.vehicle import Vehicle


def sail(v: Vehicle, steps: int, t0: float = 0.0, dt: float = 0.5, speed: float = 1.0) -> tuple[list[int], float]:
    """A boat that steers straight at the active NAV item (home for RTL), ``speed`` m/s: the items
    reported reached, in order, and the time at the end."""
    reached, t = [], t0
    n, e = v.home if v.home is not None else (0.0, 0.0)
    for _ in range(steps):
        c = v.mission[v.current] if v.mission else None
        target = v.home if c is None or c.position is None else c.position
        d = math.hypot(target[0] - n, target[1] - e)
        if d > 1e-9 and not v.executor.complete and v.executor.loiter_until is None:
            k = min(1.0, speed * dt / d)
            n, e = n + (target[0] - n) * k, e + (target[1] - e) * k
        t += dt
        v.update(n, e, t)
        reached += v.take_reached()
    return reached, t


def start(mission: list[MissionCommand]) -> Vehicle:
    v = Vehicle(mission, armed=True, mode=Mode.HOLD, default_radius=2.0)
    v.update(0.0, 0.0, 0.0)                       # home from the first fix
    assert v.set_mode(Mode.AUTO, (0.0, 0.0)) == (True, "AUTO")
    return v


def test_do_jump_repeats_its_target_the_given_number_of_times_then_goes_on():
    v = start([waypoint(0.0, 10.0, 2.0), waypoint(0.0, 20.0, 2.0),
               MissionCommand(mc.DO_JUMP, p1=0, p2=2), waypoint(10.0, 20.0, 2.0)])
    reached, _ = sail(v, 400)
    assert reached == [0, 1, 2, 0, 1, 2, 0, 1, 2, 3]
    assert v.complete and v.executor.jumps == {2: 2}
    assert [t for t, _w in v.take_notes() if "jump" in t] == ["mission: jump to item 0 (1/2)",
                                                              "mission: jump to item 0 (2/2)"]


def test_a_jump_loop_without_nav_items_ends_the_mission_instead_of_hanging():
    v = start([waypoint(0.0, 5.0, 2.0), MissionCommand(mc.DO_JUMP, p1=1, p2=-1)])
    sail(v, 40)
    assert v.complete
    assert any("without a NAV command" in t and w for t, w in v.take_notes())


def test_a_stored_command_is_skipped_with_a_statustext_and_counts_as_reached():
    servo = MissionCommand(mc.M.MAV_CMD_DO_SET_SERVO, p1=9, p2=1500)
    delay = MissionCommand(mc.M.MAV_CMD_NAV_DELAY, p1=10)
    v = start([waypoint(0.0, 5.0, 2.0), servo, delay, waypoint(0.0, 10.0, 2.0)])
    reached, _ = sail(v, 60)
    assert reached == [0, 1, 2, 3] and v.complete     # in mission order: the DO item runs when item 0 is reached
    notes = [t for t, w in v.take_notes() if w]
    assert notes == ["mission item 1: DO_SET_SERVO skipped (stored, not executed here)",
                     "mission item 2: NAV_DELAY skipped (stored, not executed here)"]


def test_change_speed_takes_effect_when_the_nav_item_before_it_is_reached_and_ends_with_the_mode():
    v = start([waypoint(0.0, 5.0, 2.0), waypoint(0.0, 10.0, 2.0), MissionCommand(mc.DO_CHANGE_SPEED, p1=1, p2=0.7),
               waypoint(0.0, 15.0, 2.0)])
    assert v.speed is None
    v.update(0.0, 4.0, 1.0)                       # item 0 reached, item 1 active: the DO waits for it
    assert v.current == 1 and v.speed is None
    v.update(0.0, 9.0, 2.0)                       # item 1 reached: the DO after it runs
    assert v.current == 3 and v.speed == 0.7
    v.set_mode(Mode.HOLD, (0.0, 3.0))
    assert v.speed is None


def test_loiter_time_keeps_station_for_its_time_then_return_to_launch_goes_home():
    v = start([waypoint(0.0, 6.0, 2.0), MissionCommand(mc.NAV_LOITER_TIME, 0.0, 12.0, p1=5.0),
               MissionCommand(mc.NAV_RETURN_TO_LAUNCH)])
    reached, t = sail(v, 22)                      # 11 m: within 2 m of the loiter point since t = 10 s
    assert reached == [0, 1] and v.current == 1 and v.executor.loiter_until is not None
    assert v.route.loiter and v.route.path[-1].tolist() == [0.0, 12.0]
    assert v.executor.loiter_until == 15.0
    reached, t = sail(v, 6, t0=t)                 # 3 s more: still loitering
    assert reached == [] and v.current == 1
    before = v.route.version
    v.update(0.0, 11.0, t + 1.0)                  # the 5 s are over: RTL, a new route home
    assert v.current == 2 and v.route.version == before + 1 and v.route.path[-1].tolist() == [0.0, 0.0]
    assert not v.route.loiter


def test_waypoint_hold_time_and_loiter_unlimited():
    v = start([waypoint(0.0, 4.0, 2.0, hold=3.0), MissionCommand(mc.NAV_LOITER_UNLIM, 0.0, 8.0),
               waypoint(0.0, 20.0, 2.0)])
    assert v.route.loiter and len(v.route.path) == 2          # a hold ends the leg sequence
    v.update(0.0, 3.0, 1.0)
    assert v.take_reached() == [0] and v.executor.loiter_until == 4.0
    v.update(0.0, 3.0, 4.0)
    assert v.current == 1 and v.route.path[-1].tolist() == [0.0, 8.0]
    v.update(0.0, 7.0, 5.0)
    assert v.take_reached() == [1] and math.isinf(v.executor.loiter_until)
    v.update(0.0, 7.0, 1e6)
    assert v.current == 1 and not v.complete                 # unlimited: until the mode or the mission changes


def test_set_home_moves_where_return_to_launch_goes():
    v = start([MissionCommand(mc.DO_SET_HOME, -5.0, 3.0, p1=0), waypoint(0.0, 4.0, 2.0),
               MissionCommand(mc.NAV_RETURN_TO_LAUNCH)])
    assert v.home == (-5.0, 3.0)
    v.update(0.0, 3.5, 1.0)
    assert v.route.path.tolist() == [[0.0, 3.5], [-5.0, 3.0]]
    v.update(-4.0, 3.0, 2.0)
    assert v.complete and v.take_reached() == [0, 1, 2]


def test_consecutive_waypoints_are_one_global_reference_path_and_passing_counts():
    v = start([waypoint(0.0, 10.0, 2.0), waypoint(0.0, 20.0, 2.0), MissionCommand(mc.DO_CHANGE_SPEED, p2=1.0),
               waypoint(0.0, 30.0, 2.0), MissionCommand(mc.DO_JUMP, p1=0, p2=1), waypoint(0.0, 40.0, 2.0)])
    # Up to the DO_JUMP: [position, wp0, wp1, wp3] (the DO item does not break the path).
    assert v.route.path.tolist() == [[0.0, 0.0], [0.0, 10.0], [0.0, 20.0], [0.0, 30.0]]
    v.update(0.0, 9.0, 1.0)
    v.update(4.0, 21.0, 2.0)                  # 4 m off item 1 but past the line through it
    # DO_CHANGE_SPEED (item 2) runs as item 1 is reached: every item in mission order.
    assert v.take_reached() == [0, 1, 2] and v.current == 3 and v.speed == 1.0
