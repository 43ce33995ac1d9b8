"""ESC nodes and the autopilot's CAN back-end on python-can's in-process `virtual` bus."""

from __future__ import annotations

import itertools
import math

import can
import pytest

from autopilot_bridge.can_actuators import CanActuators
from common import dronecan_codec as dc
from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.core import SimulatorCore
from simulator.esc import (
    CLOCK_EVERY,
    CONFLICT_IRREGULAR,
    CONFLICT_WINDOW,
    MAX_FRAMES_PER_POLL,
    NODE_ID_CONFLICT,
    RAW_COMMAND_MISSING_INDEX,
    RAW_COMMAND_OUT_OF_RANGE,
    EscBank,
)

_channels = itertools.count()


@pytest.fixture
def rig():
    cfg = settings.load(None, ["can.interface=\"virtual\""])
    channel = f"esc-test-{next(_channels)}"
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
    core = SimulatorCore(simulator_settings(cfg))
    esc = EscBank(buses[0], cfg.can, cfg.esc, core.vessel)
    acts = CanActuators(buses[1], cfg.can)
    yield cfg, core, esc, acts, buses[2]
    for b in buses:
        b.shutdown()


def test_command_reaches_the_escs_and_status_comes_back(rig):
    cfg, core, esc, acts, _ = rig
    acts.send_controls(10_000, 0.5, -0.25)
    assert esc.poll(1.0) == 1
    assert esc.raw == (4096, -2048)
    port, stdb = esc.controls()
    assert port == pytest.approx(0.5, abs=1e-4) and stdb == pytest.approx(-0.25, abs=1e-4)
    esc.publish(0.0, (core.vessel.thrust(port), core.vessel.thrust(stdb)))
    acts.service(1.0)
    for _ in range(5):  # the three frames of each Status may arrive over several polls
        acts.service(0.05)
    s = acts.summary()
    assert set(s["esc_status"]) == {"port", "starboard"}
    # thrust ~ rpm^2: half forward thrust -> max_rpm / sqrt(2); a quarter reverse -> max_rpm / 2
    assert s["esc_status"]["port"]["rpm"] == round(cfg.esc.max_rpm * math.sqrt(0.5))
    assert s["esc_status"]["starboard"]["rpm"] == round(-cfg.esc.max_rpm * math.sqrt(0.25))
    assert s["esc_status"]["port"]["voltage"] == pytest.approx(cfg.esc.voltage, rel=1e-3)
    assert s["transfers_received"] == {"NodeStatus@20": 1, "NodeStatus@21": 1, "Status@20": 1, "Status@21": 1}
    assert s["rejects"] == {} and s["transfers_lost"] == {}
    assert esc.summary()["transfers_received"] == {"NodeStatus@10": 1, "RawCommand@10": 1}


def test_status_reports_the_battery_voltage_it_is_given(rig):
    cfg, core, esc, acts, _ = rig
    core.battery.draw(1000.0, 1.0)          # a loaded pack: its terminal voltage sags
    volts = core.battery.voltage
    assert volts < cfg.esc.voltage
    esc.publish(0.0, (core.vessel.T_max, 0.0), volts)
    for _ in range(6):
        acts.service(0.05)
    port = acts.summary()["esc_status"]["port"]
    assert port["voltage"] == pytest.approx(volts, rel=1e-3)
    assert port["current"] == pytest.approx(cfg.esc.max_power / volts, rel=1e-3)


def test_status_and_node_status_rates_follow_simulated_time(rig):
    cfg, core, esc, acts, _ = rig
    for n in range(100):  # 1 s of 100 Hz frames
        esc.publish(n * 0.01, (0.0, 0.0))
    assert esc.sent["Status@20"] == 10 and esc.sent["NodeStatus@21"] == 1


def test_bad_raw_commands_are_counted_and_never_applied(rig):
    cfg, core, esc, acts, intruder = rig
    acts.send_controls(0, 0.1, 0.1)
    esc.poll(1.0)
    good = esc.raw
    bad = [
        # -8192 fits the int14 but lies outside the DroneCAN range [-8191, 8191]
        dc.to_frames(dc.RAW_COMMAND, dc.serialize(dc.make(dc.RAW_COMMAND, cmd=[-8192, 0])), 10, 5),
        dc.to_frames(dc.RAW_COMMAND, dc.raw_command([100]), 10, 6),            # no starboard index
        dc.to_frames(dc.RAW_COMMAND, dc.raw_command([100, 100]), 99, 0),      # unknown node
        [can.Message(arbitration_id=dc.message_id(8, 1030, 10), data=b"\x00\x11\x22\x33\x44\x55\x66\x77\x88",
                     is_extended_id=True, check=False)],                          # 9 bytes: wrong DLC
        dc.to_frames("uavcan.equipment.esc.RPMCommand",
                     dc.serialize(dc.make("uavcan.equipment.esc.RPMCommand", rpm=[5000, 5000])), 10, 0),
    ]
    for frames in bad:
        for f in frames:
            intruder.send(f)
    assert esc.poll(1.0) == 0
    for _ in range(3):
        esc.poll(0.05)
    assert esc.raw == good and esc.commands == 1
    rejects = esc.summary()["rejects"]
    assert rejects[RAW_COMMAND_OUT_OF_RANGE] == 1 and rejects[RAW_COMMAND_MISSING_INDEX] == 1
    assert rejects[dc.UNKNOWN_NODE] == 1 and rejects[dc.UNKNOWN_DATA_TYPE] == 1 and rejects[dc.WRONG_DLC] == 1


def _foreign_flood(bus: can.BusABC, n: int, node: int = 99) -> None:
    """``n`` single-frame full-astern RawCommands from a node that is not the autopilot."""
    for k in range(n):
        for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([-8191, -8191]), node, k % 32):
            bus.send(f)


def test_a_flood_of_foreign_frames_is_drained_up_to_the_cap_per_step_and_counted(rig):
    """Issue 31: one poll (one real-time step) reads at most MAX_FRAMES_PER_POLL frames; the rest waits
    for later steps, the cut is counted, and no foreign command is applied."""
    cfg, core, esc, acts, intruder = rig
    n = 3 * MAX_FRAMES_PER_POLL + 100
    esc.budget_s = 1e9                           # the frame cap alone (the time budget is checked below)
    _foreign_flood(intruder, n)
    acts.send_controls(0, 0.5, 0.5)              # the autopilot's command, queued behind the flood
    assert esc.poll(0.0) == 0
    assert esc.receiver.frames == MAX_FRAMES_PER_POLL
    assert esc.summary()["rejects"] == {dc.UNKNOWN_NODE: MAX_FRAMES_PER_POLL}
    assert esc.budget_stops == {"frames": 1} and esc.raw is None
    polls = 1
    while esc.raw is None and polls < 10:
        esc.poll(0.0)
        polls += 1
    assert polls == 4 and esc.raw == (4096, 4096) and esc.commands == 1
    assert esc.summary()["rejects"] == {dc.UNKNOWN_NODE: n}
    assert esc.summary()["budget_stops"] == {"frames": 3}


def test_a_poll_stops_when_its_time_budget_is_spent(rig):
    cfg, core, esc, acts, intruder = rig
    esc.budget_s = 0.0                           # spent at once: the first clock read stops the poll
    _foreign_flood(intruder, 100)
    esc.poll(0.0)
    assert esc.receiver.frames == CLOCK_EVERY and esc.budget_stops == {"time": 1}


def test_a_second_sender_claiming_the_autopilots_node_id_is_a_conflict_and_steers_nothing(rig):
    """Issue 31: a node that sends full-astern RawCommands with the autopilot's own node ID (CAN has no
    authentication), interleaved with the autopilot's: the broken transfer-ID sequence is a conflict after
    at most CONFLICT_IRREGULAR of its commands, from then on no RawCommand is applied (the stale-command
    failsafe stops the thrusters), and once the intruder stops, CONFLICT_WINDOW commands in sequence give
    the autopilot the thrusters back. One sender alone is never a conflict."""
    cfg, core, esc, acts, intruder = rig
    node = cfg.can.autopilot_node_id
    for k in range(100):
        acts.send_controls(k, 0.5, 0.5)
        esc.poll(0.0)
    assert esc.conflicts == 0 and not esc.conflict and esc.raw == (4096, 4096) and esc.commands == 100
    astern = 0
    for k in range(100):
        for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([-8191, -8191]), node, (17 + 3 * k) % 32):
            intruder.send(f)
        astern += esc.poll(0.0)                  # the intruder's commands applied
        acts.send_controls(100 + k, 0.5, 0.5)
        esc.poll(0.0)
    assert esc.conflict and esc.conflicts == 1
    assert astern <= CONFLICT_IRREGULAR, astern
    refused = esc.summary()["rejects"][NODE_ID_CONFLICT]
    assert refused >= 190, refused               # both senders' commands, from the conflict on
    for k in range(CONFLICT_WINDOW + 1):
        acts.send_controls(200 + k, 0.25, 0.25)
        esc.poll(0.0)
    assert not esc.conflict and esc.raw == (2048, 2048) and esc.summary()["node_id_conflicts"] == 1


def test_an_impostor_sending_as_the_autopilot_raises_one_alarm_an_echo_none(rig):
    """Issue 31: frames with the autopilot's node ID that it did not send (an impostor: DroneCAN has no
    authentication, and the ESCs obey it) raise one alarm per episode, which the vessel computer reports as
    a warning (STATUSTEXT), and are counted; a frame it sent, read back (an interface's echo), is neither.
    Before, both were only counted as ignored, and an impostor that silenced the autopilot went unnoticed."""
    cfg, core, esc, acts, intruder = rig
    node = cfg.can.autopilot_node_id
    acts.send_controls(0, 0.5, 0.5)
    echo = dc.to_frames(dc.RAW_COMMAND, dc.raw_command([dc.quantize(0.5), dc.quantize(0.5)]), node, 0,
                        dc.PRIORITY_HIGH)
    for f in echo:
        intruder.send(f)
    acts.service(1.0)
    assert acts.alarms() == [] and acts.summary()["impostor_frames"] == 0
    for k in range(5):
        for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([-8191, -8191]), node, 9 + k):
            intruder.send(f)
    acts.service(1.0)
    alarms = acts.alarms()
    assert len(alarms) == 1 and f"another node sends as node {node}" in alarms[0], alarms
    s = acts.summary()
    assert s["impostor_frames"] == 5 and s["node_id_conflicts"] == 1 and acts.alarms() == []


def test_autopilot_ignores_its_own_node_id_and_counts_lost_status(rig):
    cfg, core, esc, acts, intruder = rig
    # a frame claiming the autopilot's own node ID (e.g. echoed by an interface) is ignored
    for f in dc.to_frames(dc.NODE_STATUS, dc.node_status(1), cfg.can.autopilot_node_id, 0):
        intruder.send(f)
    # ESC 20's Status transfers 0, 1 and 4: 2 and 3 lost
    for tid in (0, 1, 4):
        for f in dc.to_frames(dc.ESC_STATUS, dc.serialize(dc.make(dc.ESC_STATUS, esc_index=0, rpm=tid)), 20, tid):
            intruder.send(f)
    acts.service(1.0)
    for _ in range(5):
        acts.service(0.05)
    s = acts.summary()
    assert s["own_frames_ignored"] == 1
    assert s["transfers_received"] == {"Status@20": 3} and s["transfers_lost"] == {"Status@20": 2}
    assert s["esc_status"]["port"]["rpm"] == 4


def test_esc_lag_is_first_order_and_shared_by_both_paths():
    cfg = settings.load(None, ["esc.time_constant=0.1"])
    core = SimulatorCore(simulator_settings(cfg))
    from simulator.core import Command
    core.apply(Command(0, 1.0, 0.0))
    core.step()
    a = 1.0 - math.exp(-core.frame_dt / cfg.esc.time_constant)
    assert core.thrust[0] == pytest.approx(core.vessel.T_max * a)
    for _ in range(int(5 * cfg.esc.time_constant / core.frame_dt)):
        core.apply(Command(core.time_usec, 1.0, 0.0))
        core.step()
    assert core.thrust[0] == pytest.approx(core.vessel.T_max, rel=0.01)
    instant = SimulatorCore(simulator_settings(settings.load(None, ["esc.time_constant=0.0"])))
    instant.apply(Command(0, 1.0, 0.0))
    instant.step()
    assert instant.thrust[0] == instant.vessel.T_max


def test_int14_resolution_rounds_commands_like_raw_command():
    from simulator.core import Command
    plain = SimulatorCore(simulator_settings(settings.load(None, ["esc.int14_resolution=false"])))
    plain.apply(Command(0, 0.5, -0.3))
    assert plain.controls == (0.5, -0.3)  # float commands on the MAVLink path (int14 is the default)
    for overrides in (["esc.int14_resolution=true"], ["can.actuators=\"can\""]):
        core = SimulatorCore(simulator_settings(settings.load(None, overrides)))
        core.apply(Command(0, 0.5, -0.3))
        assert core.controls == (4096 / 8191, -2457 / 8191)


def test_transfer_times_spilled_to_files_keep_memory_constant_and_read_back_whole(tmp_path):
    import numpy as np

    from common.transfer_times import TransferTimes

    rec = TransferTimes()
    rec.add(1, 0.5)                                   # not recording yet: ignored
    rec.start(spill_to=str(tmp_path / "sent"))
    n = 3 * TransferTimes.CHUNK + 17
    for k in range(n):
        rec.add(k % 32, k * 0.01)
        assert len(rec.tid) < TransferTimes.CHUNK and len(rec.at) < TransferTimes.CHUNK
    tid, at = rec.arrays()
    assert rec.count == n and len(tid) == len(at) == n
    assert tid.tolist() == [k % 32 for k in range(n)] and np.allclose(at, np.arange(n) * 0.01)
    rec.save(str(tmp_path / "sent.npz"))
    z = np.load(tmp_path / "sent.npz")
    assert z["tid"].tolist() == tid.tolist() and sorted(p.name for p in tmp_path.iterdir()) == ["sent.npz"]
    kept = TransferTimes()                            # without a spill file: in memory (hil bench can)
    kept.start()
    kept.add(3, 1.0)
    assert [a.tolist() for a in kept.arrays()] == [[3], [1.0]]
