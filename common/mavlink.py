"""MAVLink 2 codec on pymavlink's ``ardupilotmega`` dialect (a superset of ``common``).

:class:`Codec` encodes messages into bytes (one MAVLink 2 frame each, sequence numbers counted
from 0, so a run is reproducible byte for byte) and decodes one UDP datagram at a time into the
messages it wants, reporting why anything else was rejected so that callers can count it.
Each datagram is parsed on its own: a frame cut at the datagram's end is "truncated", never
joined with the next datagram.
"""

from __future__ import annotations

from collections.abc import Iterable

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

# pymavlink checks every frame's CRC-16/MCRF4XX with the fastcrc package where it is installed (a
# dependency of ours) and with a byte-by-byte Python loop otherwise: 22 against 6 us to encode a
# HIL_SENSOR, the same checksums. Benchmarks report which one ran.
CRC_BACKEND = "fastcrc" if getattr(mavlink2, "mcrf4xx", None) is not None else "python"


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

    def encode(self, name: str, *args, **kwargs) -> bytes:
        """Frame of message ``name`` (e.g. ``"hil_sensor"``) built from its encode() arguments."""
        return self.pack(getattr(self.mav, f"{name}_encode")(*args, **kwargs))

    # -- decoding --------------------------------------------------------------------------
    def _reset_parser(self) -> None:
        reset_parser(self.mav)

    def decode(self, datagram: bytes) -> tuple[list[mavlink2.MAVLink_message], list[str]]:
        """Accepted messages of one datagram, and the rejection reason of every rejected part."""
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
