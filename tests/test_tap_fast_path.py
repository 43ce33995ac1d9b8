"""The tap's short cut for clean datagrams (hil/tap.py): message objects only for the kinds it reads,
every other frame written to the .tlog as it came. On random datagrams of every kind, from the
simulator, the vessel computer and strangers, with damaged ones between, it records what the
pymavlink path records: the same .tlog bytes, truth, commands, estimates, texts, refusals and ship
samples."""

from __future__ import annotations

import random

import pytest
from pymavlink import mavutil
from test_mavlink_fast_path import random_message

from common.geodesy import LocalFrame
from common.mavlink import Codec, clean_frames, frame_ids, leading_uint64, mavlink2, message_at
from hil import tap as tap_module
from hil.tap import Tap

SIM, AP, STRANGER = ("127.0.0.1", 5001), ("127.0.0.1", 5002), ("127.0.0.1", 6666)
READ = ["HIL_STATE_QUATERNION", "AIS_VESSEL", "HIL_ACTUATOR_CONTROLS", "LOCAL_POSITION_NED", "STATUSTEXT",
        "MISSION_ITEM_REACHED", "HIL_SENSOR"]
EVERY = [cls for cls in mavlink2.mavlink_map.values()]


class _Ships:
    def __init__(self) -> None:
        self.samples: list[tuple] = []
        self.collision: list = []

    def add(self, *args) -> None:
        self.samples.append(args)


def _frame(rng: random.Random, codec: Codec, cls: type) -> bytes:
    m = random_message(rng, cls)
    if cls.msgname == "HIL_SENSOR" and rng.random() < 0.3:
        m.time_usec = rng.choice([0, 1, 255, 1 << 40])   # short payloads: trailing zeros trimmed
        m.xacc = m.yacc = m.zacc = m.xgyro = m.ygyro = m.zgyro = 0.0
    return bytes(m.pack(codec.mav))


def _datagrams(rng: random.Random, n: int) -> list[tuple[bytes, tuple[str, int]]]:
    codecs = {SIM: [Codec(1, 51), Codec(1, 52)], AP: [Codec(1, 191)], STRANGER: [Codec(1, 52), Codec(9, 99)]}
    by_name = {cls.msgname: cls for cls in EVERY}
    out = []
    for _ in range(n):
        sender = rng.choice([SIM, SIM, AP, AP, STRANGER])
        parts = []
        for _ in range(rng.randrange(1, 7)):
            cls = by_name[rng.choice(READ)] if rng.random() < 0.6 else rng.choice(EVERY)
            parts.append(_frame(rng, rng.choice(codecs[sender]), cls))
        data = b"".join(parts)
        if rng.random() < 0.1:   # damaged: the pymavlink path on both sides
            b = bytearray(data)
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            data = bytes(b)
        out.append((data, sender))
    return out


def _tap(path, lockstep: bool) -> Tap:
    t = Tap(path, LocalFrame(38.9, 121.6, 0.0), encounters=_Ships(), lockstep=lockstep)
    t.sim_addr, t.ap_addr, t.sim_ids = SIM, AP, (1, 51)
    t._t0_usec = 1_700_000_000_000_000
    return t


def _state(t: Tap) -> dict:
    keys = ("truth", "truth_times", "truth_raw", "estimate", "commands", "statustext", "mission_reached", "frames",
            "refused", "ais_forwarded", "_sim_usec", "_epoch", "_segment")
    return {k: repr(getattr(t, k)) for k in keys} | {"ships": repr(t.encounters.samples)}


@pytest.mark.parametrize("lockstep", [True, False])
def test_the_short_cut_records_what_the_pymavlink_path_records(tmp_path, monkeypatch, lockstep):
    datagrams = _datagrams(random.Random(17), 1500)
    fast = _tap(tmp_path / "fast.tlog", lockstep)
    for data, sender in datagrams:
        fast._handle(data, sender)
    fast.close()
    monkeypatch.setattr(tap_module, "clean_frames", lambda _data: None)
    slow = _tap(tmp_path / "slow.tlog", lockstep)
    for data, sender in datagrams:
        slow._handle(data, sender)
    slow.close()
    assert _state(fast) == _state(slow)
    assert fast.frames > 4000 and fast.commands and fast.truth and fast.estimate and fast.encounters.samples
    assert sum(fast.refused.values()) > 100
    if lockstep:   # in real time the stamps are the wall clock
        assert (tmp_path / "fast.tlog").read_bytes() == (tmp_path / "slow.tlog").read_bytes()


def test_frames_of_a_clean_datagram_and_their_ids_and_leading_uint64():
    sim, ap = Codec(3, 51), Codec(4, 191)
    a = sim.encode("hil_sensor", 123456789, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    b = ap.encode("hil_actuator_controls", 42, [0.5] * 16, 0, 0)
    c = sim.encode("hil_sensor", 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)   # payload trimmed to 1 byte
    data = a + b + c
    spans = clean_frames(data)
    assert spans == [(0, len(a)), (len(a), len(a) + len(b)), (len(a) + len(b), len(data))]
    assert [frame_ids(data, s) for s, _ in spans] == [(mavlink2.MAVLINK_MSG_ID_HIL_SENSOR, 3, 51),
                                                      (mavlink2.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS, 4, 191),
                                                      (mavlink2.MAVLINK_MSG_ID_HIL_SENSOR, 3, 51)]
    assert [leading_uint64(data, s, e) for s, e in spans[::2]] == [123456789, 0]
    m = message_at(data, *spans[1])
    assert m.get_type() == "HIL_ACTUATOR_CONTROLS" and m.time_usec == 42 and bytes(m.get_msgbuf()) == b
    assert clean_frames(data[:-1]) is None and clean_frames(b"\x00" + data) is None
    bad = bytearray(data)
    bad[len(a) + 12] ^= 4
    assert clean_frames(bytes(bad)) is None


def test_only_the_simulators_clock_moves_the_lockstep_stamps(tmp_path):
    """A HIL_SENSOR from anyone else (here with the largest time there is, which used to stop hil run
    with a struct.error) neither moves the .tlog's simulated time nor stops the tap."""
    t = _tap(tmp_path / "run.tlog", True)
    sim, stranger = Codec(1, 51), Codec(1, 51)
    t._handle(sim.encode("hil_sensor", 2_000_000, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0), SIM)
    for sensor in (stranger.encode("hil_sensor", (1 << 64) - 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
                   stranger.encode("hil_sensor", (1 << 64) - 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)[:-1]):
        t._handle(sensor, STRANGER)
        assert t._sim_usec == 2_000_000
    t.close()
    log = mavutil.mavlink_connection(str(tmp_path / "run.tlog"))
    stamps = []
    while (m := log.recv_match()) is not None:
        stamps.append((m.time_usec, round(m._timestamp * 1e6)))
    assert stamps == [(2_000_000, t._t0_usec + 2_000_000), ((1 << 64) - 1, t._t0_usec + 2_000_000)]
