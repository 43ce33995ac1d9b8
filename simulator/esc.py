"""The two simulated DroneCAN ESC nodes of the thrusters, on one python-can bus.

Each ESC node has its own static node ID ([can] esc_node_ids: port, starboard), takes its
``esc_index`` (0 port, 1 starboard) from ``uavcan.equipment.esc.RawCommand`` transfers of the
autopilot's node, publishes ``uavcan.equipment.esc.Status`` at ``status_rate_hz`` and
``uavcan.protocol.NodeStatus`` at ``node_status_rate_hz`` (simulated time). The command turns
into thrust in :class:`simulator.core.SimulatorCore`, which holds the first-order lag and the
stale-command failsafe shared with the MAVLink path; Status reports the propeller state that
results (rpm from thrust ~ rpm^2, power ~ rpm^3).

Bad input never reaches the thrusters: frames and transfers rejected by the transport layer are
counted by :class:`common.dronecan_codec.TransferReceiver`, and RawCommands that lack an ESC's
index or hold a value outside [-8191, 8191] are rejected whole and counted here. RawCommand
counts only from the autopilot's node (``[can] autopilot_node_id``; others are counted as
``unknown_node``), and a transfer that repeats its source's previous transfer ID is a replay:
dropped and counted (``duplicate_transfer_id``). A second sender that claims the autopilot's node ID
(DroneCAN has no authentication) breaks the sequence of its transfer IDs: while CONFLICT_IRREGULAR of the
last CONFLICT_WINDOW RawCommands are out of sequence, no RawCommand is applied (counted as
``node_id_conflict``; each episode in ``node_id_conflicts``), so the simulator's stale-command failsafe
stops the thrusters within 0.5 s instead of obeying whoever sends faster; the conflict ends after
CONFLICT_WINDOW RawCommands in sequence.

A poll's work is bounded (issue 31): it reads at most ``max_frames`` frames (MAX_FRAMES_PER_POLL) and
stops early once it has spent ``budget_s`` (POLL_BUDGET_S) of wall time, so a flood on the bus cannot
take the real-time step's 10 ms; what it leaves waits in the bus's queue (the kernel drops what does
not fit). Each cut is counted by cause (``budget_stops``: ``frames`` or ``time``).
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from collections.abc import Callable
from typing import TYPE_CHECKING, TypedDict

import can

from common import dronecan_codec as dc
from common.can_params import CanParams
from common.transfer_times import TransferTimes

if TYPE_CHECKING:
    from simulator.config import EscParams
    from simulator.vessel import Vessel


class EscBankSummary(TypedDict):
    """The ESC nodes' counters: commands applied, the CAN traffic by transfer, rejects by reason."""

    node_ids: list[int]
    raw_commands_applied: int
    last_raw_command: list[int] | None           # the newest RawCommand's values for index 0 and 1
    frames_received: int
    transfers_received: dict[str, int]
    transfers_lost: dict[str, int]
    transfers_duplicated: dict[str, int]
    transfers_sent: dict[str, int]
    send_errors: int
    rejects: dict[str, int]
    autopilot_health: int | None                 # the autopilot node's NodeStatus health (None: none heard)
    budget_stops: dict[str, int]
    node_id_conflicts: int                       # episodes of a second sender with the autopilot's node ID


RAW_COMMAND_OUT_OF_RANGE = "raw_command_out_of_range"
RAW_COMMAND_MISSING_INDEX = "raw_command_missing_index"
DUPLICATE_TRANSFER = "duplicate_transfer_id"  # a transfer repeating its source's previous transfer ID (a replay)
NODE_ID_CONFLICT = "node_id_conflict"       # a RawCommand refused while a second sender claims the autopilot's ID
# One sender's RawCommand transfer IDs step by one (mod 32); a second sender with the autopilot's node ID (CAN has
# no authentication) interleaves its own sequence. Among the last CONFLICT_WINDOW RawCommands, CONFLICT_IRREGULAR
# out of sequence (a gap or a repeat) is a conflict: a lost frame on a healthy bus is far rarer than one in eight.
CONFLICT_WINDOW = 32
CONFLICT_IRREGULAR = 4
MAX_FRAMES_PER_POLL = 256  # CAN frames one poll() reads at most (a flood waits in the socket)
# A 1 Mbit/s bus carries at most ~8,000 extended frames/s (~130 bits each), ~80 per 10 ms HIL frame, so the
# frame cap only bites on a bus without a bit rate (vcan, virtual). The time budget bounds the work where
# each frame costs more (inside User-Mode Linux ~0.4 ms a frame): a fifth of the 10 ms frame.
POLL_BUDGET_S = 0.002
CLOCK_EVERY = 4            # frames between clock reads (inside UML a clock read is a 33 us system call)


class EscBank:
    """Both ESC nodes: receive RawCommand, publish Status and NodeStatus.

    ``clock`` gives the wall time stamped on applied commands (``time.monotonic``; latency
    records only). Simulated time ``t`` (s) is passed to :meth:`publish`.
    """

    def __init__(self, bus: can.BusABC, params: CanParams, esc: EscParams, vessel: Vessel,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.bus, self.p, self.esc, self.vessel, self.clock = bus, params, esc, vessel, clock
        self.node_ids = tuple(params.esc_node_ids)
        self.receiver = dc.TransferReceiver([dc.RAW_COMMAND, dc.NODE_STATUS], nodes=[params.autopilot_node_id],
                                            own_nodes=self.node_ids)
        self.tracker = dc.TransferIdTracker()
        self.tids = [dc.TransferIds() for _ in self.node_ids]
        self.rejects: Counter = Counter()
        self.raw: tuple[int, int] | None = None     # newest valid RawCommand for index 0 and 1
        self.commands = 0                           # valid RawCommands applied
        self.commands_seen = 0                      # RawCommands since the caller last looked (lockstep)
        self.autopilot_health: int | None = None
        self.sent: Counter = Counter()
        self.send_errors = 0
        self.next_status_t = 0.0
        self.next_node_status_t = 0.0
        self.applied_times = TransferTimes()        # latency records: transfer ID and wall time applied
        self.budget_stops: Counter[str] = Counter()     # polls cut short, by cause: "frames" or "time"
        self._in_sequence: deque[bool] = deque(maxlen=CONFLICT_WINDOW)   # the last RawCommands' transfer IDs
        self.conflict = False                       # a second sender claims the autopilot's node ID now
        self.conflicts = 0                          # conflict episodes
        self.max_frames, self.budget_s = MAX_FRAMES_PER_POLL, POLL_BUDGET_S

    # -- receive ---------------------------------------------------------------------------
    def poll(self, timeout: float = 0.0) -> int:
        """Take the frames queued now (waiting up to ``timeout`` s for the first), at most ``max_frames``
        of them and for at most ``budget_s`` of wall time after the first; returns the number of valid
        RawCommands applied."""
        applied = 0
        msg = self.bus.recv(timeout)
        if msg is None:
            return 0
        deadline = time.perf_counter() + self.budget_s
        for n in range(1, self.max_frames + 1):
            tr = self.receiver.feed(msg)
            if tr is not None:
                applied += self._on_transfer(tr)
            if n == self.max_frames:
                self.budget_stops["frames"] += 1
                break
            if n % CLOCK_EVERY == 0 and time.perf_counter() >= deadline:
                self.budget_stops["time"] += 1
                break
            msg = self.bus.recv(0.0)
            if msg is None:
                break
        return applied

    def _on_transfer(self, tr: dc.Transfer) -> int:
        if tr.full_name == dc.RAW_COMMAND:
            self._sequence(tr)
        if not self.tracker.observe(tr):
            self.rejects[DUPLICATE_TRANSFER] += 1
            return 0
        if tr.full_name == dc.NODE_STATUS:
            self.autopilot_health = int(tr.msg.health)
            return 0
        if self.conflict:
            self.rejects[NODE_ID_CONFLICT] += 1
            return 0
        cmd = [int(v) for v in tr.msg.cmd]
        if len(cmd) < 2:
            self.rejects[RAW_COMMAND_MISSING_INDEX] += 1
            return 0
        if any(abs(v) > dc.RAW_COMMAND_MAX for v in cmd[:2]):
            self.rejects[RAW_COMMAND_OUT_OF_RANGE] += 1
            return 0
        self.raw = (cmd[0], cmd[1])
        self.commands += 1
        self.commands_seen += 1
        if self.applied_times.enabled:
            self.applied_times.add(tr.transfer_id, self.clock())
        return 1

    def _sequence(self, tr: dc.Transfer) -> None:
        """Judge a RawCommand's transfer ID against its source's previous one (before the tracker records it)."""
        last = self.tracker.last.get((tr.full_name, tr.source_node))
        self._in_sequence.append(last is None or (tr.transfer_id - last) % dc.TRANSFER_ID_MODULO == 1)
        irregular = self._in_sequence.count(False)
        if not self.conflict and irregular >= CONFLICT_IRREGULAR:
            self.conflict = True
            self.conflicts += 1
        elif self.conflict and irregular == 0 and len(self._in_sequence) == CONFLICT_WINDOW:
            self.conflict = False

    def controls(self) -> tuple[float, float] | None:
        """The newest command as normalised (port, starboard) in [-1, 1], or None before any."""
        if self.raw is None:
            return None
        return self.raw[0] / dc.RAW_COMMAND_MAX, self.raw[1] / dc.RAW_COMMAND_MAX

    # -- publish ---------------------------------------------------------------------------
    def propeller(self, thrust: float, voltage: float | None = None) -> dict[str, float]:
        """Propeller speed (rpm), electrical power (W), current (A) at the supply ``voltage`` (V; None:
        [esc] voltage), temperature (K) at ``thrust`` N (simulator/battery.py draws the same power)."""
        e, v = self.esc, self.vessel
        if thrust >= 0:
            rpm = e.max_rpm * math.sqrt(thrust / v.T_max)
        else:
            rpm = -e.max_rpm * math.sqrt(thrust / v.T_min)
        power = e.max_power * (abs(rpm) / e.max_rpm) ** 3
        supply = e.voltage if voltage is None or voltage <= 0 else voltage
        return {"rpm": rpm, "power": power, "current": power / supply,
                "temperature": e.ambient_temperature + e.heating * power}

    def _send(self, k: int, full_name: str, payload: bytes, priority: int) -> None:
        for frame in dc.to_frames(full_name, payload, self.node_ids[k], self.tids[k].take(full_name), priority):
            try:
                self.bus.send(frame, timeout=0.1)
            except can.CanError:
                self.send_errors += 1
                return
        self.sent[f"{dc.short_name(full_name)}@{self.node_ids[k]}"] += 1

    def publish(self, t: float, thrust: tuple[float, float], voltage: float | None = None) -> None:
        """Send whatever is due at simulated time ``t`` (s) given the applied ``thrust`` (N) and the
        supply ``voltage`` (V: the battery's terminals; None: [esc] voltage)."""
        if t + 1e-9 >= self.next_status_t:
            self.next_status_t = t + 1.0 / self.p.status_rate_hz
            supply = self.esc.voltage if voltage is None or voltage <= 0 else voltage
            for k, th in enumerate(thrust):
                s = self.propeller(th, supply)
                msg = dc.make(dc.ESC_STATUS, error_count=0, voltage=supply, current=s["current"],
                              temperature=s["temperature"], rpm=int(round(s["rpm"])),
                              power_rating_pct=min(127, int(round(100.0 * s["power"] / self.esc.max_power))),
                              esc_index=k)
                self._send(k, dc.ESC_STATUS, dc.serialize(msg), dc.PRIORITY_MEDIUM)
        if t + 1e-9 >= self.next_node_status_t:
            self.next_node_status_t = t + 1.0 / self.p.node_status_rate_hz
            for k in range(len(self.node_ids)):
                self._send(k, dc.NODE_STATUS, dc.node_status(int(t)), dc.PRIORITY_LOW)

    def summary(self) -> EscBankSummary:
        return EscBankSummary(
            node_ids=list(self.node_ids),
            raw_commands_applied=self.commands,
            last_raw_command=list(self.raw) if self.raw else None,
            frames_received=self.receiver.frames,
            transfers_received=dict(sorted(self.tracker.received.items())),
            transfers_lost=dict(sorted(self.tracker.lost.items())),
            transfers_duplicated=dict(sorted(self.tracker.duplicated.items())),
            transfers_sent=dict(sorted(self.sent.items())),
            send_errors=self.send_errors,
            rejects=dict(sorted((self.receiver.rejects + self.rejects).items())),
            autopilot_health=self.autopilot_health,
            budget_stops=dict(sorted(self.budget_stops.items())),
            node_id_conflicts=self.conflicts,
        )
