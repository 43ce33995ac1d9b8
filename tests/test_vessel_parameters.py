"""Every parameter a ground station can set, set through the parameter service, with its effect observed
in the component that uses it (issues 30 and 36: one declaration per parameter, read live, no copy).

The vessel computer is built in-process from its typed parts (tests/support/vessel_harness.py); the
ground-station link is the real :class:`autopilot_bridge.gcs.link.GcsLink` without endpoints, and each
PARAM_SET is a MAVLink 2 frame encoded by pymavlink, decoded and dispatched as the link does it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from support.vessel_harness import build_computer, frame

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.link import GcsLink
from autopilot_bridge.hil_link import BatteryReading
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.parameters import Tunable, declarations
from common.geodesy import LocalFrame
from planner.fence import Circle, Fence

M = mavlink2
START = (40.0, 22.0)          # the harbour's start, NED m


class Session:
    """A vessel computer with its GCS link, and a pymavlink GCS (system 255) talking to the link in-process."""

    def __init__(self, **kw: object) -> None:
        self.ap, self.hil, self.worker = build_computer(**kw)  # type: ignore[arg-type]
        self.link = GcsLink.open(GcsParams(endpoints=()), 1, 1, LocalFrame(38.92, 121.65, 0.0))
        self.link.attach(self.ap.commands)
        self.gcs = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        self.parser = mavlink2.MAVLink(None)
        self.t = 0.0

    def param_set(self, name: str, value: float, target: int = 1) -> bool:
        """PARAM_SET as bytes on the wire, decoded and handed to the link's dispatch table; True if taken."""
        data = self.gcs.param_set_encode(target, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32).pack(self.gcs)
        msg = self.parser.parse_char(bytearray(data))
        assert msg is not None and msg.get_type() == "PARAM_SET"
        self.link.handlers["PARAM_SET"](msg, 0.0)
        table = self.link.params_table
        assert table is not None
        p = table.get(name)
        return p is not None and math.isclose(p.get(), value, rel_tol=1e-6)

    def fix(self, seconds: float = 1.0, at: tuple[float, float] = START) -> None:
        """Frames of a boat at rest at ``at`` until navigation has a fix."""
        for _ in range(int(seconds / 0.01)):
            self.t += 0.01
            self.ap.on_frame(frame(self.t, *at), 0.0)


TESTED: set[str] = set()


def tested(*names: str) -> None:
    TESTED.update(names)


@pytest.fixture(scope="module")
def s() -> Session:
    return Session()


def test_parameters_are_declared_by_their_owners_once_with_range_units_and_doc(s):
    table = s.link.params_table
    names = [p.name for p in table.params]
    assert len(names) == len(set(names))
    owners = (s.ap.vehicle, s.ap.planning, s.ap.keeper.planner_tuning, s.ap.helm.heading_pid, s.ap.helm.speed_ctl,
              s.ap.station, s.ap.keeper.geofence, s.link.failsafe, s.link.identity,
              s.ap.onboard.battery)
    declared = [d.name for o in owners for d in declarations(o)]
    assert sorted(declared) == sorted(names)
    for o in owners:
        for d in declarations(o):
            assert isinstance(type(o).__dict__.get(d.attr) or getattr(type(o), d.attr), Tunable)
            assert d.doc and d.bounds(o)[0] < d.bounds(o)[1]
    # ArduRover's names for what the boat has; the project's own keep a prefix.
    assert {"WP_SPEED", "WP_RADIUS", "LOIT_RADIUS", "FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "FS_ACTION",
            "MIS_DONE_BEHAVE", "RTL_SPEED", "SYSID_THISMAV", "ARMING_CHECK"} <= set(names)


def test_out_of_range_and_non_whole_values_change_nothing(s):
    before = s.ap.vehicle.wp_speed
    assert not s.param_set("WP_SPEED", 99.0) and s.ap.vehicle.wp_speed == before
    assert not s.param_set("WP_SPEED", float("nan")) and s.ap.vehicle.wp_speed == before
    assert not s.param_set("FS_ACTION", 1.5) and s.link.failsafe.action in (0, 1, 2)


def test_arming_check():
    s = Session()
    assert s.param_set("ARMING_CHECK", 1)
    assert not s.ap.commands.arm(True).ok            # no navigation fix yet
    assert s.param_set("ARMING_CHECK", 0)
    assert s.ap.commands.arm(True).ok                # ArduRover's ARMING_CHECK = 0: no pre-arm checks
    tested("ARMING_CHECK")


def test_speeds_reach_the_vehicle_the_helm_and_the_traffic_assessment():
    s = Session()
    s.fix()
    assert s.param_set("WP_SPEED", 1.1)
    assert s.ap.vehicle.speed_setpoint() == pytest.approx(1.1)
    assert s.ap.planning.speed() == pytest.approx(1.1)      # what the traffic assessment predicts us at
    assert s.ap.helm.speed_setpoint() == pytest.approx(1.1)
    assert s.param_set("RTL_SPEED", 0.7)
    assert s.ap.vehicle.speed_setpoint() == pytest.approx(1.1)   # not in RTL
    assert s.ap.commands.set_mode(Mode.RTL).ok
    assert s.ap.vehicle.speed_setpoint() == pytest.approx(0.7)
    assert s.param_set("RTL_SPEED", 0.0)                         # 0: WP_SPEED
    assert s.ap.vehicle.speed_setpoint() == pytest.approx(1.1)
    tested("WP_SPEED", "RTL_SPEED")


def test_waypoint_radius_reaches_the_mission_executor_and_the_modes():
    s = Session()
    s.fix()
    assert s.param_set("WP_RADIUS", 7.5)
    assert s.ap.vehicle.executor.default_radius == 7.5
    assert s.ap.commands.set_mode(Mode.LOITER).ok
    assert s.ap.vehicle.route is not None and s.ap.vehicle.route.goal_radius == 7.5
    s.ap.commands.replace_mission(s.ap.vehicle.mission)      # a new executor reads it too (no copy)
    assert s.ap.vehicle.executor.default_radius == 7.5
    tested("WP_RADIUS")


def _far(s: Session, d: float) -> NavState:
    goal = s.ap.course.goal_ned
    return NavState(t=1.0, x=goal[0] + d, y=goal[1], psi=0.0, u=0.0, v=0.0, r=0.0, gyro_bias=0.0, position_std=1.0)


def test_mission_done_behaviour_and_loiter_radius_reach_the_station_keeper():
    s = Session()
    s.ap.current.north = s.ap.current.east = 0.0             # still water: the boat may drift within the radius
    s.ap.current.u_water = 0.0
    s.ap.course.behaviour.to(Behaviour.IDLE)
    s.ap.course.behaviour.to(Behaviour.COMPLETE)
    zero = s.ap.helm.zero_thrust
    assert s.param_set("MIS_DONE_BEHAVE", 0)                 # hold: thrusters off wherever the boat is
    assert s.ap.helm._station_keep(_far(s, 10.0), 0.01) == zero
    assert s.param_set("MIS_DONE_BEHAVE", 1)                 # loiter
    assert s.param_set("LOIT_RADIUS", 20.0)                  # 10 m off: inside the radius, drifting
    assert s.ap.helm._station_keep(_far(s, 10.0), 0.01) == zero
    assert s.param_set("LOIT_RADIUS", 4.0)                   # 10 m off: outside, steer back
    assert s.ap.helm._station_keep(_far(s, 10.0), 0.01) != zero
    assert s.ap.course.behaviour.state is Behaviour.RETURNING
    tested("MIS_DONE_BEHAVE", "LOIT_RADIUS")


def test_controller_gains_reach_the_controllers_and_survive_a_simulator_restart():
    s = Session()
    pid, spd = s.ap.helm.heading_pid, s.ap.helm.speed_ctl
    for name, v in (("HDG_KP", 50.0), ("HDG_KI", 0.0), ("HDG_KD", 10.0)):
        assert s.param_set(name, v)
    pid.reset()
    assert pid.update(0.2, 0.0, 0.1, 0.01) == pytest.approx(50.0 * 0.2 - 10.0 * 0.1)
    assert s.param_set("HDG_KI", 4.0)
    pid.reset()
    assert pid.update(0.2, 0.0, 0.0, 0.5) == pytest.approx(50.0 * 0.2 + 4.0 * 0.2 * 0.5)
    assert s.param_set("SPD_BANDWIDTH", 2.0)
    spd.reset(1.0)
    m = spd.model
    # u = u_d = u_ref: only the damping and the integral term of the new bandwidth act.
    spd.integral = 0.1
    assert spd.update(1.0, 1.0, 0.0, 0.0, 0.0) == pytest.approx(m.damping(1.0) - m.m11 * 4.0 * 0.1)
    s.ap._reset()                                            # a simulator restart keeps what was tuned
    assert (pid.kp, pid.ki, pid.kd, spd.bandwidth) == (50.0, 4.0, 10.0, 2.0)
    assert s.ap.helm.heading_pid is pid
    tested("HDG_KP", "HDG_KI", "HDG_KD", "SPD_BANDWIDTH")


def test_planner_parameters_reach_the_next_planning_cycle():
    s = Session(wait_for_arm=False)
    assert s.param_set("PLN_DEADLINE", 0.2)
    assert s.param_set("PLN_PERCEPT_RAD", 25.0)
    assert s.param_set("PLN_PNG_PROB", 0.3)
    s.fix(2.0)
    assert s.worker.requests, "no planning cycle was submitted"
    r = s.worker.requests[-1]
    assert r.deadline_s == pytest.approx(0.2)
    assert r.problem.world is not None
    assert r.problem.world.planner_overrides == {"perceptual_radius": 25.0, "png_probability": pytest.approx(0.3)}
    assert not s.param_set("PLN_DEADLINE", 0.99 * s.ap.p.planning_period)   # must stay under the period
    tested("PLN_DEADLINE", "PLN_PERCEPT_RAD", "PLN_PNG_PROB")


def test_gcs_failsafe_parameters_reach_the_failsafe():
    s = Session(wait_for_arm=False)
    s.fix()
    fs = s.link.failsafe
    s.link.view.status = s.ap.commands.status()
    assert s.param_set("FS_GCS_TIMEOUT", 3.0) and s.param_set("FS_ACTION", 1) and s.param_set("FS_GCS_ENABLE", 0)
    fs.last_heartbeat = 0.0
    fs.check(10.0)                                           # disabled: nothing
    assert not fs.active and s.ap.vehicle.mode == Mode.AUTO
    assert s.param_set("FS_GCS_ENABLE", 1)
    fs.check(2.9)                                            # within FS_GCS_TIMEOUT
    assert not fs.active
    fs.check(3.1)
    assert fs.active and s.ap.vehicle.mode == Mode.RTL       # FS_ACTION 1: RTL (home is set)
    tested("FS_GCS_TIMEOUT", "FS_ACTION", "FS_GCS_ENABLE")


def test_system_id_reaches_the_codec_and_the_link():
    s = Session()
    assert s.param_set("SYSID_THISMAV", 7)
    assert s.link.out.codec.mav.srcSystem == 7 and s.link.view.sysid == 7
    assert s.link.mission is not None and s.link.mission.sysid == 7    # the mission service reads it live too
    frame_bytes = s.link.out.codec.encode("heartbeat", 11, 3, 0, 0, 0)
    assert mavlink2.MAVLink(None).parse_char(bytearray(frame_bytes)).get_srcSystem() == 7
    assert not s.param_set("SYSID_THISMAV", 1, target=1)     # addressed to the old id: not for us any more
    assert s.param_set("SYSID_THISMAV", 1, target=7)
    tested("SYSID_THISMAV")


def _pack(volts: float, consumed: float = 100.0) -> BatteryReading:
    return BatteryReading(volts, (round(volts / 6 * 1000),) * 6, 9.0, consumed, None, 50, 0,
                          M.MAV_BATTERY_CHARGE_STATE_OK)


def _feed(s: Session, seconds: float, pack: BatteryReading) -> None:
    for _ in range(int(round(seconds / 0.01))):
        s.t += 0.01
        s.ap.on_frame(replace(frame(s.t, *START), battery=pack), 0.0)


def test_battery_parameters_reach_the_battery_monitor_and_its_failsafe():
    s = Session(wait_for_arm=False)                           # armed in AUTO
    s.fix()
    mon = s.ap.onboard.battery
    assert s.param_set("BATT_LOW_VOLT", 21.0) and s.param_set("BATT_LOW_TIMER", 0.5)
    assert s.param_set("BATT_FS_LOW_ACT", 2) and (mon.low_volt, mon.low_timer, mon.fs_low_act) == (21.0, 0.5, 2)
    _feed(s, 0.3, _pack(20.8))
    assert not mon.failsafe and s.ap.vehicle.mode == Mode.AUTO    # below for 0.3 s of BATT_LOW_TIMER's 0.5
    _feed(s, 0.3, _pack(20.8))
    assert mon.failsafe and s.ap.vehicle.mode == Mode.LOITER      # BATT_FS_LOW_ACT 2: hold station
    s = Session(wait_for_arm=False)
    s.fix()
    mon = s.ap.onboard.battery
    assert s.param_set("BATT_LOW_VOLT", 0.0) and s.param_set("BATT_CAPACITY", 1000.0)
    assert s.param_set("BATT_LOW_MAH", 300.0) and s.param_set("BATT_FS_LOW_ACT", 0)
    _feed(s, 0.1, _pack(15.0, consumed=650.0))
    assert not mon.failsafe and mon.remaining_mah() == 350.0      # 1000 - 650 left, BATT_LOW_VOLT off
    _feed(s, 0.1, _pack(15.0, consumed=750.0))
    assert mon.failsafe and s.ap.vehicle.mode == Mode.AUTO        # BATT_FS_LOW_ACT 0: nothing
    tested("BATT_CAPACITY", "BATT_LOW_VOLT", "BATT_LOW_MAH", "BATT_LOW_TIMER", "BATT_FS_LOW_ACT")


def test_fence_parameters_reach_the_planning_grid_and_the_breach_action():
    s = Session(wait_for_arm=False)
    s.fix()
    n, e = START
    # An exclusion circle 10 m east of the boat: its cells become obstacles while FENCE_ENABLE is 1.
    s.ap.commands.replace_fence(Fence(exclusion_circles=(Circle(e + 10.0, n, 3.0),)))
    row, col = s.ap.grid.cell_of(e + 10.0, n)
    assert s.ap.grid.occ[row, col]
    assert s.param_set("FENCE_ENABLE", 0)
    s.fix(0.05)
    assert not s.ap.grid.occ[row, col]
    assert s.param_set("FENCE_ENABLE", 1)
    s.fix(0.05)
    assert s.ap.grid.occ[row, col]
    # A fence the boat is outside of: FENCE_ACTION decides what the breach does.
    assert s.param_set("FENCE_ACTION", 2)
    s.ap.commands.replace_fence(Fence(exclusion_circles=(Circle(e, n, 5.0),)))
    s.fix(0.05)
    assert s.ap.keeper.geofence.breached and s.ap.vehicle.mode == Mode.LOITER
    s.ap.commands.set_mode(Mode.AUTO)
    s.ap.commands.replace_fence(Fence())
    s.fix(0.05)
    assert not s.ap.keeper.geofence.breached
    assert s.param_set("FENCE_ACTION", 1)
    s.ap.commands.replace_fence(Fence(exclusion_circles=(Circle(e, n, 5.0),)))
    s.fix(0.05)
    assert s.ap.vehicle.mode == Mode.RTL
    tested("FENCE_ENABLE", "FENCE_ACTION")


def test_every_parameter_has_its_effect_tested(s):
    """Runs last in this module: a parameter added without a test of its effect fails here."""
    assert TESTED == {p.name for p in s.link.params_table.params}


def test_the_docs_table_is_the_declarations():
    """docs/gcs.md's parameter table is what the components declare (python -m autopilot_bridge.parameters)."""
    import re
    from pathlib import Path

    from autopilot_bridge.parameters import markdown_table

    doc = (Path(__file__).resolve().parents[1] / "docs" / "gcs.md").read_text()
    table = re.search(r"<!-- parameters: generated -->\n(.*?)\n<!-- /parameters -->", doc, re.S)
    assert table is not None and table.group(1) == markdown_table()


def test_hold_near_an_obstacle_keeps_station_at_the_last_safe_point():
    """HOLD where the fence (here: everywhere) is nearer than the hold clearance steers back to the last safe
    point. Its station keeper's state machine started in WAITING, from which COMPLETE and RETURNING are no
    transitions: every such frame raised ValueError (a numeric fault, thrusters off), and the boat drifted
    onto the quay (issue 31's hour of chaos, seed 31)."""
    s = Session()
    helm = s.ap.helm
    here = _far(s, 0.0)
    helm.last_safe = (here.x + 10.0, here.y)
    helm.fence_depth = lambda _n, _e: 0.0
    thrust = helm.hold(here, 0.01)
    assert helm.holding and thrust != helm.zero_thrust
    assert helm._hold_behaviour.state is Behaviour.RETURNING


def test_manual_without_a_stick_is_hold_and_keeps_station_near_an_obstacle():
    """MANUAL with no MANUAL_CONTROL newer than 1 s is HOLD (ArduRover's radio failsafe): clear of obstacles
    the thrusters are off, near one it keeps station at the last safe point (issue 31's chaos: a GCS's
    MANUAL left the boat to the current beside the quay); a fresh stick drives the thrusters again."""
    import time

    s = Session()
    helm = s.ap.helm
    here = _far(s, 0.0)
    assert helm.manual(None, here, 0.01) == helm.zero_thrust and not helm.holding   # open water: drift
    helm.last_safe = (here.x + 10.0, here.y)
    helm.fence_depth = lambda _n, _e: 0.0
    stale = (0.0, 0.0, time.monotonic() - 5.0)
    assert helm.manual(stale, here, 0.01) != helm.zero_thrust and helm.holding
    fresh = (0.0, 0.0, time.monotonic())                     # the stick centred: the person stops the boat
    assert helm.manual(fresh, here, 0.01) == helm.zero_thrust and not helm.holding
