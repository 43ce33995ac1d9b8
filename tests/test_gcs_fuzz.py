"""Fuzzing the GCS port of a live `hil run`: random bytes, truncated and bit-flipped frames, valid
messages with absurd fields, over UDP and TCP. The boat keeps running, counts the rejects, and still
obeys a proper ground station afterwards. Seeded: the same garbage every time."""

from __future__ import annotations

import json
import math
import socket

import numpy as np
from support.gcs_client import Gcs, M, start_run, stop_run

from common.mavlink import mavlink2
from hil.hilrun import free_udp_port

NAN, INF = float("nan"), float("inf")


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _text(v) -> str:
    return (v.decode(errors="replace") if isinstance(v, (bytes, bytearray)) else str(v)).rstrip("\x00")


def _absurd(mav) -> list:
    """Valid frames whose fields make no sense."""
    cmds = [M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_MISSION_START,
            M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_DO_REPOSITION, 65535, 0]
    out = []
    for c in cmds:
        for v in (NAN, INF, -INF, 1e30, -1e30, 3.0):
            out.append(mav.command_long_encode(1, 1, c, 255, v, v, v, v, v, v, v))
            out.append(mav.command_int_encode(1, 1, 255, c, 255, 255, v, v, v, v, 2**31 - 1, -2**31, v))
    out += [
        mav.mission_count_encode(1, 1, 65535, 0), mav.mission_count_encode(1, 1, 3, 255),
        mav.mission_item_int_encode(1, 1, 65535, 255, 65535, 255, 255, NAN, INF, -INF, NAN, 2**31 - 1, -2**31, INF, 0),
        mav.mission_item_encode(1, 1, 0, 0, 16, 0, 1, NAN, NAN, NAN, NAN, INF, NAN, NAN, 0),
        mav.mission_request_int_encode(1, 1, 65535, 0), mav.mission_request_encode(1, 1, 60000, 7),
        mav.mission_set_current_encode(1, 1, 65535), mav.mission_clear_all_encode(1, 1, 200),
        mav.param_set_encode(1, 1, b"WP_SPEED", NAN, 9), mav.param_set_encode(1, 1, b"\xff\xfe" * 8, INF, 9),
        mav.param_set_encode(1, 1, b"FS_ACTION", 1.5, 9), mav.param_request_read_encode(1, 1, b"", 32767),
        mav.param_request_read_encode(1, 1, b"NOPE", -1), mav.set_mode_encode(1, 1, 4294967295),
        mav.request_data_stream_encode(1, 1, 255, 65535, 1), mav.request_data_stream_encode(1, 1, 0, 0, 1),
        mav.manual_control_encode(1, -32768, 32767, 0, -32768, 65535),
        mav.heartbeat_encode(M.MAV_TYPE_GCS, 255, 255, 2**32 - 1, 255),
    ]
    return out


def test_fuzzing_the_gcs_port_keeps_the_boat_running_and_counts_rejects(tmp_path):
    rng = np.random.default_rng(20190606)
    port, tport = free_udp_port(), _free_tcp_port()
    out = tmp_path / "run"
    proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                     "--gcs", f"udpin:127.0.0.1:{port}", "--gcs", f"tcpin:127.0.0.1:{tport}")
    gcs = Gcs(f"udpout:127.0.0.1:{port}")
    try:
        assert gcs.connect() is not None
        first = gcs.recv("GLOBAL_POSITION_INT", 30)
        mav = mavlink2.MAVLink(None, 66, 66)
        valid = [bytes(m.pack(mav)) for m in _absurd(mav)]
        datagrams = [rng.integers(0, 256, rng.integers(1, 300), dtype=np.uint8).tobytes() for _ in range(300)]
        for f in valid:
            datagrams.append(f)                                                   # absurd but valid
            datagrams.append(f[: rng.integers(1, len(f))])                         # truncated
            b = bytearray(f)
            b[rng.integers(0, len(b))] ^= 1 << int(rng.integers(0, 8))           # one bit flipped
            datagrams.append(bytes(b))
            datagrams.append(b"\xfd" + f[1:8] + rng.integers(0, 256, 40, dtype=np.uint8).tobytes())  # bad payload
        order = rng.permutation(len(datagrams))
        fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tcp = socket.create_connection(("127.0.0.1", tport), timeout=10)
        try:
            for i in order:
                fuzz.sendto(datagrams[i], ("127.0.0.1", port))
                tcp.sendall(datagrams[i])
                gcs.beat()
        finally:
            fuzz.close()
            tcp.close()
        # Still alive, still moving in time, still obeying a proper GCS. (The fuzz may have switched
        # streams off: a rate of 0 is a valid request. Ask for them as MAVProxy does, again until they
        # come: the TCP connection's fuzz, read a frame budget at a time, may still hold a rate-0 request
        # that lands after ours.)
        later = None
        for _ in range(15):
            gcs.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
            later = gcs.recv("GLOBAL_POSITION_INT", 2, lambda m: m.time_boot_ms > first.time_boot_ms)
            if later is not None:
                break
        assert later is not None and proc.poll() is None
        assert gcs.arm(True).result == M.MAV_RESULT_ACCEPTED
        assert gcs.recv("HEARTBEAT", 10, lambda h: h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) is not None
        pv = gcs.param_set("WP_SPEED", 1.5)
        assert pv is not None and math.isclose(pv.param_value, 1.5)
        # The three absurd writes once more, one at a time and answered: the fuzz's own copies may be
        # dropped by a full UDP receive buffer, or swallowed by a TCP parser out of step after garbage.
        for name, value, why in ((b"WP_SPEED", NAN, "WP_SPEED: nan outside"),
                                 (b"\xff\xfe" * 8, INF, "unknown parameter"),
                                 (b"FS_ACTION", 1.5, "FS_ACTION")):
            gcs.drain()
            gcs.mav.param_set_send(1, 1, name, value, M.MAV_PARAM_TYPE_REAL32)
            warn = gcs.recv("STATUSTEXT", 10, lambda t, why=why: _text(t.text).startswith(why))
            assert warn is not None and warn.severity == M.MAV_SEVERITY_WARNING, why
        pv = gcs.param_set("WP_SPEED", NAN)
        assert pv is not None and math.isclose(pv.param_value, 1.5)  # unchanged, and said so
        n_sent = len(datagrams)
    finally:
        gcs.close()
        stop_run(proc)
    g = json.loads((out / "autopilot.json").read_text())["gcs"]
    rejects = g["rejects"]
    assert rejects.get("not_mavlink", 0) > 100 and rejects.get("bad_crc", 0) > 50 and rejects.get("truncated", 0) > 50
    assert sum(rejects.values()) < 10 * n_sent
    assert g["param_rejects"] >= 4  # the paced NaN, unknown name, 1.5 for an integer choice, NaN again
    s = json.loads((out / "summary.json").read_text())["gcs"]
    assert s["rejects"] == rejects and s["datagrams_in"] > s["frames_in"]  # garbage came in, few frames
