"""The link pieces on their own: UDP endpoint (fan-out, newest-only, loss injection), MAVLink codec
reject reasons, and the lockstep re-send that keeps a lost datagram from deadlocking the loop."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from common.mavlink import BAD_CRC, NOT_MAVLINK, TRUNCATED, UNKNOWN_MESSAGE, UNWANTED_MESSAGE, Codec
from common.udp import UdpEndpoint, parse_hostport
from hil.commands.run import HilClient, stop_process
from tests.conftest import REPO


def test_parse_hostport():
    assert parse_hostport("127.0.0.1:14560") == ("127.0.0.1", 14560)
    for bad in ("127.0.0.1", ":80", "host:port", "h:70000"):
        with pytest.raises(ValueError, match="'"):
            parse_hostport(bad)


def test_fan_out_and_drain_latest():
    with UdpEndpoint() as a, UdpEndpoint() as b, UdpEndpoint() as src:
        for ep in (a, b):
            src.add_destination(ep.address)
        for i in range(5):
            src.send(bytes([i]))
        got = [b.recv(timeout=5.0) for _ in range(5)]  # recv: oldest first, nothing lost on loopback
        assert got == [bytes([i]) for i in range(5)]
        assert a.recv(timeout=5.0) == b"\x00"
        src.send(b"\x05")
        assert b.recv(timeout=5.0) == b"\x05"
        # a holds 1..5 now: drain_latest keeps only the newest
        assert a.drain_latest() == b"\x05" and a.drain_latest() is None
        assert a.last_sender == src.address


def test_seeded_loss_injection():
    def count(seed):
        with UdpEndpoint() as rx, UdpEndpoint(send_loss=0.2, loss_seed=seed) as tx:
            tx.add_destination(rx.address)
            for i in range(2000):
                tx.send(i.to_bytes(2, "little"))
            return tx.dropped_out, tx.sent
    dropped, sent = count(3)
    assert dropped + sent == 2000
    assert dropped == pytest.approx(400, abs=4 * np.sqrt(2000 * 0.2 * 0.8))
    assert count(3) == (dropped, sent)
    with pytest.raises(ValueError):
        UdpEndpoint(recv_loss=1.5)


def test_codec_reject_reasons():
    tx, rx = Codec(1, 1), Codec(2, 2, accept=("HIL_ACTUATOR_CONTROLS",))
    frame = tx.encode("hil_actuator_controls", 123, [0.1] * 16, 0, 0)
    msgs, rej = rx.decode(frame)
    assert [m.time_usec for m in msgs] == [123] and rej == []
    assert rx.decode(b"\x00\x01\x02")[1] == [NOT_MAVLINK]
    assert rx.decode(frame[:-1])[1] == [TRUNCATED]
    bad = bytearray(frame)
    bad[-1] ^= 0xFF
    assert rx.decode(bytes(bad))[1] == [BAD_CRC]
    assert rx.decode(tx.encode("heartbeat", 1, 2, 3, 4, 5))[1] == [UNWANTED_MESSAGE]
    # a well-formed MAVLink 2 frame of an id no dialect knows (CRC cannot be checked): unknown
    unknown = bytes([0xFD, 1, 0, 0, 0, 1, 1, 0x39, 0x30, 0x00, 7, 0, 0])
    assert rx.decode(unknown)[1][0] in (UNKNOWN_MESSAGE, BAD_CRC)
    # two commands in one datagram are both returned, in order
    both = frame + tx.encode("hil_actuator_controls", 124, [0.2] * 16, 0, 0)
    assert [m.time_usec for m in rx.decode(both)[0]] == [123, 124]


def test_lockstep_resends_the_latest_frame_when_a_command_is_lost():
    client = HilClient()
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil", "sim", "--json", "--lockstep", "--duration", "0.05",
         "--state-to", f"127.0.0.1:{client.port}", "--commands-on", "127.0.0.1:0",
         "--set", "sim.lockstep_resend=0.2"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = client.next_frame(timeout=20.0)
        assert first is not None and first.time_usec == 0
        # do not answer: the "command was lost"; the simulator must re-send the same bytes
        again = client.next_frame(timeout=20.0)
        assert again is not None and again.raw == first.raw
        frame = again
        for k in range(5):
            client.command(frame.time_usec, 0.5, 0.5)
            frame = client.next_frame(timeout=20.0)
            assert frame is not None and frame.time_usec == (k + 1) * 10_000
        out, err = proc.communicate(timeout=30)
    finally:
        stop_process(proc)
        client.close()
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["lockstep_resends"] >= 1 and summary["steps"] == 5


def test_one_reject_classifier_for_every_mavlink_endpoint():
    """The HIL codec and the ground-station link's parser share common.mavlink.bad_data_reason: a
    corrupted checksum is bad_crc at both (they had diverged on the message's capitalisation)."""
    from autopilot_bridge.gcs.framing import FrameParser
    from common.mavlink import BAD_CRC, Codec, bad_data_reason, mavlink2

    frame = bytearray(Codec(1, 1).encode("heartbeat", 0, 0, 0, 0, 0))
    frame[-1] ^= 0xFF
    _, rejects = Codec(2, 1, accept={"HEARTBEAT"}).decode(bytes(frame))
    assert rejects == [BAD_CRC]
    assert FrameParser(None).parse(bytes(frame), keep=False, max_frames=32).rejects == [BAD_CRC]
    for text, want in (("invalid MAVLink prefix '0'", "not_mavlink"), ("invalid MAVLink CRC", "bad_crc"),
                       ("invalid crc", "bad_crc"), ("Bad signature", "malformed")):
        assert bad_data_reason(mavlink2.MAVLink_bad_data(b"x", text)) == want
