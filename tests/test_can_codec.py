"""DroneCAN transfers on CAN frames: layout, CRC, reassembly and every reject reason (in-process)."""

from __future__ import annotations

import can
import numpy as np
import pytest
from dronecan.transport import Transfer as DronecanTransfer

from common import dronecan_codec as dc
from common import dronecan_layout


def status_msg(rpm=1234, index=1):
    return dc.make(dc.ESC_STATUS, error_count=3, voltage=24.0, current=2.5, temperature=300.0, rpm=rpm,
                   power_rating_pct=40, esc_index=index)


def test_crc16_ccitt_check_value():
    # The standard check value of CRC-16/CCITT-FALSE over the ASCII digits 1-9.
    assert dc.crc16_ccitt(b"123456789") == 0x29B1


@pytest.mark.parametrize("msg,name", [
    (dc.make(dc.RAW_COMMAND, cmd=[8191, -8191]), dc.RAW_COMMAND),
    (status_msg(), dc.ESC_STATUS),
    (dc.make(dc.NODE_STATUS, uptime_sec=77, health=1, mode=0, sub_mode=0, vendor_specific_status_code=5),
     dc.NODE_STATUS),
])
def test_frames_match_the_dronecan_package_transport(msg, name):
    """Our transport layer and the dronecan package's produce the same frames, byte for byte."""
    ours = dc.to_frames(name, dc.serialize(msg), source_node=42, transfer_id=29, priority=dc.PRIORITY_HIGH)
    theirs = DronecanTransfer(transfer_id=29, source_node_id=42, payload=msg,
                              transfer_priority=dc.PRIORITY_HIGH).to_frames()
    assert [(f.arbitration_id, bytes(f.data)) for f in ours] == [(f.message_id, bytes(f.bytes)) for f in theirs]
    assert all(f.is_extended_id for f in ours)


def test_id_layout_and_multi_frame_tail_bytes():
    frames = dc.to_frames(dc.ESC_STATUS, dc.serialize(status_msg()), 21, 35, dc.PRIORITY_MEDIUM)
    assert len(frames) == 3  # 14 payload bytes + 2 CRC bytes over 7-byte chunks
    assert frames[0].arbitration_id == (16 << 24) | (1034 << 8) | 21
    tails = [f.data[-1] for f in frames]
    assert [t & 0x1F for t in tails] == [3, 3, 3]                 # 35 mod 32
    assert [(t >> 7) & 1 for t in tails] == [1, 0, 0]              # start of transfer
    assert [(t >> 6) & 1 for t in tails] == [0, 0, 1]              # end of transfer
    assert [(t >> 5) & 1 for t in tails] == [0, 1, 0]              # toggle
    single = dc.to_frames(dc.RAW_COMMAND, dc.raw_command([100, -100]), 10, 0)
    assert len(single) == 1 and single[0].data[-1] == 0xC0 and single[0].dlc == 5


def test_round_trip_through_the_receiver():
    rx = dc.TransferReceiver([dc.ESC_STATUS, dc.RAW_COMMAND])
    out = [rx.feed(f) for f in dc.to_frames(dc.ESC_STATUS, dc.serialize(status_msg(-4321, 0)), 20, 7)]
    assert out[:2] == [None, None]
    t = out[2]
    assert (t.full_name, t.source_node, t.transfer_id) == (dc.ESC_STATUS, 20, 7)
    assert (t.msg.rpm, t.msg.esc_index, t.msg.error_count) == (-4321, 0, 3)
    [t] = [rx.feed(f) for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([-8191, 8191]), 10, 1)]
    assert list(t.msg.cmd) == [-8191, 8191]
    assert not rx.rejects


def test_raw_command_refuses_out_of_range_values():
    with pytest.raises(ValueError):
        dc.raw_command([8192, 0])
    assert dc.quantize(1.5) == 8191 and dc.quantize(-1.0) == -8191 and dc.quantize(0.5) == 4096


def frame(arb, data, **kw):
    return can.Message(arbitration_id=arb, data=bytes(data), is_extended_id=kw.pop("ext", True), **kw)


def status_frames(tid=0, node=20):
    return dc.to_frames(dc.ESC_STATUS, dc.serialize(status_msg()), node, tid)


def test_every_reject_reason_is_counted_and_nothing_is_returned():
    rx = dc.TransferReceiver([dc.ESC_STATUS, dc.RAW_COMMAND], nodes=[10, 20], own_nodes=[5])
    raw = dc.to_frames(dc.RAW_COMMAND, dc.raw_command([1, 2]), 10, 0)[0]
    got = []
    # wrong DLC: an empty frame has no tail byte; a 1-byte RawCommand holds no whole int14
    got.append(rx.feed(frame(raw.arbitration_id, b"")))
    got.append(rx.feed(frame(raw.arbitration_id, b"\x01\xc1")))
    # bad CRC: flip one payload bit of a multi-frame transfer
    fs = status_frames(1)
    bad = bytearray(fs[1].data)
    bad[0] ^= 0x01
    got += [rx.feed(fs[0]), rx.feed(frame(fs[1].arbitration_id, bad)), rx.feed(fs[2])]
    # toggle error: the second frame with the toggle bit of the first
    fs = status_frames(2)
    t = bytearray(fs[1].data)
    t[-1] &= ~0x20
    got += [rx.feed(fs[0]), rx.feed(frame(fs[1].arbitration_id, t))]
    # missing start, transfer-ID mismatch and an interrupted transfer
    fs = status_frames(3)
    got.append(rx.feed(fs[1]))
    other = status_frames(4)
    got += [rx.feed(fs[0]), rx.feed(other[1])]
    got += [rx.feed(fs[0]), rx.feed(other[0])]
    # unknown data type (GetNodeInfo-free message 1031 = esc.RPMCommand), unknown node, not DroneCAN
    rpm_type = "uavcan.equipment.esc.RPMCommand"
    rpm_cmd = dc.to_frames(rpm_type, dc.serialize(dc.make(rpm_type, rpm=[1, 2])), 10, 0)
    got += [rx.feed(f) for f in rpm_cmd]
    got += [rx.feed(f) for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([1, 2]), 33, 0)]
    got.append(rx.feed(frame(0x123, b"\x00\xc0", ext=False)))
    got.append(rx.feed(frame(raw.arbitration_id, raw.data, is_remote_frame=False, is_error_frame=True)))
    # service frame and own frames
    got.append(rx.feed(frame(raw.arbitration_id | 0x80, raw.data)))
    got += [rx.feed(f) for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([1, 2]), 5, 0)]
    assert got.count(None) == len(got)
    assert dict(rx.rejects) == {
        dc.WRONG_DLC: 2, dc.BAD_CRC: 1, dc.TOGGLE_ERROR: 1, dc.MISSING_START: 1, dc.TRANSFER_ID_MISMATCH: 1,
        dc.INCOMPLETE_TRANSFER: 1, dc.UNKNOWN_DATA_TYPE: 1, dc.UNKNOWN_NODE: 1, dc.NOT_DRONECAN: 2,
        dc.SERVICE_OR_ANONYMOUS: 1}
    assert rx.own_frames == 1
    # after all that, a good transfer still goes through
    assert [rx.feed(f) for f in status_frames(9)][-1].msg.rpm == 1234


def test_transfer_id_tracker_counts_gaps_and_duplicates_across_the_wrap():
    tr = dc.TransferIdTracker()
    rx = dc.TransferReceiver([dc.RAW_COMMAND])
    for tid in [30, 31, 0, 3, 3, 4]:  # 1 and 2 lost, 3 duplicated
        [t] = [rx.feed(f) for f in dc.to_frames(dc.RAW_COMMAND, dc.raw_command([0, 0]), 10, tid)]
        tr.observe(t)
    assert tr.received == {"RawCommand@10": 5}
    assert tr.lost == {"RawCommand@10": 2}
    assert tr.duplicated == {"RawCommand@10": 1}


# -- the integer-arithmetic layouts of the command path against the dronecan package ---------------

def _reference(name, payload):
    """(accepted, fields) as the dronecan package decodes ``payload`` (decode, then re-encode check)."""
    msg = dc.decode(dc.data_type(name), payload)
    if msg is None:
        return False, None
    if name == dc.RAW_COMMAND:
        return True, {"cmd": [int(v) for v in msg.cmd]}
    return True, {k: int(getattr(msg, k)) for k in
                  ("uptime_sec", "health", "mode", "sub_mode", "vendor_specific_status_code")}


def _fast(name, payload):
    ns = dronecan_layout.unpack(dc.FAST_LAYOUTS[name], payload)
    return (False, None) if ns is None else (True, vars(ns))


def test_fast_encoding_is_byte_identical_to_the_dronecan_package():
    rng = np.random.default_rng(7)
    for n in list(range(21)) * 20:
        cmd = [int(v) for v in rng.integers(-8192, 8192, n)]
        expected = dc.serialize(dc.make(dc.RAW_COMMAND, cmd=cmd))
        assert dronecan_layout.pack(dronecan_layout.RAW_COMMAND, {}, cmd) == expected
    for _ in range(300):
        f = {"uptime_sec": int(rng.integers(0, 2**32)), "health": int(rng.integers(0, 4)),
             "mode": int(rng.integers(0, 8)),
             "sub_mode": int(rng.integers(0, 8)), "vendor_specific_status_code": int(rng.integers(0, 2**16))}
        assert dronecan_layout.pack(dronecan_layout.NODE_STATUS, f) == dc.serialize(dc.make(dc.NODE_STATUS, **f))
    assert dc.raw_command([8191, -8191]) == dc.serialize(dc.make(dc.RAW_COMMAND, cmd=[8191, -8191]))
    with pytest.raises(ValueError):
        dronecan_layout.pack(dronecan_layout.RAW_COMMAND, {}, [8192])
    with pytest.raises(ValueError):
        dronecan_layout.pack(dronecan_layout.RAW_COMMAND, {}, [0] * 21)


@pytest.mark.parametrize("name,max_len", [(dc.RAW_COMMAND, 40), (dc.NODE_STATUS, 12)])
def test_fast_decoding_accepts_and_refuses_exactly_what_the_dronecan_package_does(name, max_len):
    """Random payloads of every length, and canonical ones with one bit flipped (padding included):
    the same verdict and the same field values as decoding with the dronecan package."""
    rng = np.random.default_rng(11)
    payloads = [bytes(rng.integers(0, 256, n, dtype=np.uint8)) for n in range(max_len + 1) for _ in range(40)]
    payloads += [bytes(n) for n in range(max_len + 1)]  # all zero: only the padding rule refuses most
    for n in range(21):
        good = dc.raw_command(rng.integers(-8191, 8192, n)) if name == dc.RAW_COMMAND else dc.node_status(n, 1, 2, n)
        payloads.append(good)
        for bit in range(8 * len(good)):
            b = bytearray(good)
            b[bit // 8] ^= 1 << (bit % 8)
            payloads.append(bytes(b))
    accepted = 0
    for p in payloads:
        ours, ref = _fast(name, p), _reference(name, p)
        assert ours == ref, p.hex()
        accepted += ours[0]
    assert 0 < accepted < len(payloads)  # both verdicts were exercised
