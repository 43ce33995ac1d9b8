"""The autopilot's DroneCAN actuator back-end: thruster set-points as ESC RawCommand over CAN.

Same small interface as the MAVLink back-end (:class:`autopilot_bridge.hil_link.HilLink`):
``send_controls(time_usec, port, stdb)`` with normalised commands in [-1, 1], plus
``service()`` (read the bus), ``summary()`` and ``close()``. Any python-can bus works.

Every command is one ``uavcan.equipment.esc.RawCommand`` transfer from the autopilot's node
(cmd[0] port, cmd[1] starboard, int14 in [-8191, 8191], negative = reverse), at high priority.
The node also sends ``uavcan.protocol.NodeStatus`` at ``node_status_rate_hz`` of frame time, and
reads ``uavcan.equipment.esc.Status`` and NodeStatus back from the ESC nodes; everything else,
and anything malformed, is dropped and counted. Frames of its own node ID are ignored. Status and
NodeStatus count only from the configured ESC nodes (others: ``unknown_node``), only for the ESC
index that node owns (``esc_index_mismatch``), and never twice with one transfer ID
(``duplicate_transfer_id``, a replay). One service() call reads at most MAX_FRAMES_PER_SERVICE frames.

Lockstep: the simulator advances one frame per answer, and a RawCommand carries no frame time,
so each answer is also sent as HIL_ACTUATOR_CONTROLS (``lockstep_token``) holding exactly the
values of the RawCommand sent just before it; the simulator steps on the token once its ESC
nodes hold that RawCommand (docs/can.md).
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Callable
from typing import TypedDict

import can

from autopilot_bridge.hil_link import SensorLink
from common import dronecan_codec as dc
from common.can_params import CanParams
from common.transfer_times import TransferTimes

MAX_FRAMES_PER_SERVICE = 256
ECHO_MEMORY = 128          # frames sent lately: one of them read back is the interface's echo, not an impostor
CONFLICT_QUIET_S = 2.0     # s of wall time without an impostor's frame that end a node-ID conflict episode



class CanPathSummary(TypedDict):
    """The ``can`` section of the autopilot's summary: the bus, DroneCAN transfers by type (sent,
    received, lost, duplicated), refusals by reason, each ESC's newest status (by side: rpm, V, A,
    degC ...) and health by node id."""

    interface: str
    channel: str
    node_id: int
    raw_commands_sent: int
    transfers_sent: dict[str, int]
    send_errors: int
    frames_received: int
    own_frames_ignored: int
    impostor_frames: int
    node_id_conflicts: int
    transfers_received: dict[str, int]
    transfers_lost: dict[str, int]
    transfers_duplicated: dict[str, int]
    rejects: dict[str, int]
    esc_status: dict[str, dict[str, float]]
    esc_health: dict[str, int]


RECEIVED = (dc.ESC_STATUS, dc.NODE_STATUS)   # the data types taken from the bus


def esc_receiver(params: CanParams) -> dc.TransferReceiver:
    """What the vessel computer takes from the bus: ESC_STATUS and NODE_STATUS from the ESCs' node IDs,
    its own node ID's frames told apart (impostors)."""
    return dc.TransferReceiver(list(RECEIVED), nodes=tuple(params.esc_node_ids), own_nodes=[params.autopilot_node_id])


class CanActuators:
    """Thruster commands over DroneCAN on ``bus``; ESC Status read back."""

    def __init__(self, bus: can.BusABC, params: CanParams, lockstep_token: SensorLink | None = None,
                 clock: Callable[[], float] = time.monotonic, *,
                 receiver: dc.TransferReceiver | None = None) -> None:
        """``receiver``: the transfers taken from the bus, built by the assembly
        (:func:`esc_receiver`; None: built here from ``params``)."""
        self.bus, self.p, self.token, self.clock = bus, params, lockstep_token, clock
        self.node_id = params.autopilot_node_id
        self.esc_ids = tuple(params.esc_node_ids)
        self.receiver = receiver if receiver is not None else esc_receiver(params)
        self.tracker = dc.TransferIdTracker()
        self.tids = dc.TransferIds()
        self.rejects: Counter = Counter()
        self.sent: Counter = Counter()
        self.send_errors = 0
        self.commands_sent = 0
        self.esc_status: dict[int, dict[str, float]] = {}
        self.esc_health: dict[int, int] = {}
        self.next_node_status_t = 0.0
        self.started = clock()
        self.sent_times = TransferTimes()   # latency records: transfer ID and wall time commanded
        self._echoes: deque[tuple[int, bytes]] = deque(maxlen=ECHO_MEMORY)
        self.impostor_frames = 0            # frames with our node ID that we did not send
        self.node_id_conflicts = 0          # episodes of them (CONFLICT_QUIET_S apart)
        self._last_impostor = -float("inf")
        self._alarms: list[str] = []

    def _send(self, full_name: str, payload: bytes, priority: int) -> int:
        tid = self.tids.take(full_name)
        for frame in dc.to_frames(full_name, payload, self.node_id, tid, priority):
            self._echoes.append((frame.arbitration_id, bytes(frame.data)))
            try:
                self.bus.send(frame, timeout=0.1)
            except can.CanError:
                self.send_errors += 1
                return tid
        self.sent[dc.short_name(full_name)] += 1
        return tid

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None:
        """RawCommand for normalised ``port`` and ``stdb`` in [-1, 1] answering the frame at ``time_usec``."""
        t0 = self.clock()
        values = (dc.quantize(port), dc.quantize(stdb)) if armed else (0, 0)
        tid = self._send(dc.RAW_COMMAND, dc.raw_command(values), dc.PRIORITY_HIGH)
        self.commands_sent += 1
        self.sent_times.add(tid, t0)
        if self.token is not None:
            self.token.send_controls(time_usec, values[0] / dc.RAW_COMMAND_MAX, values[1] / dc.RAW_COMMAND_MAX, armed)
        t = time_usec * 1e-6
        if t + 1e-9 >= self.next_node_status_t:
            self.next_node_status_t = t + 1.0 / self.p.node_status_rate_hz
            self._send(dc.NODE_STATUS, dc.node_status(int(t)), dc.PRIORITY_LOW)

    def service(self, timeout: float = 0.0) -> None:
        """Read every frame queued now: ESC Status and NodeStatus of the ESC nodes."""
        msg = self.bus.recv(timeout)
        for k in range(MAX_FRAMES_PER_SERVICE):
            if msg is None:
                return
            if msg.is_extended_id and msg.arbitration_id & 0x7F == self.node_id:
                self._own_id(msg)
            tr = self.receiver.feed(msg)
            if tr is not None:
                self._on_transfer(tr)
            if k + 1 < MAX_FRAMES_PER_SERVICE:  # the rest of a flood waits for the next call
                msg = self.bus.recv(0.0)

    def _own_id(self, msg: can.Message) -> None:
        """A frame with this node's ID: the interface's echo of one sent lately, or an impostor's. DroneCAN
        has no authentication, and the ESCs obey whoever sends as this node: each episode of an impostor's
        frames raises one alarm (:meth:`alarms`) and is counted."""
        if (msg.arbitration_id, bytes(msg.data)) in self._echoes:
            return
        self.impostor_frames += 1
        now = self.clock()
        if now - self._last_impostor > CONFLICT_QUIET_S:
            self.node_id_conflicts += 1
            self._alarms.append(f"CAN: another node sends as node {self.node_id} (node-ID conflict): "
                                "the ESCs may obey it")
        self._last_impostor = now

    def alarms(self) -> list[str]:
        """Alarms raised since the last call (the vessel computer reports them as warnings)."""
        out, self._alarms = self._alarms, []
        return out

    def _on_transfer(self, tr: dc.Transfer) -> None:
        if not self.tracker.observe(tr):
            self.rejects["duplicate_transfer_id"] += 1
            return
        m = tr.msg
        if tr.full_name == dc.NODE_STATUS:
            self.esc_health[tr.source_node] = int(m.health)
            return
        index = int(m.esc_index)
        if index >= len(self.esc_ids) or self.esc_ids[index] != tr.source_node:
            self.rejects["esc_index_mismatch"] += 1
            return
        self.esc_status[index] = {"node_id": tr.source_node, "rpm": int(m.rpm), "voltage": float(m.voltage),
                                  "current": float(m.current), "temperature": float(m.temperature),
                                  "power_rating_pct": int(m.power_rating_pct), "error_count": int(m.error_count)}

    def esc_telemetry(self) -> list[dict[str, float] | None]:
        """Per ESC index (port, starboard): the newest Status fields plus ``count``, the Status
        transfers received from that ESC; None for an ESC not heard from yet (the GCS link's
        ESC_TELEMETRY_1_TO_4)."""
        out: list[dict[str, float] | None] = []
        for i, node in enumerate(self.esc_ids):
            s = self.esc_status.get(i)
            out.append(None if s is None else {**s, "count": self.tracker.received_from(dc.ESC_STATUS, node)})
        return out if any(r is not None for r in out) else []

    def summary(self) -> CanPathSummary:
        """Counters of the CAN path (the ``can`` key of the autopilot summary)."""
        names = ("port", "starboard")
        return CanPathSummary(
            interface=self.p.interface,
            channel=self.p.channel,
            node_id=self.node_id,
            raw_commands_sent=self.commands_sent,
            transfers_sent=dict(sorted(self.sent.items())),
            send_errors=self.send_errors,
            frames_received=self.receiver.frames,
            own_frames_ignored=self.receiver.own_frames,
            impostor_frames=self.impostor_frames,
            node_id_conflicts=self.node_id_conflicts,
            transfers_received=dict(sorted(self.tracker.received.items())),
            transfers_lost=dict(sorted(self.tracker.lost.items())),
            transfers_duplicated=dict(sorted(self.tracker.duplicated.items())),
            rejects=dict(sorted((self.receiver.rejects + self.rejects).items())),
            esc_status={names[i]: s for i, s in sorted(self.esc_status.items())},
            esc_health={str(k): v for k, v in sorted(self.esc_health.items())},
        )

    def close(self) -> None:
        self.bus.shutdown()

