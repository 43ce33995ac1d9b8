"""Integer-arithmetic (de)serialisation of the DroneCAN types on the thruster command path.

The ``dronecan`` package serialises through strings of '0'/'1' characters: about 13 us to encode a
RawCommand and as much to decode one on a desktop CPU, twice that inside User-Mode Linux. On the
command path (100 Hz and more, every command on both sides) that was the largest share of our
stack's latency over bare python-can. This module does the same bit layout with Python integers
for the types whose layout is fixed and simple: ``uavcan.equipment.esc.RawCommand`` and
``uavcan.protocol.NodeStatus``. tests/test_can_codec.py checks it against the ``dronecan``
package, which stays the reference and serves every other type.

The DroneCAN bit layout ("Data serialization" in the DroneCAN specification): fields follow one
another with no alignment; a field of n bits is split into little-endian bytes, the last of which
holds the n mod 8 high bits, and each piece enters the stream most significant bit first. The
stream is padded with zeros to whole bytes. The last array of a message uses tail array
optimisation: no length prefix, its length is whatever fills the payload.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property
from types import SimpleNamespace

# RawCommand's value range, here rather than in dronecan_codec so that the simulator and the
# vessel computer can quantise without importing the dronecan package (~0.3 s of start-up).
RAW_COMMAND_MAX = 8191          # int14 command range [-8191, 8191]; negative = reverse


def quantize(normalised: float) -> int:
    """A normalised thruster command in [-1, 1] as a RawCommand value (the ESC's resolution)."""
    x = max(-1.0, min(1.0, float(normalised)))
    return int(round(x * RAW_COMMAND_MAX))


@dataclass(frozen=True)
class Field:
    """One primitive field: ``bits`` wide, ``signed`` two's complement or unsigned."""

    name: str
    bits: int
    signed: bool = False


@dataclass(frozen=True)
class Layout:
    """A message of primitive ``fields`` followed, optionally, by a tail-optimised array of
    ``array`` elements (at most ``array_max``)."""

    fields: tuple[Field, ...]
    array: Field | None = None
    array_max: int = 0

    @cached_property
    def fixed_bits(self) -> int:
        return sum(f.bits for f in self.fields)


def _push(acc: int, value: int, width: int) -> int:
    """Append ``value`` (already reduced to ``width`` unsigned bits) to the stream ``acc``."""
    shift = 0
    while width - shift >= 8:
        acc = (acc << 8) | ((value >> shift) & 0xFF)
        shift += 8
    rest = width - shift
    return (acc << rest) | (value >> shift) if rest else acc


def _pull(stream: int, end: int, width: int) -> int:
    """The unsigned value of ``width`` bits whose first bit is ``end`` bits above the stream's
    least significant bit (``end`` = bits from this field's start to the end of the stream)."""
    value, shift = 0, 0
    while width - shift >= 8:
        end -= 8
        value |= ((stream >> end) & 0xFF) << shift
        shift += 8
    rest = width - shift
    if rest:
        value |= ((stream >> (end - rest)) & ((1 << rest) - 1)) << shift
    return value


def _to_unsigned(f: Field, v: int) -> int:
    if f.signed:
        if not -(1 << (f.bits - 1)) <= v < (1 << (f.bits - 1)):
            raise ValueError(f"{f.name}: {v} does not fit int{f.bits}")
        return v & ((1 << f.bits) - 1)
    if not 0 <= v < (1 << f.bits):
        raise ValueError(f"{f.name}: {v} does not fit uint{f.bits}")
    return v


def _from_unsigned(f: Field, v: int) -> int:
    return v - (1 << f.bits) if f.signed and v >> (f.bits - 1) else v


def pack(layout: Layout, values: dict[str, int], array: Iterable[int] = ()) -> bytes:
    """Payload bytes; ValueError for a value that does not fit its field (never truncated)."""
    acc, nbits = 0, 0
    for f in layout.fields:
        acc = _push(acc, _to_unsigned(f, int(values[f.name])), f.bits)
        nbits += f.bits
    if layout.array is not None:
        a = layout.array
        items = [int(v) for v in array]
        if len(items) > layout.array_max:
            raise ValueError(f"{a.name}: {len(items)} elements, at most {layout.array_max}")
        for v in items:
            acc = _push(acc, _to_unsigned(a, v), a.bits)
        nbits += a.bits * len(items)
    pad = -nbits % 8
    return (acc << pad).to_bytes((nbits + pad) // 8, "big")


def unpack(layout: Layout, payload: bytes) -> SimpleNamespace | None:
    """The fields of ``payload`` as attributes (the array as a list under its name), or None when
    the payload is not the canonical serialisation of any message of this layout (too short, too
    long, or non-zero padding) -- the same payloads the ``dronecan`` package's decode-and-reencode
    check refuses."""
    end = 8 * len(payload)           # bits from the read position to the end of the stream
    if end < layout.fixed_bits:
        return None
    stream = int.from_bytes(payload, "big")
    out: dict[str, int | list[int]] = {}
    for f in layout.fields:
        out[f.name] = _from_unsigned(f, _pull(stream, end, f.bits))
        end -= f.bits
    if layout.array is not None:
        a = layout.array
        items = []
        for _ in range(min(end // a.bits, layout.array_max)):
            items.append(_from_unsigned(a, _pull(stream, end, a.bits)))
            end -= a.bits
        out[a.name] = items
    if end >= 8 or stream & ((1 << end) - 1):
        return None
    return SimpleNamespace(**out)


# uavcan.equipment.esc.RawCommand (1030): int14[<=20] cmd, tail-array optimised.
RAW_COMMAND = Layout(fields=(), array=Field("cmd", 14, signed=True), array_max=20)

# uavcan.protocol.NodeStatus (341): uint32 uptime_sec, uint2 health, uint3 mode, uint3 sub_mode,
# uint16 vendor_specific_status_code.
NODE_STATUS = Layout(fields=(Field("uptime_sec", 32), Field("health", 2), Field("mode", 3), Field("sub_mode", 3),
                             Field("vendor_specific_status_code", 16)))
