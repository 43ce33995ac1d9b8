"""MAVLink 2 message signing (https://mavlink.io/en/guide/message_signing.html) and the write gate.

* :func:`load_signing_key` reads the shared secret key.
* :class:`ReplayGuard` verifies a signed frame: the 48-bit SHA-256 signature over the key and the frame,
  and a timestamp (10 µs units since 2015-01-01) strictly newer than the last accepted one of the
  same (link id, system id, component id). There is ONE guard per link and key, shared by every
  parser of every transport (UDP, each TCP connection, serial): a frame captured on one connection
  and replayed on another, or replayed over UDP, is refused. A frame is recorded only once its
  signature is good, so a forged frame with a future timestamp cannot lock the real GCS out; a good
  frame stamped more than :data:`FUTURE_SLACK` ahead of our clock is refused and recorded nowhere, so
  a GCS with a wrong clock cannot lock the others out either (issue 31).
* :class:`SecurityGate` decides, per message, whether a frame may change the vessel: with signing on,
  every state- or rate-changing message (:data:`WRITES`) must carry a good signature; with an
  allow-list, its source system id must be listed. Refusals are counted by reason.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from autopilot_bridge.gcs.peers import RANK_GCS, RANK_SIGNED, RANK_STRANGER
from common.mavlink import MAV_TYPE, MavMessage, mavlink2

SIGNING_EPOCH = 1420070400  # 2015-01-01 00:00:00 UTC, the MAVLink 2 signing timestamp origin
NEW_STREAM_SLACK = 6_000_000  # a new stream's first timestamp may lag our clock by 60 s (10 µs units), as the spec
FUTURE_SLACK = 6_000_000      # a timestamp may lead our wall clock by 60 s at most (10 µs units); beyond: refused
MAX_STREAMS = 256             # (link id, sysid, compid) streams remembered (256 links x ids would be 2^24)

# Messages that change the vessel's state or what it sends (rates included): signing and the allow-list
# apply to these. Read requests (PARAM_REQUEST_*, MISSION_REQUEST_*, PING) stay open, rate-limited
# (:mod:`.limits`), so that telemetry remains readable without the key.
WRITES = frozenset({
    "COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT",
    "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "MISSION_WRITE_PARTIAL_LIST", "PARAM_SET", "PARAM_EXT_SET",
    "MANUAL_CONTROL", "RC_CHANNELS_OVERRIDE", "SET_POSITION_TARGET_GLOBAL_INT", "SET_POSITION_TARGET_LOCAL_NED",
    "REQUEST_DATA_STREAM", "SET_HOME_POSITION", "SETUP_SIGNING", "SET_GPS_GLOBAL_ORIGIN",
})


def load_signing_key(path: str) -> bytes:
    """32-byte key from a file: raw 32 bytes, 64 hex digits, or a passphrase (SHA-256 of it, as MAVProxy)."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"signing key file {path}: {exc.strerror or exc}") from None
    if len(raw) == 32:
        return raw
    text = raw.decode(errors="replace").strip()
    if not text:
        raise ValueError(f"signing key file {path}: empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    return hashlib.sha256(text.encode()).digest()


def signing_now(wall: float | None = None) -> int:
    """The signing timestamp of a wall time (s since the Unix epoch; now by default), 10 µs units."""
    return int(((time.time() if wall is None else wall) - SIGNING_EPOCH) * 1e5)


def signature_matches(key: bytes, msgbuf: bytes | bytearray) -> bool:
    """Whether a signed frame's 6-byte signature is SHA-256(key + frame up to the signature)[:6]."""
    return len(msgbuf) > 13 and hmac.compare_digest(hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6],
                                                    bytes(msgbuf[-6:]))


def _stamp(msgbuf: bytes | bytearray) -> int:
    """A signed frame's timestamp (10 µs units since 2015-01-01)."""
    low, high = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
    return int(low + (high << 32))


class ReplayGuard:
    """One link's signature check and replay state: newest accepted timestamp per (link id, sysid, compid).

    Our clock is the wall clock (as a signing timestamp), never earlier than at the start; timestamps
    received never move it. A timestamp more than :data:`FUTURE_SLACK` ahead of the wall clock is refused
    (``future``) and changes nothing: before issue 31, one good frame stamped a day ahead (a GCS with a
    wrong clock) moved our clock a day on, and every new stream was then refused as a replay for a day.
    """

    def __init__(self, key: bytes, now: int | None = None, wall: Callable[[], float] = time.time) -> None:
        self.key = key
        self.wall = wall
        self.timestamp = signing_now(wall()) if now is None else now   # our clock: max(start, newest accepted)
        self.streams: dict[tuple[int, int, int], int] = {}
        self.refused: Counter[str] = Counter()                    # "replay" / "bad_signature" / "future"

    def check(self, msgbuf: bytes | bytearray, src_system: int, src_component: int) -> bool:
        """pymavlink's ``check_signature`` hook: True for a good signature with a fresh timestamp."""
        if not signature_matches(self.key, msgbuf):
            self.refused["bad_signature"] += 1
            return False
        link_id = msgbuf[-13]
        stamp = _stamp(msgbuf)
        clock = max(self.timestamp, signing_now(self.wall()))
        if stamp > clock + FUTURE_SLACK:
            self.refused["future"] += 1
            return False
        stream = (link_id, src_system, src_component)
        last = self.streams.get(stream)
        if (last is not None and stamp <= last) or (last is None and stamp + NEW_STREAM_SLACK < clock):
            self.refused["replay"] += 1
            return False
        if last is None and len(self.streams) >= MAX_STREAMS:
            self.streams.pop(next(iter(self.streams)))   # the oldest stream's state: bounded memory
        self.streams[stream] = stamp
        self.timestamp = clock   # the stamps we accept never move our clock (a wrong GCS clock stays its own)
        return True

    def install(self, mav: mavlink2.MAVLink) -> None:
        """Make a pymavlink parser verify with this guard and decode unsigned frames too (the gate decides)."""
        mav.signing.secret_key = self.key
        mav.signing.timestamp = self.timestamp
        mav.signing.allow_unsigned_callback = lambda _mav, _msgid: True
        mav.check_signature = self.check


class SecurityGate:
    """Whether a decoded message may change the vessel; counts refusals by reason in ``counts``."""

    def __init__(self, key: bytes | None, allowed_sysids: tuple[int, ...], counts: Counter[str]) -> None:
        self.key = key
        self.allowed = frozenset(allowed_sysids)
        self.counts = counts

    def signed(self, m: MavMessage) -> bool:
        """Signed with our key and fresh (the frame passed :class:`ReplayGuard` while it was parsed)."""
        return bool(getattr(m, "_signed", False))

    def allows(self, m: MavMessage, kind: str) -> bool:
        if kind not in WRITES:
            return True
        if self.allowed and m.get_srcSystem() not in self.allowed:
            self.counts["not_allowed_sysid"] += 1
            return False
        if self.key is not None and not self.signed(m):
            if not m.get_header().incompat_flags & mavlink2.MAVLINK_IFLAG_SIGNED:
                self.counts["unsigned"] += 1
            elif signature_matches(self.key, m.get_msgbuf()):
                # our key: a timestamp too far ahead (a wrong clock), or an old one (a captured frame sent again)
                self.counts["future" if _stamp(m.get_msgbuf()) > signing_now() + FUTURE_SLACK else "replay"] += 1
            else:
                self.counts["bad_signature"] += 1
            return False
        return True

    def peer_rank(self, m: MavMessage, kind: str) -> int:
        """The place a frame that passed :meth:`allows` earns its sender in the peer table (:mod:`.peers`):
        signed with our key; without signing, a frame that talks like a ground station (a GCS HEARTBEAT
        or a write, from an allowed system id); anything else ranks as a stranger's."""
        if self.signed(m):
            return RANK_SIGNED
        if self.key is not None:
            return RANK_STRANGER
        if self.allowed and m.get_srcSystem() not in self.allowed:
            return RANK_STRANGER
        if kind in WRITES or (kind == "HEARTBEAT" and getattr(m, "type", None) == MAV_TYPE.MAV_TYPE_GCS):
            return RANK_GCS
        return RANK_STRANGER
