"""The ground-station link's devices, opened before the link is built on them.

:func:`open_gcs_devices` reads ``[gcs]`` once: the signing key, one transport per endpoint, the MAVLink
codec with the vessel's ids (signing its frames when there is a key) and the socket that mirrors
accepted frames to the `hil run` tap. :class:`~autopilot_bridge.gcs.link.GcsLink` takes them built
(the vessel computer's assembly opens them with the other devices; :meth:`GcsLink.open` for tests).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.context import Transport
from autopilot_bridge.gcs.signing import load_signing_key, signing_now
from autopilot_bridge.gcs.transport import open_endpoint
from common.mavlink import Codec
from common.udp import UdpEndpoint


@dataclass
class GcsDevices:
    """What the link talks through: the vessel's MAVLink ids, its ``transports`` (one per ``[gcs]
    endpoints`` entry), the ``codec`` of those ids, the optional ``mirror`` socket, the signing ``key`` (None: unsigned)
    and ``security``, the refusals by reason that the transports' peer tables count into (the link's
    gate and limiter count into it too)."""

    system_id: int
    component_id: int
    transports: list[Transport]
    codec: Codec
    mirror: UdpEndpoint | None
    key: bytes | None
    security: Counter[str] = field(default_factory=Counter)

    def close(self) -> None:
        for tr in self.transports:
            tr.close()
        if self.mirror is not None:
            self.mirror.close()


def open_gcs_devices(params: GcsParams, system_id: int, component_id: int, *, mirror_to: tuple[str, ...] = (),
                     mirror_from: str = "127.0.0.1:0",
                     clock: Callable[[], float] = time.monotonic) -> GcsDevices:
    """The devices of ``[gcs]`` (ValueError with one line on a bad endpoint, a busy port, an unreadable
    key; whatever was opened before it closed again). ``mirror_to``: "HOST:PORT" addresses that get a
    copy of each accepted frame, sent from ``mirror_from``; ``clock`` (s, monotonic) times the peers'
    silences."""
    key = load_signing_key(params.signing_key_file) if params.signing_key_file else None
    security: Counter[str] = Counter()
    transports: list[Transport] = []
    try:
        for conn in params.connections:
            transports.append(open_endpoint(conn, params.max_peers, security, clock))
        codec = Codec(system_id, component_id)
        if key is not None:
            s = codec.mav.signing
            s.secret_key, s.sign_outgoing, s.link_id = key, True, 0
            s.timestamp = signing_now()
        mirror = UdpEndpoint(mirror_from, list(mirror_to)) if mirror_to else None
    except ValueError:
        for tr in transports:
            tr.close()
        raise
    return GcsDevices(system_id, component_id, transports, codec, mirror, key, security)
