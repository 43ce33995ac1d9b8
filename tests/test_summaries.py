"""The typed summaries (autopilot_bridge/summary.py, hil/run_summary.py): what crosses the process
boundary and what goes on disk survives table -> JSON -> table unchanged, keeps the keys the files
always had, and a key that does not fit is one line naming it, never a KeyError."""

from __future__ import annotations

import dataclasses
import json

import pytest
from support.summaries import (
    ARDUPILOT,
    CAN,
    ENCOUNTER,
    GCS,
    RUN_CAN,
    RUN_TRAFFIC,
    TRAFFIC,
    autopilot_summary,
    run_summary,
)

from common.tables import to_table
from hil.errors import ConfigError, RunFailed
from hil.run_summary import read_autopilot_summary, read_simulator_summary, read_summary


def _through_json(summary):
    return json.loads(json.dumps(to_table(summary), allow_nan=False))


@pytest.mark.parametrize("summary", [
    run_summary(),
    run_summary(outcome="collision", reached_goal=False, collisions=1, collision_time_s=45.25, energy_J=None,
                warnings=("another hil run streams with system id 1",), gcs=GCS,
                encounters=(ENCOUNTER, {"mmsi": 412000104, "name": "", "type": "not met", "compliant": None}),
                traffic=RUN_TRAFFIC, can=RUN_CAN, plot=None, plot_error="OSError: x"),
    run_summary(simulator=ARDUPILOT, actuators="ardupilot", planning_cycles=None, security=dataclasses.replace(
        run_summary().security, simulator=None, autopilot=None, tap=None)),    # ArduRover flew
    run_summary(planning_cycles=None, plans_accepted=None, deadline_overruns=None, worker_restarts=None,
                fallback_activations=None, tracking=None, control_latency_ms=None, navigation=None,
                sensed_obstacles=None, simulator=None, run_folder=None, plot=None),   # the autopilot was killed
])
def test_a_run_summary_round_trips_through_json(summary):
    assert read_summary(_through_json(summary)) == summary


@pytest.mark.parametrize("summary", [
    autopilot_summary(),
    autopilot_summary(complete_time_s=None, mission_complete=False, worker_startup_s=dataclasses.replace(
        autopilot_summary().worker_startup_s, count=0, max=None), can=CAN,
        traffic=TRAFFIC, gcs=GCS),
    autopilot_summary(link=None, busy_poll=None, local_paths=None, estimated_track=None,
                      sensed_cells=None),  # Autopilot.summary()
])
def test_an_autopilot_summary_round_trips_through_json(summary):
    assert read_autopilot_summary(_through_json(summary)) == summary


def test_the_files_keep_their_keys_and_optional_sections_stay_absent():
    table = to_table(run_summary())
    assert list(table)[:4] == ["scenario", "seed", "mode", "outcome"]
    assert list(table)[-4:] == ["events", "actuators", "run_folder", "plot"]
    for absent in ("warnings", "gcs", "encounters", "traffic", "can", "plot_error"):
        assert absent not in table
    assert table["control_latency_ms"] == {"p50": 0.4, "p99": 6.0, "max": 80.0, "frames": 100}
    assert set(table["security"]) == {"simulator", "autopilot", "autopilot_navigation_numeric", "tap"}
    assert table["collision_time_s"] is None      # None where the key always appears
    ap = to_table(autopilot_summary(can=None, gcs=None))
    assert "can" not in ap and "gcs" not in ap and ap["traffic"] is None
    assert list(ap)[-6:] == ["traffic", "link", "busy_poll", "local_paths", "estimated_track", "sensed_cells"]


def test_an_unknown_or_missing_key_is_one_line_naming_it():
    table = to_table(run_summary())
    with pytest.raises(ConfigError) as exc:
        read_summary({**table, "outcom": "goal"}, "run/summary.json")
    assert str(exc.value) == "run/summary.json: outcom: unknown key (did you mean 'outcome'?)"
    del table["sim_time_s"]
    with pytest.raises(ConfigError, match=r"^summary.json: sim_time_s: missing key$"):
        read_summary(table)
    nested = to_table(run_summary())
    del nested["security"]["tap"]
    with pytest.raises(ConfigError, match=r"^summary.json: security.tap: missing key$"):
        read_summary(nested)
    with pytest.raises(ConfigError, match=r"^summary.json: expected a JSON object, got list$"):
        read_summary([1, 2])
    ap = to_table(autopilot_summary())
    ap["control_latency_ms"]["p99"] = "fast"
    with pytest.raises(RunFailed) as exc:
        read_autopilot_summary(ap)
    assert str(exc.value) == "the autopilot's summary: control_latency_ms.p99: expected a number, got 'fast'"
    assert "\n" not in str(exc.value)


def test_a_section_is_read_as_its_owner_typed_it():
    """The sections (tracking, link, gcs, can, traffic, busy_poll, local_paths) have their owners'
    types: a key they do not have, a missing one or a value of the wrong type is one line naming it;
    an optional key may be absent."""
    ap = to_table(autopilot_summary(gcs=GCS, can=CAN, traffic=TRAFFIC))
    ap["gcs"]["frames_inn"] = 3
    with pytest.raises(RunFailed, match=r"^the autopilot's summary: gcs.frames_inn: unknown key \(did you mean "
                                        r"'frames_in'\?\)$"):
        read_autopilot_summary(ap)
    ap = to_table(autopilot_summary(can=CAN))
    del ap["can"]["node_id"]
    with pytest.raises(RunFailed, match=r"^the autopilot's summary: can.node_id: missing key$"):
        read_autopilot_summary(ap)
    ap = to_table(autopilot_summary(traffic=TRAFFIC))
    ap["traffic"]["encounters"][0]["start_s"] = "soon"
    with pytest.raises(RunFailed, match=r"traffic.encounters\[0\].start_s: expected a number, got 'soon'$"):
        read_autopilot_summary(ap)
    ap = to_table(autopilot_summary())
    ap["local_paths"][0]["path_ned"] = "none"
    with pytest.raises(RunFailed, match=r"local_paths\[0\].path_ned: expected an array"):
        read_autopilot_summary(ap)
    no_frames = to_table(autopilot_summary(tracking={"frames": 0}))     # TrackingStats with nothing to say
    assert read_autopilot_summary(no_frames).tracking == {"frames": 0}



def test_the_simulator_section_is_read_as_its_back_end_typed_it():
    """``simulator`` is the vessel computer's run's section (HilSimulatorSection) or ArduRover's
    (ArduPilotSimulatorSection): each is read strictly, the error names the key of the section the table
    is, and ``can`` and ``security.simulator`` have their types too."""
    hil_run = read_summary(_through_json(run_summary()))
    assert hil_run.simulator_counters() == hil_run.simulator and hil_run.ardurover() is None
    flown = read_summary(_through_json(run_summary(simulator=ARDUPILOT)))
    assert flown.simulator_counters() is None and flown.ardurover() == ARDUPILOT["ardupilot"]
    table = to_table(run_summary(simulator=ARDUPILOT))
    table["simulator"]["ardupilot"]["instance"] = "eleven"
    with pytest.raises(ConfigError, match=r"^summary.json: simulator.ardupilot.instance: expected an integer, "
                                          r"got 'eleven'$"):
        read_summary(table)
    table = to_table(run_summary())
    table["simulator"]["stepping"]["steps_per_s"] = "fast"
    with pytest.raises(ConfigError, match=r"^summary.json: simulator.stepping.steps_per_s: expected a number"):
        read_summary(table)
    table = to_table(run_summary())
    del table["simulator"]["battery"]
    with pytest.raises(ConfigError, match=r"^summary.json: simulator.battery: missing key$"):
        read_summary(table)
    table = to_table(run_summary(can=RUN_CAN))
    table["can"]["simulator"]["raw_commands_aplied"] = 3
    with pytest.raises(ConfigError, match=r"^summary.json: can.simulator.raw_commands_aplied: unknown key \(did you "
                                          r"mean 'raw_commands_applied'\?\)$"):
        read_summary(table)
    table = to_table(run_summary())
    del table["security"]["simulator"]["kernel_drops"]
    with pytest.raises(ConfigError, match=r"^summary.json: security.simulator.kernel_drops: missing key$"):
        read_summary(table)


def test_the_simulators_own_summaries_are_read_as_their_types():
    """What the simulator's parts print, built for real in-process (the JSON back-end's physics answering
    servo packets; the core's battery and truth), read back strictly as the types they declare."""
    from hil import settings
    from hil.assembly.simulator import simulator_settings
    from hil.config import from_typed_table
    from simulator.core import SimulatorCore
    from simulator.json_backend import JsonPhysics, JsonPhysicsSummary, SkidMixer, encode_servo_packet

    core = SimulatorCore(simulator_settings(settings.load()), None, ())
    physics = JsonPhysics(core, SkidMixer.from_params({"SERVO1_FUNCTION": 73, "SERVO3_FUNCTION": 74}), (0.0, 0.0))
    pwm = (1900, 1500, 1900) + (1500,) * 13
    for n in range(5):
        physics.answer(encode_servo_packet(400, n, pwm))
    summary = json.loads(json.dumps(physics.summary()))
    assert from_typed_table(JsonPhysicsSummary, summary, "json") == summary
    assert summary["packets"] == 5 and summary["final_state"]["u"] > 0.0
    summary["final_state"]["psi"] = None
    with pytest.raises(ConfigError, match=r"^json: final_state.psi: expected a number, got None$"):
        from_typed_table(JsonPhysicsSummary, summary, "json")
    with pytest.raises(RunFailed, match=r"^the simulator's summary: expected a JSON object, got list$"):
        read_simulator_summary([])
