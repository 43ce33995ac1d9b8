"""common.mavlink's short cuts past pymavlink. parse_clean, the one-pass parser of clean datagrams,
gives what pymavlink's parser gives, message for message, on every message of the dialect with
random fields, and any datagram it does not take (corrupt, signed, MAVLink 1, unknown ids) is left
to pymavlink, which names the fault. Codec.encode frames every message without text fields byte
for byte as pymavlink does, and refuses what pymavlink refuses."""

from __future__ import annotations

import random
import struct

import pytest

from common.mavlink import UNWANTED_MESSAGE, Codec, mavlink2, parse_clean

EVERY = [cls.msgname for cls in mavlink2.mavlink_map.values()]


def _value(rng: random.Random, ftype: str) -> object:
    if ftype == "float":
        return struct.unpack("<f", struct.pack("<f", rng.choice([0.0, -0.0, rng.uniform(-1e6, 1e6), float("nan")])))[0]
    if ftype == "double":
        return rng.choice([0.0, rng.uniform(-1e12, 1e12), float("inf")])
    bits = int(ftype.rstrip("_t").lstrip("u").replace("int", "") or 8) if "int" in ftype else 8
    if ftype.startswith("u") or ftype == "char":
        return rng.choice([0, rng.randrange(1 << bits)])
    return rng.choice([0, rng.randrange(-(1 << (bits - 1)), 1 << (bits - 1))])


def random_message(rng: random.Random, cls: type) -> mavlink2.MAVLink_message:
    """An instance of ``cls`` with random fields: zeros often (MAVLink 2 trims trailing zeros), NaN."""
    args = []
    counts = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))   # array_lengths: wire order
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        n = counts[name]
        if ftype == "char":
            k = rng.randrange(n + 1) if n else 1
            args.append(bytes(rng.randrange(32, 127) for _ in range(k)) if n else bytes([rng.randrange(32, 127)]))
        elif n:
            args.append([_value(rng, ftype) for _ in range(n)])
        else:
            args.append(_value(rng, ftype))
    return cls(*args)


def same_messages(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert type(x) is type(y)
        assert repr(x.to_dict()) == repr(y.to_dict())          # repr: NaN == NaN, -0.0 != 0.0
        assert x.get_msgbuf() == y.get_msgbuf() and type(x.get_msgbuf()) is type(y.get_msgbuf())
        assert x.get_payload() == y.get_payload() and x.get_crc() == y.get_crc()
        assert vars(x.get_header()) == vars(y.get_header())
        assert x.get_srcSystem() == y.get_srcSystem() and x.get_seq() == y.get_seq()
        assert {k: repr(v) for k, v in vars(x).items() if k != "_header"} == \
            {k: repr(v) for k, v in vars(y).items() if k != "_header"}


def encoded(rng: random.Random, k: int) -> tuple[bytes, Codec]:
    tx = Codec(rng.randrange(1, 255), rng.randrange(1, 255))
    frames = [tx.pack(random_message(rng, rng.choice(list(mavlink2.mavlink_map.values())))) for _ in range(k)]
    return b"".join(frames), tx


def test_every_message_of_the_dialect_parses_as_pymavlink_parses_it() -> None:
    rng = random.Random(7)
    rx = Codec(255, 190, accept=EVERY)
    for cls in mavlink2.mavlink_map.values():
        for _ in range(3):
            data = Codec(rng.randrange(1, 255), rng.randrange(1, 255)).pack(random_message(rng, cls))
            fast = parse_clean(data)
            assert fast is not None, cls.msgname
            slow, rejects = rx.decode_stream(data)
            assert rejects == []
            same_messages(fast, slow)


def test_datagrams_of_several_frames_and_the_accept_filter() -> None:
    rng = random.Random(11)
    rx = Codec(255, 190, accept=EVERY)
    for _ in range(200):
        data, _ = encoded(rng, rng.randrange(0, 6))
        assert parse_clean(data) is not None
        assert rx.decode(data)[1] == rx.decode_stream(data)[1] == []
        same_messages(rx.decode(data)[0], rx.decode_stream(data)[0])
    rx = Codec(255, 190, accept=("HIL_SENSOR", "HIL_GPS", "HEARTBEAT"))
    data = Codec(1, 1).pack(mavlink2.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3)) + \
        Codec(1, 1).pack(mavlink2.MAVLink_system_time_message(1, 2))
    msgs, rejects = rx.decode(data)
    assert [m.get_type() for m in msgs] == ["HEARTBEAT"] and rejects == [UNWANTED_MESSAGE]


def test_a_payload_longer_than_this_dialect_knows_is_cut_as_pymavlink_cuts_it() -> None:
    """A sender with a newer dialect appends extension fields this one does not know."""
    from fastcrc import crc16

    rng = random.Random(3)
    rx = Codec(255, 190, accept=EVERY)
    for cls in rng.sample(list(mavlink2.mavlink_map.values()), 40):
        frame = bytearray(Codec(1, 1).pack(random_message(rng, cls)))
        extra = bytes(rng.randrange(1, 256) for _ in range(rng.randrange(1, 8)))
        length = frame[1] + len(extra)
        if length > 255:
            continue
        frame = frame[:1] + bytes([length]) + frame[2:-2] + extra
        frame += struct.pack("<H", crc16.mcrf4xx(bytes(frame[1:]) + bytes([cls.crc_extra])))
        fast = parse_clean(bytes(frame))
        assert fast is not None
        same_messages(fast, rx.decode_stream(bytes(frame))[0])


def test_a_datagram_it_does_not_take_gets_pymavlinks_verdict() -> None:
    """Flipped bytes, cuts, junk, MAVLink 1: parse_clean refuses whatever is not clean, and
    Codec.decode then says exactly what pymavlink's parser says (accepted messages and rejects)."""
    rng = random.Random(5)
    rx = Codec(255, 190, accept=EVERY)
    refused = 0
    for trial in range(600):
        data, _ = encoded(rng, rng.randrange(1, 4))
        b = bytearray(data)
        kind = trial % 4
        if kind == 0:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        elif kind == 1:
            b = b[:rng.randrange(len(b))]
        elif kind == 2:
            b[rng.randrange(len(b) + 1):0] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 5)))
        else:
            b += bytes(rng.randrange(1, 12))
        d = bytes(b)
        refused += parse_clean(d) is None
        fast, slow = rx.decode(d), rx.decode_stream(d)
        assert fast[1] == slow[1]
        same_messages(fast[0], slow[0])
    assert refused > 500   # nearly every damaged datagram is refused; the rest are clean frames still


def test_mavlink1_unknown_ids_and_signed_frames_go_to_pymavlink() -> None:
    v1 = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    data = bytes(mavlink2.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3).pack(v1, force_mavlink1=True))
    assert parse_clean(data) is None
    rx = Codec(255, 190, accept=EVERY)
    assert [m.get_type() for m in rx.decode(data)[0]] == ["HEARTBEAT"]
    unknown = bytearray(Codec(1, 1).pack(mavlink2.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3)))
    unknown[7:10] = (0x00, 0xF0, 0x7F)     # an id no dialect has
    assert parse_clean(bytes(unknown)) is None
    tx = Codec(1, 1)
    tx.mav.signing.secret_key, tx.mav.signing.sign_outgoing, tx.mav.signing.timestamp = bytes(32), True, 1
    signed = tx.pack(mavlink2.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3))
    assert signed[2] == 0x01 and parse_clean(signed) is None
    assert [m.get_type() for m in rx.decode(signed)[0]] == ["HEARTBEAT"]   # pymavlink's verdict: no key here


@pytest.mark.parametrize("key", [bytes(range(32))])
def test_a_codec_that_checks_signatures_never_takes_the_shortcut(key: bytes) -> None:
    rx = Codec(255, 190, accept=EVERY)
    rx.mav.signing.secret_key = key
    rx.mav.signing.allow_unsigned_callback = lambda _mav, _msgid: False
    data = Codec(1, 1).pack(mavlink2.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3))
    assert parse_clean(data) is not None            # a clean frame, but unsigned
    msgs, rejects = rx.decode(data)
    assert msgs == [] and rejects == ["malformed"]  # "Invalid signature": refused as pymavlink refuses it


def encode_args(rng: random.Random, cls: type) -> tuple[list, dict]:
    """encode() arguments of a random ``cls``: positional, the last few as keywords, or extension
    fields left to their defaults."""
    m = random_message(rng, cls)
    values = [getattr(m, n) for n in cls.fieldnames]
    cut = rng.randrange(len(values) + 1)
    args, kwargs = values[:cut], dict(zip(cls.fieldnames[cut:], values[cut:], strict=True))
    if kwargs and rng.random() < 0.3:
        kwargs.popitem()        # an extension field (or a required one: encode() must then refuse)
    return args, kwargs


def test_encode_frames_byte_for_byte_as_pymavlink_does() -> None:
    rng = random.Random(13)
    fast, slow = Codec(17, 42), Codec(17, 42)
    framed = refused = 0
    for _ in range(12):
        for cls in mavlink2.mavlink_map.values():
            args, kwargs = encode_args(rng, cls)
            name = cls.msgname.lower()
            try:
                want = slow.pack(getattr(slow.mav, f"{name}_encode")(*args, **kwargs))
            except Exception as exc:      # pymavlink refuses: so must encode(), the same way
                with pytest.raises(type(exc)):
                    fast.encode(name, *args, **kwargs)
                fast.mav.seq = slow.mav.seq
                refused += 1
                continue
            assert fast.encode(name, *args, **kwargs) == want, name
            framed += 1
    assert framed > 2000 and refused > 0 and fast.mav.seq == slow.mav.seq


def test_signed_links_are_framed_by_pymavlink() -> None:
    a, b = Codec(1, 1), Codec(1, 1)
    for c in (a, b):
        c.mav.signing.secret_key, c.mav.signing.sign_outgoing, c.mav.signing.timestamp = bytes(32), True, 5
    frame = a.encode("hil_actuator_controls", 10, [0.5] * 16, 1, 0)
    assert frame[2] == 0x01 and len(frame) == 12 + frame[1] + 13
    assert frame == b.pack(b.mav.hil_actuator_controls_encode(10, [0.5] * 16, 1, 0))


def test_other_buffer_types_get_the_same_answer() -> None:
    rng = random.Random(17)
    rx = Codec(255, 190, accept=EVERY)
    for _ in range(50):
        data, _ = encoded(rng, rng.randrange(1, 4))
        want = rx.decode(data)
        for buf in (bytearray(data), memoryview(data)):
            got = rx.decode(buf)
            assert got[1] == want[1]
            same_messages(got[0], want[0])
