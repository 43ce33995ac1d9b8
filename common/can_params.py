"""The [can] configuration section: the CAN bus both the autopilot and the simulated ESCs use."""

from __future__ import annotations

import socket
from dataclasses import dataclass
from typing import Literal, TypedDict, Unpack

import can
from can.typechecking import CanFilters

from common.params import param


@dataclass(frozen=True)
class CanParams:
    """Which actuator path the autopilot uses, and the DroneCAN bus of the CAN path.

    Defaults as in configs/default.toml: configuration files from before this section load unchanged.
    """

    actuators: Literal["mavlink", "can"] = param(
        "thruster set-points as HIL_ACTUATOR_CONTROLS over UDP (mavlink) or DroneCAN RawCommand over CAN (can)",
        default="mavlink")
    interface: str = param("python-can interface of the bus (socketcan, virtual, pcan, ...)", default="socketcan")
    channel: str = param("python-can channel of the bus (vcan0, can0, ...)", default="vcan0")
    autopilot_node_id: int = param("static DroneCAN node ID of the autopilot", ge=1, le=127, default=10)
    esc_node_ids: tuple[int, int] = param("static DroneCAN node IDs of the port and starboard ESCs", default=(20, 21))
    status_rate_hz: float = param("ESC Status rate of each ESC node (simulated time)", "Hz", gt=0, le=100, default=10.0)
    node_status_rate_hz: float = param(
        "NodeStatus rate of every node (DroneCAN: 1-2 Hz typical)", "Hz", gt=0, le=10, default=1.0)
    lockstep_wait: float = param(
        "lockstep: wall time the simulator waits for the RawCommand that matches a frame's answer", "s", gt=0,
        default=1.0)
    log: bool = param("hil run: record every CAN frame to can.log (candump format) in the run folder", default=True)
    socket_rx_buffer: int = param(
        "SocketCAN: receive buffer of each node's socket (SO_RCVBUF; the kernel caps it at net.core.rmem_max)",
        "bytes", ge=0, default=1 << 20)

    def __post_init__(self) -> None:
        ids = (self.autopilot_node_id, *self.esc_node_ids)
        if any(not 1 <= i <= 127 for i in self.esc_node_ids):
            raise ValueError("esc_node_ids: node IDs must lie in 1..127")
        if len(set(ids)) != len(ids):
            raise ValueError("esc_node_ids: the autopilot and the two ESCs need distinct node IDs")


class BusOptions(TypedDict, total=False):
    """The ``can.Bus`` options this project opens buses with."""

    can_filters: CanFilters | None
    receive_own_messages: bool


def kernel_filters(params: CanParams, from_node: int) -> CanFilters | None:
    """A receive filter that passes only messages (service bit 0) from node ``from_node``, applied by the
    kernel on SocketCAN: the simulated ESCs take the autopilot's node only, so a flood from other nodes
    never reaches the simulator's socket, costs no step any work and waits in no queue ahead of the
    autopilot's commands (issue 31). Frames dropped there are not counted (``unknown_node`` then counts
    nothing on SocketCAN). None on other interfaces: python-can filters those in software inside
    ``recv``, which with a timeout of 0 returns None at the first frame it filters out and would cut a
    poll short."""
    if params.interface != "socketcan":
        return None
    return [{"can_id": from_node, "can_mask": 0xFF, "extended": True}]


def open_bus(params: CanParams, **kwargs: Unpack[BusOptions]) -> can.BusABC:
    """``can.Bus`` of the configured interface and channel; ValueError with a one-line reason.

    On SocketCAN the socket's receive buffer is raised to ``socket_rx_buffer``: the default (about
    200 KB) holds only about a hundred frames in User-Mode Linux, and a control loop held up for a
    second and a half while the ESCs kept sending overflowed it in the hour-long soak.
    """
    try:
        bus = can.Bus(interface=params.interface, channel=params.channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise ValueError(f"cannot open CAN bus {params.interface}:{params.channel}: {exc}") from None
    sock = getattr(bus, "socket", None)
    if params.interface == "socketcan" and params.socket_rx_buffer and isinstance(sock, socket.socket):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, params.socket_rx_buffer)
    return bus
