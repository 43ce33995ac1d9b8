"""The vessel computer's HIL link reads fields without message objects (Codec.frames):
what it decodes, refuses and counts must be what it did with pymavlink's message objects, on a
simulator's real datagrams (sensors, GPS, DVL, range scans, AIS of a traffic scenario) and on random
datagrams of every kind from the simulator and from strangers, damaged ones between."""

from __future__ import annotations

import random
from collections import Counter

import pytest
from test_tap_fast_path import _datagrams

from autopilot_bridge.hil_link import TAKEN, HilLink
from common import mavlink as mavlink_module
from common.geodesy import LocalFrame
from common.mavlink import Codec
from hil import scenario as scenarios
from hil import settings
from hil.assembly.simulator import simulator_settings
from hil.scenario import simulator_overrides
from simulator.core import SimulatorCore
from simulator.rangefinder import WorldMap


def _simulator_datagrams(scenario: str, steps: int) -> list[bytes]:
    base = settings.load()
    scen = scenarios.instance(scenarios.load_spec(scenario), None, base.current)
    cfg = settings.load(None, ["sim.seed=4", *simulator_overrides(scen, base.current)])
    core = SimulatorCore(simulator_settings(cfg), WorldMap(scen.truth_occ(), scen.resolution), tuple(scen.traffic))
    out = []
    for k in range(steps):
        out.append(core.frame())
        core.step()
        if k == steps // 2:   # a restarted simulator: its clock starts over
            core = SimulatorCore(simulator_settings(cfg), WorldMap(scen.truth_occ(), scen.resolution),
                                 tuple(scen.traffic))
    return out


def _decode_all(datagrams: list[bytes]) -> tuple[list[str], dict]:
    cfg = settings.load()
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    link = HilLink.open("127.0.0.1:0", (), geo, sim_ids=(cfg.link.system_id, cfg.link.component_id),
                   truth_component_id=cfg.traffic.truth_component_id)
    try:
        frames = [repr(link.decode(d)) for d in datagrams]
        ais = repr(link.take_ais())
        state = {"rejects": dict(link.rejects), "truth_ignored": link.truth_ignored, "frames": link.frames,
                 "ais": ais, "ais_received": link.ais_received, "switches": link.timeline_switches,
                 "bytes": link.codec.mav.total_bytes_received, "packets": link.codec.mav.total_packets_received}
    finally:
        link.close()
    return frames, state


def _streams() -> list[bytes]:
    real = _simulator_datagrams("harbour", 400) + _simulator_datagrams("colregs-harbour", 300)
    stranger = [data for data, _sender in _datagrams(random.Random(23), 1200)]
    rng = random.Random(5)
    mixed = real + stranger
    rng.shuffle(mixed)
    return real + mixed


def test_the_link_decodes_refuses_and_counts_what_it_did_with_message_objects(monkeypatch):
    datagrams = _streams()
    fast_frames, fast = _decode_all(datagrams)
    monkeypatch.setattr(mavlink_module, "clean_frames", lambda _data: None)   # Codec.frames -> Codec.decode
    slow_frames, slow = _decode_all(datagrams)
    assert fast_frames == slow_frames
    assert fast == slow
    decoded = [f for f in fast_frames[:700] if f != "None"]
    assert len(decoded) > 600 and "RangeScan(bearings=(" in "".join(decoded) and "GpsFix(" in "".join(decoded)
    assert fast["ais_received"] > 0 and fast["truth_ignored"] > 300 and fast["switches"] >= 1
    assert sum(fast["rejects"].values()) > 300


@pytest.mark.parametrize("seed", [1, 2])
def test_codec_frames_are_decodes_messages_field_by_field(seed):
    """Codec.frames against Codec.decode on random datagrams: the same accepted messages (type,
    ids, every field's value), the same rejections and counters."""
    taken = list(TAKEN) + ["HIL_ACTUATOR_CONTROLS", "HEARTBEAT"]
    a, b = Codec(1, 1, accept=taken), Codec(1, 1, accept=taken)
    checked = 0
    for data, _sender in _datagrams(random.Random(seed), 800):
        frames, rejects_a = a.frames(data)
        msgs, rejects_b = b.decode(data)
        assert Counter(rejects_a) == Counter(rejects_b)
        assert [(k, s, c) for k, s, c, _ in frames] == \
            [(m.get_type(), m.get_srcSystem(), m.get_srcComponent()) for m in msgs]
        for (_k, _s, _c, fields), m in zip(frames, msgs, strict=True):
            view = fields()
            assert {n: repr(getattr(view, n)) for n in m.fieldnames} == {n: repr(getattr(m, n)) for n in m.fieldnames}
            checked += 1
    assert checked > 800
    assert (a.mav.total_bytes_received, a.mav.total_packets_received) == \
        (b.mav.total_bytes_received, b.mav.total_packets_received)
