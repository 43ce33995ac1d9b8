"""One connection-string grammar for every endpoint, after pymavlink's ``mavutil.mavlink_connection``.

==========================  ==================================================================
``udpin:HOST:PORT``         bind a UDP socket on HOST:PORT and answer whoever talks to it
``udp:HOST:PORT``           the same as ``udpin:`` (as in mavutil)
``udpout:HOST:PORT``        send UDP datagrams to HOST:PORT (from a free local port)
``tcp:HOST:PORT``           connect to a TCP server at HOST:PORT (client)
``tcpin:HOST:PORT``         accept TCP connections on HOST:PORT (server)
``serial:DEVICE:BAUD``      a serial port (a telemetry radio), e.g. ``serial:/dev/ttyUSB0:57600``
``HOST:PORT``               the option's own meaning: a destination for options that send
                            (``udpout:``), a bound address for options that receive (``udpin:``)
==========================  ==================================================================

Not every endpoint can use every form: the HIL links are UDP datagrams (one datagram = one
lockstep frame), so ``--state-to`` and ``--actuators-to`` take the sending forms and
``--commands-on`` and ``--listen`` the receiving ones; the ground-station link takes them all.
A :class:`Role` names what an endpoint accepts; :func:`parse` refuses anything else with one line
that names the accepted forms (a misspelt prefix never falls through as a host name).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Kind = Literal["udpin", "udpout", "tcp", "tcpin", "serial"]

ALL_FORMS = ("udpin:HOST:PORT", "udp:HOST:PORT", "udpout:HOST:PORT", "tcp:HOST:PORT", "tcpin:HOST:PORT",
             "serial:DEVICE:BAUD", "HOST:PORT")
_PREFIX = {"udpin": "udpin", "udp": "udpin", "udpout": "udpout", "tcp": "tcp", "tcpin": "tcpin", "serial": "serial"}
_BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000,
          1500000, 2000000, 3000000)


@dataclass(frozen=True)
class Connection:
    """A parsed connection string. ``host``/``port`` for the network kinds, ``device``/``baud`` for serial."""

    kind: Kind
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    @property
    def hostport(self) -> str:
        """"HOST:PORT" of a network endpoint."""
        return f"{self.host}:{self.port}"

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def endpoint(self) -> tuple[str, str, int]:
        """(kind, host, port); for serial, (kind, device, baud)."""
        if self.kind == "serial":
            return self.kind, self.device, self.baud
        return self.kind, self.host, self.port


@dataclass(frozen=True)
class Role:
    """What one endpoint (an option or configuration key) accepts.

    ``kinds``: the accepted kinds; ``plain``: the kind a bare HOST:PORT means there; ``what``:
    a few words saying what the endpoint does, for error messages.
    """

    kinds: tuple[Kind, ...]
    plain: Kind
    what: str

    def forms(self) -> str:
        names = {"udpin": ("udpin:HOST:PORT", "udp:HOST:PORT"), "udpout": ("udpout:HOST:PORT",),
                 "tcp": ("tcp:HOST:PORT",), "tcpin": ("tcpin:HOST:PORT",), "serial": ("serial:DEVICE:BAUD",)}
        out = ["HOST:PORT"] + [f for k in self.kinds for f in names[k]]
        return ", ".join(out)


SEND_UDP = Role(("udpout",), "udpout", "sends UDP datagrams")
RECEIVE_UDP = Role(("udpin",), "udpin", "receives UDP datagrams on a bound address")
GCS = Role(("udpout", "udpin", "tcp", "tcpin", "serial"), "udpout", "talks to ground stations")


def _hostport(text: str, rest: str) -> tuple[str, int]:
    if rest.startswith("["):  # [IPv6]:PORT
        host, sep, port = rest[1:].partition("]:")
    else:
        host, sep, port = rest.rpartition(":")
    if not sep or not host:
        raise ValueError(f"{text!r}: expected HOST:PORT after the prefix, e.g. 127.0.0.1:14550")
    if ":" in host and not rest.startswith("["):
        raise ValueError(f"{text!r}: {host!r} is not a host name (accepted forms: {', '.join(ALL_FORMS)})")
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"{text!r}: port {port!r} is not an integer") from None
    if not 0 <= p <= 65535:
        raise ValueError(f"{text!r}: port {p} is outside 0-65535")
    return host, p


def parse(text: str, role: Role = GCS) -> Connection:
    """Parse ``text`` for an endpoint of ``role``; ValueError with one line naming the accepted forms."""
    text = str(text).strip()
    head, sep, rest = text.partition(":")
    if sep and head.lower() in _PREFIX:
        kind: Kind = _PREFIX[head.lower()]  # type: ignore[assignment]
    elif sep and head.startswith("/"):
        raise ValueError(f"{text!r}: a serial device is written serial:{text} (accepted forms: {role.forms()})")
    else:
        kind, rest = role.plain, text
        if sep and not rest.startswith("[") and rest.count(":") > 1:
            raise ValueError(f"{text!r}: unknown prefix {head + ':'!r} (accepted forms here: {role.forms()})")
    if kind not in role.kinds:
        raise ValueError(f"{text!r}: this endpoint {role.what}; {head}: is not one of its forms "
                         f"(accepted forms here: {role.forms()})")
    if kind == "serial":
        device, sep, baud = rest.rpartition(":")
        if not sep or not device:
            device, baud = rest, "57600"
        try:
            b = int(baud)
        except ValueError:
            raise ValueError(f"{text!r}: baud rate {baud!r} is not an integer (serial:DEVICE:BAUD)") from None
        if b not in _BAUDS:
            raise ValueError(f"{text!r}: baud rate {b} is not a standard one ({', '.join(map(str, _BAUDS))})")
        return Connection("serial", device=device, baud=b, text=text)
    host, port = _hostport(text, rest)
    if kind in ("udpout", "tcp") and port == 0:
        raise ValueError(f"{text!r}: {kind}: needs the port of the peer to reach, not 0")
    return Connection(kind, host, port, text=text)
