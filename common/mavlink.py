"""MAVLink 2 codec on pymavlink's ``ardupilotmega`` dialect (a superset of ``common``).

:class:`Codec` encodes messages into bytes (one MAVLink 2 frame each, sequence numbers counted
from 0, so a run is reproducible byte for byte) and decodes one UDP datagram at a time into the
messages it wants, reporting why anything else was rejected so that callers can count it.
Each datagram is parsed on its own: a frame cut at the datagram's end is "truncated", never
joined with the next datagram.

The HIL loop's datagrams are clean (whole, unsigned MAVLink 2 frames with good checksums) and few
kinds: :func:`parse_clean` and :meth:`Codec.encode` handle those without pymavlink's byte-stream
parser and message objects, with the same bytes and messages; everything else goes to pymavlink.
"""

from __future__ import annotations

import inspect
import struct
from collections import namedtuple
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import Any, TypeAlias

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

# Rejection reasons (keys of the counters reported by the simulator and the bridge).
NOT_MAVLINK = "not_mavlink"          # bytes that do not start a MAVLink frame
BAD_CRC = "bad_crc"                  # a frame whose checksum does not match
TRUNCATED = "truncated"              # a frame cut short by the end of the datagram
MALFORMED = "malformed"              # any other framing or payload error
UNKNOWN_MESSAGE = "unknown_message"  # a valid frame of a message id the dialect does not know
UNWANTED_MESSAGE = "unwanted_message"  # a valid, known message this endpoint does not take
REJECT_REASONS = (NOT_MAVLINK, BAD_CRC, TRUNCATED, MALFORMED, UNKNOWN_MESSAGE, UNWANTED_MESSAGE)

MAV_TYPE = mavlink2  # the dialect module, for enums (e.g. MAV_FRAME_BODY_FRD)

# A decoded MAVLink message, project-wide. pymavlink generates one class per message from the XML
# dialect and ships no type information, so to mypy this is Any: its fields are read unchecked.
MavMessage: TypeAlias = mavlink2.MAVLink_message
# A message's fields by name: the pymavlink message, or a named tuple type made at run time from its
# class (:func:`_fields`). Its attributes exist only at run time.
MavFields: TypeAlias = Any
# One field's value as ``struct`` packs it (int, float, bytes, or a list of them for an array;
# typeshed types struct's values as Any): which one depends on the message and the field.
MavValue: TypeAlias = Any

# pymavlink checks every frame's CRC-16/MCRF4XX with the fastcrc package where it is installed (a
# dependency of ours) and with a byte-by-byte Python loop otherwise: 22 against 6 us to encode a
# HIL_SENSOR, the same checksums. Benchmarks report which one ran.
CRC_BACKEND = "fastcrc" if getattr(mavlink2, "mcrf4xx", None) is not None else "python"

_V2_STX, _V2_HEADER, _CRC_LEN = 0xFD, 10, 2


class _Layout:
    """What pymavlink's ``MAVLink.decode`` needs of one message class, worked out once: the payload
    unpacker, and how its wire-ordered (largest type first) values become the declared fields."""

    __slots__ = ("cls", "crc_extra", "size", "unpack", "order", "spans", "strings", "texts", "_view")

    def __init__(self, cls: type[MavMessage]) -> None:
        self.cls, self.crc_extra = cls, bytes((cls.crc_extra,))
        self.size, self.unpack = cls.unpacker.size, cls.unpacker.unpack
        lengths = cls.lengths
        if sum(lengths) == len(lengths):     # no arrays: a permutation of the unpacked values
            self.order: tuple[int, ...] | None = tuple(cls.orders)
            self.spans: tuple[tuple[int, int], ...] = ()
        else:                                # arrays: (first value, count) per declared field
            self.order = None
            self.spans = tuple((sum(lengths[:o]), lengths[o]) for o in cls.orders)
        self.strings = "s" in cls.unpacker.format
        # char arrays, which the message's constructor turns into text (to the first NUL, ASCII)
        self.texts = tuple(i for i, t in enumerate(cls.fieldtypes) if t == "char")
        self._view: type[MavFields] | None = None

    def view(self) -> type[MavFields]:
        """A named tuple type of the message's fields (pymavlink's names, declared order), made once."""
        if self._view is None:
            self._view = namedtuple(self.cls.msgname, self.cls.fieldnames, rename=True)  # type: ignore[misc]
        return self._view

    def fields(self, payload: bytes) -> list[MavValue]:
        t = self.unpack(payload)
        if self.order is not None:
            out: list[MavValue] = [t[o] for o in self.order]
        else:
            out = [t[tip] if n == 1 or isinstance(t[tip], bytes) else list(t[tip:tip + n]) for tip, n in self.spans]
        if self.strings:
            out = [e.rstrip(b"\x00") if isinstance(e, bytes) else e for e in out]
        return out


_LAYOUTS = {msg_id: _Layout(cls) for msg_id, cls in mavlink2.mavlink_map.items()}
_mcrf4xx: Callable[[bytes], int] | None = getattr(mavlink2, "mcrf4xx", None)


def parse_clean(datagram: bytes) -> list[mavlink2.MAVLink_message] | None:
    """The messages of a datagram made only of whole, unsigned MAVLink 2 frames of known ids with
    good checksums - what a sender of ours writes - or None for anything else.

    Each message is what pymavlink's parser makes of the same bytes (class, fields, header, frame
    bytes; tests/test_mavlink_fast_path.py compares them), built in one pass over the datagram instead
    of pymavlink's byte-stream state machine, at a third to a half of its cost (docs/performance.md).
    The caller parses a None datagram with pymavlink, which then names what is wrong with it.
    """
    if _mcrf4xx is None:
        return None
    try:
        return _parse_clean(datagram, _mcrf4xx)
    except Exception:   # whatever the bytes (or a buffer type it does not expect): pymavlink decides
        return None


def clean_frames(datagram: bytes) -> list[tuple[int, int]] | None:
    """The (start, end) of each frame of a datagram :func:`parse_clean` takes (every check made,
    the checksums included), or None where it would give None: for a reader that builds message
    objects only for some of the frames (:func:`frame_ids`, :func:`message_at`)."""
    if _mcrf4xx is None:
        return None
    try:
        spans = _walk(datagram, _mcrf4xx)
    except Exception:   # as parse_clean: pymavlink decides
        return None
    return None if spans is None else [(i, end) for i, end, _ in spans]


def frame_ids(datagram: bytes, start: int) -> tuple[int, int, int]:
    """(message id, source system, source component) of the frame at ``start`` of a clean datagram."""
    return (datagram[start + 7] | datagram[start + 8] << 8 | datagram[start + 9] << 16,
            datagram[start + 5], datagram[start + 6])


def leading_uint64(datagram: bytes, start: int, end: int) -> int:
    """The first 8 payload bytes of the clean frame ``datagram[start:end]`` as a little-endian
    uint64 (MAVLink 2 trims a payload's trailing zeros: missing bytes are 0): the first wire field
    of a message whose largest field comes first, e.g. HIL_SENSOR's ``time_usec``."""
    first = bytes(datagram[start + _V2_HEADER:min(end - _CRC_LEN, start + _V2_HEADER + 8)])
    return int.from_bytes(first.ljust(8, b"\0"), "little")


def message_at(datagram: bytes, start: int, end: int) -> mavlink2.MAVLink_message:
    """The message of the frame ``datagram[start:end]`` found by :func:`clean_frames`."""
    return _message(datagram, start, end, _LAYOUTS[frame_ids(datagram, start)[0]])


def _fields(datagram: bytes, start: int, end: int, layout: _Layout) -> MavFields:
    """The fields of the clean frame ``datagram[start:end]`` by name: a named tuple of the values
    :func:`message_at`'s message holds (char arrays made text as its constructor makes them),
    without building the message."""
    values = layout.fields(_payload(datagram, start, end, layout))
    for i in layout.texts:
        values[i] = values[i].split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return layout.view()._make(values)


def _walk(datagram: bytes, crc16: Callable[[bytes], int]) -> list[tuple[int, int, _Layout]] | None:
    n, i, out = len(datagram), 0, []
    while i < n:
        # incompat_flags 0: unsigned (and no flag this parser does not know)
        if n - i < _V2_HEADER + _CRC_LEN or datagram[i] != _V2_STX or datagram[i + 2] != 0:
            return None
        end = i + _V2_HEADER + datagram[i + 1] + _CRC_LEN
        if end > n:
            return None
        layout = _LAYOUTS.get(datagram[i + 7] | datagram[i + 8] << 8 | datagram[i + 9] << 16)
        if layout is None:
            return None
        if crc16(datagram[i + 1:end - 2] + layout.crc_extra) != datagram[end - 2] | datagram[end - 1] << 8:
            return None
        out.append((i, end, layout))
        i = end
    return out


def _payload(datagram: bytes, i: int, end: int, layout: _Layout) -> bytes:
    length = datagram[i + 1]
    payload = datagram[i + _V2_HEADER:end - 2]
    if length < layout.size:   # MAVLink 2 drops the payload's trailing zeros
        payload += bytes(layout.size - length)
    return payload[:layout.size]


def _message(datagram: bytes, i: int, end: int, layout: _Layout) -> mavlink2.MAVLink_message:
    length = datagram[i + 1]
    m = layout.cls(*layout.fields(_payload(datagram, i, end, layout)))   # an error: pymavlink reports it
    frame = bytearray(datagram[i:end])
    m._msgbuf, m._payload, m._crc = frame, frame[6:-2], datagram[end - 2] | datagram[end - 1] << 8   # pymavlink's
    m._header = mavlink2.MAVLink_header(layout.cls.id, 0, datagram[i + 3], length, datagram[i + 4],
                                        datagram[i + 5], datagram[i + 6])
    return m


def _parse_clean(datagram: bytes, crc16: Callable[[bytes], int]) -> list[mavlink2.MAVLink_message] | None:
    spans = _walk(datagram, crc16)
    return None if spans is None else [_message(datagram, i, end, layout) for i, end, layout in spans]


def _itself(m: MavMessage) -> MavMessage:
    return m


def reset_parser(mav: mavlink2.MAVLink) -> None:
    """Forget whatever a pymavlink parser holds: the next bytes start a new frame."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavlink2.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False


def bad_data_reason(bad: mavlink2.MAVLink_bad_data) -> str:
    """The rejection reason of a frame pymavlink could not parse: the one classifier of every
    MAVLink endpoint (HIL link, simulator, ground-station link)."""
    reason = str(getattr(bad, "reason", "")).lower()
    if "prefix" in reason:
        return NOT_MAVLINK
    if "crc" in reason:
        return BAD_CRC
    return MALFORMED


class _Encoder:
    """What pymavlink's ``<name>_encode`` and ``pack`` do for one message without text fields,
    worked out once: the encode() arguments in wire order, arrays spread out, into the payload."""

    __slots__ = ("msg_id", "crc_extra", "pack", "names", "defaults", "wire", "declared_order")

    def __init__(self, cls: type[MavMessage]) -> None:
        encode = getattr(mavlink2.MAVLink, f"{cls.msgname.lower()}_encode")
        params = list(inspect.signature(encode).parameters.values())[1:]   # after self
        self.msg_id, self.crc_extra, self.pack = cls.id, bytes((cls.crc_extra,)), cls.unpacker.pack
        self.names = tuple(p.name for p in params)          # the declared order, encode()'s
        self.defaults = tuple(p.default for p in params)    # extension fields default to 0
        count = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
        self.wire = tuple((self.names.index(n), count[n]) for n in cls.ordered_fieldnames)
        # no arrays, and the wire order is encode()'s (HIL_SENSOR, HIL_GPS...): the values go as they are
        self.declared_order = all(not n and i == k for k, (i, n) in enumerate(self.wire))

    def payload(self, args: tuple[MavValue, ...], kwargs: dict[str, MavValue]) -> bytes | None:
        """The full (untrimmed) payload, or None where encode() would complain (pymavlink then says how)."""
        if not kwargs and len(args) <= len(self.names):   # the usual call: positional, defaults after
            tail = self.defaults[len(args):]
            if inspect.Parameter.empty in tail:
                return None
            if self.declared_order:
                return self.pack(*args, *tail)
            values: Sequence[MavValue] = args + tail
        else:
            named = self._values(args, kwargs)
            if named is None:
                return None
            values = named
        flat: list[MavValue] = []
        for i, n in self.wire:
            v = values[i]
            if n:
                flat.extend([v[j] for j in range(n)])
            else:
                flat.append(v)
        return self.pack(*flat)

    def _values(self, args: tuple[MavValue, ...], kwargs: dict[str, MavValue]) -> list[MavValue] | None:
        """encode()'s arguments in declared order, defaults filled in (None where it would complain)."""
        if len(args) > len(self.names):
            return None
        values, taken = list(args), 0
        for name, default in zip(self.names[len(args):], self.defaults[len(args):], strict=True):
            if name in kwargs:
                values.append(kwargs[name])
                taken += 1
            elif default is inspect.Parameter.empty:
                return None
            else:
                values.append(default)
        if taken != len(kwargs):
            return None
        return values


_BY_NAME = {cls.msgname.lower(): cls for cls in mavlink2.mavlink_map.values()}
_ENCODERS: dict[str, _Encoder | None] = {}   # built on first use: all of them cost ~9 ms at import


def _encoder(name: str) -> _Encoder | None:
    """The :class:`_Encoder` of message ``name`` (None: unknown, or it has text fields)."""
    if name not in _ENCODERS:
        cls = _BY_NAME.get(name)
        _ENCODERS[name] = _Encoder(cls) if cls is not None and "s" not in cls.unpacker.format else None
    return _ENCODERS[name]
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")


class Codec:
    """Encoder/decoder for one MAVLink endpoint (system id, component id, accepted message types)."""

    def __init__(self, system_id: int, component_id: int, accept: Iterable[str] = ()) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        self.accept = frozenset(accept)

    # -- encoding --------------------------------------------------------------------------
    def pack(self, msg: mavlink2.MAVLink_message) -> bytes:
        """One MAVLink 2 frame of ``msg``; advances the sequence number."""
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        return bytes(buf)

    def encode(self, name: str, *args: MavValue, **kwargs: MavValue) -> bytes:
        """Frame of message ``name`` (e.g. ``"hil_sensor"``) built from its encode() arguments.

        Unsigned messages without text fields are framed here, byte for byte as pymavlink frames
        them (tests/test_mavlink_fast_path.py), without building a message object: a third of the
        cost. Anything else, or arguments encode() would refuse, goes through pymavlink."""
        enc = _encoder(name)
        if enc is not None and _mcrf4xx is not None and not self.mav.signing.sign_outgoing:
            try:
                payload = enc.payload(args, kwargs)
            except (IndexError, TypeError, KeyError, struct.error):
                payload = None
            if payload is not None:
                return self._frame(enc, payload)
        return self.pack(getattr(self.mav, f"{name}_encode")(*args, **kwargs))

    def _frame(self, enc: _Encoder, payload: bytes) -> bytes:
        """pymavlink's MAVLink_message._pack for an unsigned MAVLink 2 frame; advances the sequence number."""
        payload = payload.rstrip(b"\x00") or payload[:1]    # MAVLink 2 trims trailing zeros, keeps one byte
        mav = self.mav
        header = _HEADER.pack(_V2_STX, len(payload), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent,
                              enc.msg_id & 0xFFFF, enc.msg_id >> 16)
        body = header + payload
        assert _mcrf4xx is not None
        frame = body + _CRC.pack(_mcrf4xx(body[1:] + enc.crc_extra))
        mav.seq = (mav.seq + 1) % 256
        return frame

    # -- decoding --------------------------------------------------------------------------
    def _reset_parser(self) -> None:
        reset_parser(self.mav)

    def decode(self, datagram: bytes) -> tuple[list[mavlink2.MAVLink_message], list[str]]:
        """Accepted messages of one datagram, and the rejection reason of every rejected part."""
        clean = parse_clean(datagram) if self.mav.signing.secret_key is None else None
        if clean is not None:
            self.mav.total_bytes_received += len(datagram)
            self.mav.total_packets_received += len(clean)
            accepted = [m for m in clean if m.get_type() in self.accept]
            return accepted, [UNWANTED_MESSAGE] * (len(clean) - len(accepted))
        return self.decode_stream(datagram)

    def frames(self, datagram: bytes) -> tuple[list[tuple[str, int, int, Callable[[], MavFields]]], list[str]]:
        """:meth:`decode` for a reader that needs the fields of some messages only: each accepted
        message as (type, source system, source component, fields), where ``fields()`` gives its
        fields by name. On a clean datagram they are read from the frame when asked for
        (:func:`_fields`), and no message object is built; anything else is the message
        pymavlink parsed. The same messages, values and rejections as :meth:`decode`."""
        spans = clean_frames(datagram) if self.mav.signing.secret_key is None else None
        if spans is None:   # not clean, or signed: what decode() would do with it
            msgs, rejects = self.decode_stream(datagram)
            return [(m.get_type(), m.get_srcSystem(), m.get_srcComponent(), partial(_itself, m)) for m in msgs], rejects
        self.mav.total_bytes_received += len(datagram)
        self.mav.total_packets_received += len(spans)
        out: list[tuple[str, int, int, Callable[[], MavFields]]] = []
        for start, end in spans:
            msg_id, system, component = frame_ids(datagram, start)
            layout = _LAYOUTS[msg_id]
            if layout.cls.msgname in self.accept:
                out.append((layout.cls.msgname, system, component, partial(_fields, datagram, start, end, layout)))
        return out, [UNWANTED_MESSAGE] * (len(spans) - len(out))

    def decode_stream(self, datagram: bytes) -> tuple[list[mavlink2.MAVLink_message], list[str]]:
        """:meth:`decode` through pymavlink's parser alone (any datagram; signed frames)."""
        self._reset_parser()
        accepted: list[mavlink2.MAVLink_message] = []
        rejects: list[str] = []
        try:
            msgs = self.mav.parse_buffer(datagram) or []
        except Exception:  # pymavlink raises struct/Value errors on some corrupt payloads
            self._reset_parser()
            return [], [MALFORMED]
        for m in msgs:
            if isinstance(m, mavlink2.MAVLink_bad_data):
                rejects.append(bad_data_reason(m))
            elif isinstance(m, mavlink2.MAVLink_unknown):
                rejects.append(UNKNOWN_MESSAGE)
            elif m.get_type() in self.accept:
                accepted.append(m)
            else:
                rejects.append(UNWANTED_MESSAGE)
        if self.mav.buf_len() > 0:
            rejects.append(TRUNCATED)
        self._reset_parser()
        return accepted, rejects
