"""DroneCAN (UAVCAN v0) transfers on classic CAN 2.0B frames, as CAN ESCs and ArduPilot speak it.

Shared by the simulator's ESC nodes and the autopilot's CAN actuator back-end. The data types
(field layout, default data type IDs, data type signatures) and their bit-level serialisation
come from the ``dronecan`` package's DSDL definitions, except RawCommand and NodeStatus, which
are on the command path and use the same layout in integer arithmetic (common/dronecan_layout.py,
checked against the package in the tests); its node and driver layers are not used.
The transport layer is ours and follows the DroneCAN specification ("CAN bus transport layer"):

* 29-bit message frame ID: priority (bits 28-24), data type ID (23-8), service flag (7) = 0,
  source node ID (6-0);
* the last payload byte of every frame is the tail byte: start of transfer (bit 7), end of
  transfer (6), toggle (5, 0 on the first frame and alternating), transfer ID (4-0, per data
  type and source node, incremented modulo 32 per transfer);
* a transfer of more than 7 payload bytes is split over several frames and prefixed by a
  CRC-16-CCITT (polynomial 0x1021, little-endian) of the payload, computed from an initial value
  derived from the data type signature; single-frame transfers carry no CRC;
* the last array of a message uses tail array optimisation (no length field).

Rejected frames and transfers are counted per reason by :class:`TransferReceiver`; nothing in
this module raises on bad input from the bus.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache
from typing import TypeAlias

import can
import dronecan
from dronecan.transport import bits_from_bytes, bytes_from_bits

from common import dronecan_layout
from common.dronecan_layout import RAW_COMMAND_MAX, quantize  # noqa: F401  (both sides' names for them)

# dronecan builds its DSDL types and their message classes at run time from the DSDL definitions and
# ships no type information, so to mypy these are Any: a message's fields are read unchecked.
DronecanType: TypeAlias = dronecan.dsdl.parser.CompoundType      # has default_dtid, signature, fields
DronecanMessage: TypeAlias = dronecan.transport.CompoundValue    # a message object of such a type

# Data type IDs and full names (DroneCAN standard data types).
RAW_COMMAND = "uavcan.equipment.esc.RawCommand"   # 1030
ESC_STATUS = "uavcan.equipment.esc.Status"        # 1034
NODE_STATUS = "uavcan.protocol.NodeStatus"        # 341

TRANSFER_ID_MODULO = 32         # 5-bit transfer ID on CAN 2.0

# Priorities (0 highest, 31 lowest). ArduPilot sends RawCommand at a high priority.
PRIORITY_HIGH = 8
PRIORITY_MEDIUM = 16
PRIORITY_LOW = 24

# Reject reasons (the keys of TransferReceiver.rejects).
WRONG_DLC = "wrong_dlc"                     # no tail byte, > 8 bytes, or a payload of the wrong size for its type
BAD_CRC = "bad_crc"
TOGGLE_ERROR = "toggle_error"
MISSING_START = "missing_start_of_transfer"  # continuation frame with no transfer in progress
TRANSFER_ID_MISMATCH = "transfer_id_mismatch"  # continuation frame of another transfer
INCOMPLETE_TRANSFER = "incomplete_transfer"  # a new start frame interrupted a multi-frame transfer
UNKNOWN_DATA_TYPE = "unknown_data_type"
UNKNOWN_NODE = "unknown_node"
NOT_DRONECAN = "not_dronecan"                # 11-bit ID, remote or error frame, CAN FD
SERVICE_OR_ANONYMOUS = "service_or_anonymous"


# The command-path types, serialised with integer arithmetic (common/dronecan_layout.py).
FAST_LAYOUTS = {RAW_COMMAND: dronecan_layout.RAW_COMMAND, NODE_STATUS: dronecan_layout.NODE_STATUS}


def data_type(full_name: str) -> DronecanType:
    """The ``dronecan`` DSDL type object of ``full_name`` (has default_dtid, signature, fields)."""
    return dronecan.TYPENAMES[full_name]


def crc16_ccitt(data: bytes | bytearray, crc: int = 0xFFFF) -> int:
    """CRC-16-CCITT-FALSE (poly 0x1021, no reflection) of ``data`` continuing from ``crc``."""
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def transfer_crc_seed(signature: int) -> int:
    """Initial CRC of a multi-frame transfer: the CRC of the 64-bit data type signature (LE)."""
    return crc16_ccitt(signature.to_bytes(8, "little"))


def message_id(priority: int, dtid: int, source_node: int) -> int:
    """29-bit CAN ID of a message transfer from a node with an ID (not anonymous)."""
    if not (0 <= priority <= 31 and 0 <= dtid <= 0xFFFF and 1 <= source_node <= 127):
        raise ValueError(f"bad message ID parts: priority {priority}, data type {dtid}, node {source_node}")
    return (priority << 24) | (dtid << 8) | source_node


def serialize(msg: DronecanMessage) -> bytes:
    """Payload bytes of a ``dronecan`` message object (tail array optimisation, zero padded)."""
    bits = msg._pack(tao=True)
    if len(bits) % 8:
        bits += "0" * (8 - len(bits) % 8)
    return bytes(bytes_from_bits(bits))


def decode(dt: DronecanType, payload: bytes) -> DronecanMessage | None:
    """The ``dronecan`` message object of type ``dt`` in ``payload``, or None unless ``payload`` is
    exactly its serialisation (too short, too long, or non-zero padding)."""
    try:
        msg = dt()
        msg._unpack(bits_from_bytes(bytearray(payload)), True)
        canonical = serialize(msg)
    except Exception:
        return None
    return msg if canonical == payload else None


def make(full_name: str, **fields: object) -> DronecanMessage:
    """A ``dronecan`` message object of type ``full_name`` with ``fields`` set."""
    return data_type(full_name)(**fields)


def to_frames(full_name: str, payload: bytes, source_node: int, transfer_id: int,
              priority: int = PRIORITY_MEDIUM, timestamp: float = 0.0) -> list[can.Message]:
    """The CAN frames of one message transfer of ``payload`` bytes."""
    dt = data_type(full_name)
    arb = message_id(priority, dt.default_dtid, source_node)
    tid = transfer_id % TRANSFER_ID_MODULO
    if len(payload) <= 7:
        chunks = [bytes(payload)]
    else:
        crc = crc16_ccitt(payload, transfer_crc_seed(dt.get_data_type_signature()))
        body = bytes((crc & 0xFF, crc >> 8)) + bytes(payload)
        chunks = [body[i:i + 7] for i in range(0, len(body), 7)]
    frames = []
    for i, chunk in enumerate(chunks):
        tail = (0x80 if i == 0 else 0) | (0x40 if i == len(chunks) - 1 else 0) | (0x20 if i % 2 else 0) | tid
        frames.append(can.Message(arbitration_id=arb, is_extended_id=True, data=chunk + bytes((tail,)),
                                  timestamp=timestamp))
    return frames


@dataclass(frozen=True)
class Transfer:
    """One received, validated message transfer."""

    full_name: str
    source_node: int
    transfer_id: int
    priority: int
    payload: bytes
    msg: DronecanMessage    # the decoded ``dronecan`` message object
    timestamp: float        # of its first frame (python-can's receive timestamp, s)


class _Session:
    __slots__ = ("tid", "toggle", "data", "timestamp")

    def __init__(self, tid: int, timestamp: float) -> None:
        self.tid, self.toggle, self.data, self.timestamp = tid, 0, bytearray(), timestamp


class TransferReceiver:
    """Reassembles and validates message transfers from CAN frames.

    ``accept`` is the set of data type full names this node takes; ``nodes`` restricts the source
    node IDs accepted (None: any); frames from ``own_nodes`` are ignored (counted apart, not as
    rejects). Every frame that does not end up in a returned :class:`Transfer` is counted in
    :attr:`rejects` by reason, except continuation frames of transfers still in progress.
    """

    def __init__(self, accept: Iterable[str], nodes: Iterable[int] | None = None,
                 own_nodes: Iterable[int] = ()) -> None:
        self.types = {data_type(n).default_dtid: data_type(n) for n in accept}
        self.nodes = None if nodes is None else frozenset(nodes)
        self.own_nodes = frozenset(own_nodes)
        self.sessions: dict[int, _Session] = {}
        self.rejects: Counter = Counter()
        self.own_frames = 0
        self.frames = 0

    def feed(self, frame: can.Message) -> Transfer | None:
        """Take one frame; return the transfer it completes, if any."""
        self.frames += 1
        if frame.is_error_frame or frame.is_remote_frame or not frame.is_extended_id or frame.is_fd:
            self.rejects[NOT_DRONECAN] += 1
            return None
        data = bytes(frame.data)
        if not 1 <= frame.dlc <= 8 or len(data) != frame.dlc:
            self.rejects[WRONG_DLC] += 1
            return None
        arb = frame.arbitration_id
        source = arb & 0x7F
        if source in self.own_nodes:
            self.own_frames += 1
            return None
        if arb & 0x80 or source == 0:
            self.rejects[SERVICE_OR_ANONYMOUS] += 1
            return None
        dt = self.types.get((arb >> 8) & 0xFFFF)
        if dt is None:
            self.rejects[UNKNOWN_DATA_TYPE] += 1
            return None
        if self.nodes is not None and source not in self.nodes:
            self.rejects[UNKNOWN_NODE] += 1
            return None
        tail = data[-1]
        sot, eot, toggle, tid = bool(tail & 0x80), bool(tail & 0x40), (tail >> 5) & 1, tail & 0x1F
        key = arb & ~(0x1F << 24)  # one session per data type and source, whatever the priority
        if sot:
            if key in self.sessions:
                self.rejects[INCOMPLETE_TRANSFER] += 1
                del self.sessions[key]
            if toggle:
                self.rejects[TOGGLE_ERROR] += 1
                return None
            if eot:
                return self._finish(dt, arb, tid, data[:-1], frame.timestamp, multi=False)
            new = self.sessions[key] = _Session(tid, frame.timestamp)
            new.data += data[:-1]
            new.toggle = 1
            return None
        s = self.sessions.get(key)
        if s is None:
            self.rejects[MISSING_START] += 1
            return None
        if tid != s.tid:
            self.rejects[TRANSFER_ID_MISMATCH] += 1
            del self.sessions[key]
            return None
        if toggle != s.toggle:
            self.rejects[TOGGLE_ERROR] += 1
            del self.sessions[key]
            return None
        s.data += data[:-1]
        s.toggle ^= 1
        if not eot:
            if len(s.data) > 512:  # longer than any type we accept: a stuck transfer
                self.rejects[WRONG_DLC] += 1
                del self.sessions[key]
            return None
        del self.sessions[key]
        return self._finish(dt, arb, tid, bytes(s.data), s.timestamp, multi=True)

    def _finish(self, dt: DronecanType, arb: int, tid: int, body: bytes, timestamp: float,
                multi: bool) -> Transfer | None:
        if multi:
            if len(body) < 3:
                self.rejects[WRONG_DLC] += 1
                return None
            got, body = body[0] | (body[1] << 8), body[2:]
            if crc16_ccitt(body, transfer_crc_seed(dt.get_data_type_signature())) != got:
                self.rejects[BAD_CRC] += 1
                return None
        layout = FAST_LAYOUTS.get(dt.full_name)
        if layout is not None:
            msg = dronecan_layout.unpack(layout, body)
        else:
            msg = decode(dt, body)
        if msg is None:  # too short / too long for the type, or trailing garbage
            self.rejects[WRONG_DLC] += 1
            return None
        return Transfer(dt.full_name, arb & 0x7F, tid, (arb >> 24) & 0x1F, body, msg, timestamp)


class TransferIdTracker:
    """Transfers lost (gaps in transfer IDs) and duplicated, per (data type, source node)."""

    def __init__(self) -> None:
        self.last: dict[tuple[str, int], int] = {}
        self.names: dict[tuple[str, int], str] = {}
        self.received: Counter = Counter()
        self.lost: Counter = Counter()
        self.duplicated: Counter = Counter()

    def _name(self, full_name: str, node: int) -> str:
        """The counters' key: "Status@20"."""
        key = (full_name, node)
        name = self.names.get(key)
        if name is None:
            name = self.names[key] = f"{short_name(full_name)}@{node}"
        return name

    def received_from(self, full_name: str, node: int) -> int:
        """Transfers of ``full_name`` received from ``node`` so far."""
        return self.received.get(self._name(full_name, node), 0)

    def observe(self, t: Transfer) -> bool:
        """Record ``t``; False when it repeats the previous transfer ID (a duplicate)."""
        key = (t.full_name, t.source_node)
        name = self._name(*key)
        last = self.last.get(key)
        self.last[key] = t.transfer_id
        if last is not None:
            gap = (t.transfer_id - last) % TRANSFER_ID_MODULO
            if gap == 0:
                self.duplicated[name] += 1
                return False
            self.lost[name] += gap - 1
        self.received[name] += 1
        return True


class TransferIds:
    """Outgoing transfer-ID counters, one per data type (a node's own source ID is fixed)."""

    def __init__(self) -> None:
        self.next: Counter = Counter()

    def take(self, full_name: str) -> int:
        tid = self.next[full_name] % TRANSFER_ID_MODULO
        self.next[full_name] += 1
        return tid


def node_status(uptime_sec: int, health: int = 0, mode: int = 0, vendor_status: int = 0) -> bytes:
    """NodeStatus payload (7 bytes): health 0 = OK, mode 0 = OPERATIONAL."""
    return dronecan_layout.pack(dronecan_layout.NODE_STATUS, {
        "uptime_sec": int(uptime_sec) & 0xFFFFFFFF, "health": health, "mode": mode, "sub_mode": 0,
        "vendor_specific_status_code": vendor_status})


def raw_command(values: Iterable[int]) -> bytes:
    """RawCommand payload; ValueError for a value outside [-8191, 8191] (never sent)."""
    vals = [int(v) for v in values]
    if any(abs(v) > RAW_COMMAND_MAX for v in vals):
        raise ValueError(f"RawCommand values must lie in [-{RAW_COMMAND_MAX}, {RAW_COMMAND_MAX}]: {vals}")
    return dronecan_layout.pack(dronecan_layout.RAW_COMMAND, {}, vals)


@cache
def short_name(full_name: str) -> str:
    """"uavcan.equipment.esc.Status" -> "Status"."""
    return full_name.rsplit(".", 1)[-1]
