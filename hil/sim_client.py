"""The vessel-computer side of the HIL link at its simplest: a client that receives the simulator's
frames and answers each with HIL_ACTUATOR_CONTROLS. Used by `hil run --demo` (a constant-thrust
controller) and `hil bench sim` (the simulator's speed alone), and by the simulator's UDP tests.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Unpack

from hil import processes
from hil.config import config_args

if TYPE_CHECKING:
    from common.mavlink import MavMessage


@dataclass
class Frame:
    """The messages of one simulator datagram, by type."""

    raw: bytes
    time_usec: int | None
    messages: dict[str, MavMessage] = field(default_factory=dict)


class HilClient:
    """The vessel-computer side of the link: receives frames, answers with HIL_ACTUATOR_CONTROLS.

    Bound to 127.0.0.1 on a free port (see :attr:`port`); commands go back to the address the
    frames come from (the simulator sends from its command socket).
    """

    ACCEPT = ("HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION", "ODOMETRY")

    def __init__(self, bind: str = "127.0.0.1:0", system_id: int = 1, component_id: int = 1) -> None:
        """``system_id``/``component_id``: the autopilot's (the simulator takes commands only from those)."""
        from common.mavlink import Codec
        from common.udp import UdpEndpoint

        self.ep = UdpEndpoint(bind)
        self.codec = Codec(system_id, component_id, accept=self.ACCEPT)
        self.frames = self.commands = self.rejects = 0

    @property
    def port(self) -> int:
        return self.ep.address[1]

    def next_frame(self, timeout: float, latest: bool = False) -> Frame | None:
        """The next datagram (``latest``: the newest queued one) decoded, or None on timeout."""
        data = self.ep.drain_latest() if latest else None
        if data is None:
            data = self.ep.recv(timeout)
        if data is None:
            return None
        msgs, rejects = self.codec.decode(data)
        self.rejects += len(rejects)
        self.frames += 1
        f = Frame(data, None, {m.get_type(): m for m in msgs})
        if "HIL_SENSOR" in f.messages:
            f.time_usec = int(f.messages["HIL_SENSOR"].time_usec)
        return f

    def command(self, time_usec: int, port: float, stdb: float) -> bytes:
        """Send one HIL_ACTUATOR_CONTROLS (controls[0] port, [1] starboard) to the simulator."""
        data = self.codec.encode("hil_actuator_controls", time_usec, [port, stdb] + [0.0] * 14, 0, 0)
        if self.ep.last_sender is not None:
            self.ep.sock.sendto(data, self.ep.last_sender)
            self.commands += 1
        return data

    def close(self) -> None:
        self.ep.close()


def sim_command(args: argparse.Namespace, client_port: int, lockstep: bool) -> list[str]:
    cmd = [sys.executable, "-m", "hil", "sim", "--json", "--state-to", f"127.0.0.1:{client_port}",
           "--commands-from", f"127.0.0.1:{client_port}",
           "--commands-on", "127.0.0.1:0", "--duration", repr(float(args.duration))]
    cmd += config_args(args.config)
    for o in args.overrides:
        cmd += ["--set", o]
    if args.seed is not None:
        cmd += ["--seed", str(args.seed)]
    cmd += ["--lockstep"] if lockstep else ["--speedup", repr(float(args.speedup))]
    return cmd


def start_simulator(cmd: list[str], **kwargs: Unpack[processes.ChildOptions]) -> subprocess.Popen:
    """Start the simulator subprocess; it is stopped if this process dies."""
    return processes.start(cmd, **kwargs)
