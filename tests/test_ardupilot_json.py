"""The simulator as ArduPilot SITL's JSON physics (simulator/json_backend.py): packets, skid steering,
the state's wire form, lockstep stepping, and the exchange over a real UDP socket."""

from __future__ import annotations

import json
import math
import re
import socket
from pathlib import Path

import pytest

from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.core import Command, SimulatorCore
from simulator.json_backend import (
    MAGIC_16,
    MAGIC_32,
    ChannelRange,
    JsonPhysics,
    JsonServer,
    SkidMixer,
    encode_servo_packet,
    parse_servo_packet,
    state_json,
)
from simulator.sensors import G

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "ardupilot"

# The first two servo packets ArduRover V4.7.0-dev (the shipped SITL binary, motorboat-skid parameters,
# disarmed) sent to the physics, recorded on the wire: 1200 Hz requested at first, then the rate it
# measured from our 10 ms steps; SERVO1-4 at TRIM 1500, SERVO5-16 at 1000.
RECORDED = (bytes.fromhex("1a48b00400000000" + "dc05" * 4 + "e803" * 12),
            bytes.fromhex("1a48650001000000" + "dc05" * 4 + "e803" * 12))


def _core(**initial: float) -> SimulatorCore:
    over = [f"sim.initial.{k}={v!r}" for k, v in initial.items()]
    return SimulatorCore(simulator_settings(settings.load(None, over)))


def _pwm(left: int, right: int, n: int = 16) -> tuple[int, ...]:
    p = [1500] * 4 + [1000] * (n - 4)
    p[0], p[2] = left, right
    return tuple(p)


def test_recorded_packets_parse() -> None:
    a, b = (parse_servo_packet(p) for p in RECORDED)
    assert a is not None and b is not None
    assert (a.frame_rate, a.frame_count, b.frame_rate, b.frame_count) == (1200, 0, 101, 1)
    assert a.pwm == (1500,) * 4 + (1000,) * 12
    assert SkidMixer().controls(a.pwm) == (0.0, 0.0)   # disarmed: TRIM on both throttles, no thrust


def test_packet_sizes_and_magic() -> None:
    p32 = encode_servo_packet(400, 7, tuple(range(1000, 1032)))
    assert len(p32) == 8 + 64 and int.from_bytes(p32[:2], "little") == MAGIC_32
    got = parse_servo_packet(p32)
    assert got is not None and got.pwm[31] == 1031 and got.frame_count == 7
    assert int.from_bytes(RECORDED[0][:2], "little") == MAGIC_16
    assert parse_servo_packet(RECORDED[0][:-2]) is None            # short
    assert parse_servo_packet(RECORDED[0] + b"\0\0") is None       # long
    assert parse_servo_packet(b"\x00\x00" + RECORDED[0][2:]) is None   # wrong magic
    assert parse_servo_packet(b"") is None
    with pytest.raises(ValueError):
        encode_servo_packet(400, 0, (1500,) * 8)


def test_channel_range_honours_min_trim_max() -> None:
    ch = ChannelRange(1000, 1600, 2000)            # asymmetric: 400 us ahead, 600 us astern
    assert ch.normalised(1600) == 0.0
    assert ch.normalised(2000) == 1.0 and ch.normalised(1800) == 0.5
    assert ch.normalised(1000) == -1.0 and ch.normalised(1300) == -0.5
    assert ch.normalised(2500) == 1.0 and ch.normalised(700) == -1.0     # beyond the range: clamped
    assert ch.normalised(0) == 0.0                                      # output off
    assert ChannelRange(1000, 1600, 2000, reversed=True).normalised(1800) == -0.5
    with pytest.raises(ValueError):
        ChannelRange(1500, 1500, 2000)


def test_mixer_from_params() -> None:
    params = {"SERVO1_FUNCTION": 74, "SERVO4_FUNCTION": 73, "SERVO1_MIN": 1000, "SERVO1_MAX": 2000,
              "SERVO4_TRIM": 1400, "SERVO4_REVERSED": 1}
    m = SkidMixer.from_params(params)
    assert (m.left_channel, m.right_channel) == (4, 1)
    pwm = [1500] * 16
    pwm[3], pwm[0] = 1200, 2000            # left reversed: 1200 is 200 of its 300 us astern -> +2/3
    port, stdb = m.controls(tuple(pwm))
    assert port == pytest.approx(2 / 3) and stdb == 1.0
    with pytest.raises(ValueError, match="73"):
        SkidMixer.from_params({"SERVO3_FUNCTION": 74})
    with pytest.raises(ValueError, match="SERVO1 and SERVO2"):
        SkidMixer.from_params({"SERVO1_FUNCTION": 73, "SERVO2_FUNCTION": 73, "SERVO3_FUNCTION": 74})


@pytest.mark.skipif(not (SHARED / "rover-skid.parm").exists(), reason=f"ArduPilot's parameter files not in {SHARED}")
def test_mixer_from_the_shipped_parameter_files() -> None:
    from hil.ardupilot import PARAM_FILES, read_params

    params = read_params(tuple(SHARED / n for n in PARAM_FILES))
    assert "SIM_TIDE_0.5" not in params              # the malformed line ArduPilot also skips
    m = SkidMixer.from_params(params)
    assert (m.left_channel, m.right_channel) == (1, 3)
    assert (m.left.min, m.left.trim, m.left.max) == (1000, 1500, 2000)


def test_state_is_compact_json_arduPilot_reads() -> None:
    """ArduPilot's reader finds each key and reads the value right after '":' (no space), so the
    state must be compact; framing is newline, object, newline."""
    out = state_json(2.5, (13.0, 4.0, math.pi / 2, 1.0, 0.2, 0.1), (0.3, -0.4), (10.0, 5.0))
    assert out.startswith(b"\n{") and out.endswith(b"}\n")
    text = out.decode().strip()
    assert ": " not in text and ", " not in text
    for key in ("gyro", "accel_body", "position", "attitude", "velocity"):
        assert re.search(f'"{key}":\\[', text), key
    assert re.search(r'"timestamp":2\.5[,}]', text)
    s = json.loads(text)
    assert s["imu"]["gyro"] == [0.0, 0.0, 0.1]
    assert s["imu"]["accel_body"] == [0.3, -0.4, pytest.approx(-G)]      # specific force: -g on z at rest
    assert s["position"] == [3.0, -1.0, 0.0]                              # NED from home
    vn, ve, vd = s["velocity"]                                             # heading east: u east, v south
    assert (vn, ve, vd) == (pytest.approx(-0.2), pytest.approx(1.0), 0.0)
    assert s["attitude"] == [0.0, 0.0, pytest.approx(math.pi / 2)]


def test_state_never_carries_non_finite_numbers() -> None:
    out = state_json(0.01, (math.nan, 0.0, 0.0, math.inf, 0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
    assert b"nan" not in out.lower() and b"inf" not in out.lower()
    json.loads(out)


def test_a_repeated_frame_is_answered_again_without_a_step() -> None:
    phys = JsonPhysics(_core(), SkidMixer(), (0.0, 0.0))
    first = phys.answer(RECORDED[0])
    assert first is not None and phys.core.n == 1
    assert json.loads(first)["timestamp"] == pytest.approx(phys.core.frame_dt)
    assert phys.answer(RECORDED[0]) == first and phys.core.n == 1 and phys.repeats == 1
    assert phys.answer(RECORDED[1]) != first and phys.core.n == 2
    assert phys.answer(b"junk") is None and phys.malformed == 1 and phys.core.n == 2


def test_same_truth_as_the_mavlink_server_for_the_same_thrust() -> None:
    """PWM 1800/1750 on SERVO1/3 (TRIM 1500, MAX 2000 in rover.parm) is port 0.6, starboard 0.5: the
    JSON physics and the MAVLink server's core, commanded alike, give the same truth, bit for bit."""
    mixer = SkidMixer.from_params({"SERVO1_FUNCTION": 73, "SERVO3_FUNCTION": 74, "SERVO1_MIN": 1000,
                                   "SERVO1_MAX": 2000, "SERVO3_MIN": 1000, "SERVO3_MAX": 2000})
    phys = JsonPhysics(_core(x=5.0, y=7.0, psi=0.3), mixer, (5.0, 7.0))
    ref = _core(x=5.0, y=7.0, psi=0.3)
    for k in range(300):
        answer = phys.answer(encode_servo_packet(100, k, _pwm(1800, 1750)))
        ref.apply(Command(ref.time_usec, 0.6, 0.5))
        ref.step()
    assert phys.core.state == ref.state
    s = json.loads(answer)
    assert s["position"][0] == pytest.approx(ref.state[0] - 5.0, abs=1e-8)
    assert s["timestamp"] == pytest.approx(3.0)
    assert ref.state[3] > 0.5 and ref.state[5] > 0.0   # ahead, and turning to starboard (more thrust to port)


def test_left_ahead_right_astern_turns_to_starboard() -> None:
    phys = JsonPhysics(_core(), SkidMixer(left=ChannelRange(1000, 1500, 2000), right=ChannelRange(1000, 1500, 2000)),
                       (0.0, 0.0))
    for k in range(200):
        answer = phys.answer(encode_servo_packet(100, k, _pwm(2000, 1000)))
    assert json.loads(answer)["imu"]["gyro"][2] > 0.3        # rad/s, clockwise seen from above


def test_server_answers_its_firmware_only_in_lockstep() -> None:
    phys = JsonPhysics(_core(), SkidMixer(), (0.0, 0.0))
    server = JsonServer(phys, ("127.0.0.1", 0), duration=0.05, idle_timeout=5.0)
    steps: list[int] = []
    server.after_step = lambda core: steps.append(core.n)
    fw, other = (socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2))
    fw.settimeout(5.0)
    dest = ("127.0.0.1", server.port)
    import threading

    summary: dict = {}
    th = threading.Thread(target=lambda: summary.update(server.run()))
    th.start()
    try:
        stamps = []
        for k in range(5):
            fw.sendto(encode_servo_packet(100, k, _pwm(1500, 1500)), dest)
            if k == 2:
                other.sendto(encode_servo_packet(100, 99, _pwm(2000, 2000)), dest)   # not the firmware
            stamps.append(json.loads(fw.recvfrom(512)[0])["timestamp"])
        th.join(timeout=10.0)
    finally:
        server.stop()
        th.join(timeout=5.0)
        server.close()
        fw.close()
        other.close()
    assert stamps == pytest.approx([0.01, 0.02, 0.03, 0.04, 0.05])
    assert steps == [1, 2, 3, 4, 5]
    assert summary["wrong_peer"] == 1 and summary["steps"] == 5 and not summary["idle_end"]


def test_a_busy_port_is_one_line() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        with pytest.raises(ValueError, match="JSON physics port"):
            JsonServer(JsonPhysics(_core(), SkidMixer(), (0.0, 0.0)), s.getsockname())


def test_moored_the_boat_holds_still_while_time_passes() -> None:
    phys = JsonPhysics(_core(x=5.0, y=7.0, psi=0.3), SkidMixer(), (5.0, 7.0))
    start = phys.core.state
    phys.moored = True
    for k in range(100):
        answer = phys.answer(encode_servo_packet(100, k, _pwm(2000, 2000)))
    s = json.loads(answer)
    assert phys.core.state == start and s["timestamp"] == pytest.approx(1.0)
    assert s["position"] == [0.0, 0.0, 0.0] and s["imu"]["accel_body"][:2] == [0.0, 0.0]
    phys.moored = False
    phys.answer(encode_servo_packet(100, 100, _pwm(2000, 2000)))
    assert phys.core.state != start


def test_route_cross_track() -> None:
    from hil.ardupilot import route_cross_track

    route = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]
    import numpy as np

    xte = route_cross_track(np.array([[5.0, 1.0], [10.0, 5.0], [12.0, 5.0], [-3.0, 4.0]]), np.array(route))
    assert xte is not None
    assert {k: xte[k] for k in ("cross_track_rms_m", "cross_track_max_m")} == {
        "cross_track_rms_m": pytest.approx(math.sqrt((1 + 0 + 4 + 25) / 4), abs=1e-3), "cross_track_max_m": 5.0}
    assert route_cross_track(np.zeros((0, 2)), np.array(route)) is None


def test_project_parameters_come_from_the_hull_and_the_configuration(tmp_path: Path) -> None:
    """CRUISE_THROTTLE holds CRUISE_SPEED on this hull; the turn limits are the hull's full turn rate
    (eq. (4) at full differential thrust) less a margin; the file reads back as ArduPilot reads it."""
    from hil.ardupilot import TURN_MARGIN, cruise_throttle, full_turn_rate, project_params, read_params, write_params
    from simulator.vessel import Vessel, hull_dynamics

    cfg = settings.load()
    p = project_params(cfg)
    assert p["CRUISE_SPEED"] == p["WP_SPEED"] == cfg.autopilot.cruise_speed
    v = Vessel(cfg.vessel)
    t = v.thrust(p["CRUISE_THROTTLE"] / 100.0)
    d = hull_dynamics((0.0, 0.0, 0.0, cfg.autopilot.cruise_speed, 0.0, 0.0), v.propulsion(t, t),
                      (0.0, 0.0, 0.0), (0.0, 0.0), v.coefficients)
    assert abs(d[3]) < 0.01                                  # m/s^2: the throttle holds the speed
    assert cruise_throttle(cfg.vessel, 3.5) == pytest.approx(100.0, abs=0.1)   # beyond top speed: full
    r = full_turn_rate(cfg.vessel)
    assert 0.5 < r < 0.8                                     # rad/s (docs: 0.63 at full differential)
    assert p["ATC_STR_RAT_MAX"] == pytest.approx(math.degrees(TURN_MARGIN * r), abs=0.1)
    assert p["SYSID_THISMAV"] == cfg.autopilot.system_id and p["MIS_DONE_BEHAVE"] == 1.0
    f = tmp_path / "p.parm"
    write_params(f, p)
    (tmp_path / "q.parm").write_text("# comment\nWP_SPEED 2.5\nBROKEN_LINE\nSIM_X nan\n")
    merged = read_params((f, tmp_path / "q.parm"))
    assert merged["WP_SPEED"] == 2.5 and "BROKEN_LINE" not in merged and "SIM_X" not in merged
    assert merged["CRUISE_THROTTLE"] == p["CRUISE_THROTTLE"]


def test_station_keeping_figures_from_a_tlog(tmp_path: Path) -> None:
    """The bench's station-keeping figures from a .tlog's truth: arrival, RMS and largest distance from
    the goal after it, the share of time within the tolerance."""
    import struct
    from types import SimpleNamespace

    from common.geodesy import LocalFrame
    from common.mavlink import Codec
    from hil.benches.ardupilot import station_figures

    geo, codec = LocalFrame(38.92, 121.65, 0.0), Codec(1, 51)
    # north: 10 m from the goal at (50, 0), closing at 1 m/s, then 1 m off for 10 s, then 4 m off for 10 s
    samples = [(t, 40.0 + t) for t in range(0, 10)] + [(t, 49.0) for t in range(10, 20)] + \
        [(t, 54.0) for t in range(20, 30)]
    with open(tmp_path / "run.tlog", "wb") as f:
        for t, n in samples:
            lat, lon = geo.sea_level_to_geodetic(n, 0.0)
            frame = codec.encode("hil_state_quaternion", t * 1_000_000, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                 int(round(lat * 1e7)), int(round(lon * 1e7)), 0, 0, 0, 0, 0, 0, 0, 0, 0)
            f.write(struct.pack(">Q", t * 1_000_000) + frame)
    summary = SimpleNamespace(tlog=str(tmp_path / "run.tlog"), sim_time_s=29.0, outcome="timeout", collisions=0,
                              min_clearance_m=5.0)
    fig = station_figures(summary, (50.0, 0.0), 3.0, geo, hold_s=15.0)
    assert fig["arrived_s"] == 7.0 and fig["held_s"] == 15.0
    d = [1] * 6 + [4] * 10        # m, the samples at 14 ... 29 s
    assert fig["station_max_m"] == pytest.approx(4.0, abs=0.02)
    assert fig["station_rms_m"] == pytest.approx(math.sqrt(sum(x * x for x in d) / len(d)), abs=0.02)
    assert fig["within_tolerance"] == pytest.approx(6 / 16, abs=1e-3)
    never = station_figures(summary, (500.0, 0.0), 3.0, geo)
    assert never["arrived_s"] is None and never["within_tolerance"] == 0.0


def test_the_system_id_goes_to_arduRover_under_both_names() -> None:
    """ArduPilot 4.7 renamed SYSID_THISMAV to MAV_SYSID, and the shipped binary ignores the old name in
    a defaults file: with a system id other than 1 (`hil run` beside another run takes instance N and
    system id 1 + N) it kept 1, and this process, listening for the id it had set, never heard it."""
    from hil import settings
    from hil.ardupilot import project_params

    params = project_params(settings.load(None, ["autopilot.system_id=7"]))
    assert params["MAV_SYSID"] == params["SYSID_THISMAV"] == 7.0
