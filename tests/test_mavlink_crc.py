"""pymavlink's CRC back-end: fastcrc (a dependency, for speed) must give the checksums of its
reference loop, and the frames we encode must carry the checksum the reference computes."""

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from common.mavlink import CRC_BACKEND, Codec


def test_pymavlink_uses_fastcrc():
    # A missing fastcrc still works, 3-4x slower per frame: the install must bring it (pyproject.toml).
    assert CRC_BACKEND == "fastcrc"
    assert mavlink2.x25crc is mavlink2._x25crc_fast


def test_fast_crc_equals_the_reference_loop_on_random_bytes():
    rng = np.random.default_rng(7)
    for n in list(range(0, 40)) + [255, 280, 1000]:
        buf = rng.integers(0, 256, size=n, dtype=np.uint8).tobytes()
        assert mavlink2._x25crc_fast(buf).crc == mavlink2._x25crc_slow(buf).crc, n
        # accumulated in two pieces, as pymavlink adds the CRC_EXTRA byte after the frame
        fast, slow = mavlink2._x25crc_fast(buf[: n // 2]), mavlink2._x25crc_slow(buf[: n // 2])
        fast.accumulate(buf[n // 2:])
        slow.accumulate(buf[n // 2:])
        assert fast.crc == slow.crc


def test_encoded_hil_frames_carry_the_reference_checksum():
    c = Codec(1, 51)
    frames = [c.encode("hil_sensor", 123456, *[0.25] * 9, 0.0, 0.0, 0.0, 0.0, 0x1FF),
              c.encode("hil_actuator_controls", 123456, [0.5, -0.25] + [0.0] * 14, 128, 0),
              c.encode("hil_gps", 123456, 3, 600000000, 100000000, 0, 100, 200, 150, 100, 50, 0, 9000, 12)]
    for f in frames:
        msgid = f[7] | f[8] << 8 | f[9] << 16
        crc = mavlink2._x25crc_slow(f[1:-2])
        crc.accumulate(bytes([mavlink2.mavlink_map[msgid].crc_extra]))
        assert crc.crc == f[-2] | f[-1] << 8
