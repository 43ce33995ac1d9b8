"""The vessel's ground-station link: MAVLink 2 to any number of ground stations (Figure 2's console).

One :class:`GcsLink` per vessel computer, the autopilot's ``telemetry`` object. It is a thin composition
of one module per MAVLink microservice, all sharing an :class:`~.context.Outbox` and a
:class:`~.context.VehicleView`:

* :mod:`.transport` - UDP, TCP and serial endpoints; :mod:`.framing` - bytes to messages per peer;
* :mod:`.signing` - signature and replay check (one state per link and key) and the write gate;
* :mod:`.limits` - the frame budget per service call and the rate limits on read requests;
* :mod:`.telemetry` - streamed messages and their rates, messages on request, PING;
* :mod:`.command` - COMMAND_LONG/INT through a table keyed by MAV_CMD, SET_MODE, MANUAL_CONTROL, goto;
* :mod:`.mission_service` - the mission protocol (:class:`~.mission.MissionServer`) on the vessel's API;
* :mod:`.parameter` - the parameter protocol; :mod:`.failsafe` - the GCS-heartbeat failsafe.

Inbound messages are dispatched through :attr:`GcsLink.handlers`, a table keyed by message type that
each service fills (:meth:`handlers`). Before a handler runs, a frame passes the security gate and the
read limiter; only then is it copied to ``mirror_to`` (the `hil run` tap, which writes the run's .tlog).
Whatever arrives, nothing here raises into the control loop: bad input is counted and dropped.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Hashable
from typing import TypedDict

from autopilot_bridge.gcs.command import CommandService
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.context import Outbox, Transport, VehicleView
from autopilot_bridge.gcs.devices import GcsDevices, open_gcs_devices
from autopilot_bridge.gcs.failsafe import GcsFailsafe
from autopilot_bridge.gcs.framing import FrameParser
from autopilot_bridge.gcs.identity import Identity
from autopilot_bridge.gcs.limits import FRAME_BUDGET, ReadLimiter
from autopilot_bridge.gcs.mission import MissionServer
from autopilot_bridge.gcs.mission_service import MissionService
from autopilot_bridge.gcs.parameter import ParameterService
from autopilot_bridge.gcs.signing import (
    ReplayGuard,
    SecurityGate,
    load_signing_key,
)
from autopilot_bridge.gcs.telemetry import TelemetryService
from autopilot_bridge.parameters import Param, ParamTable, bind
from autopilot_bridge.vehicle_api import VehicleApi, VehicleStatus
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage
from common.percentiles import StreamingPercentiles

__all__ = ["GcsLink", "load_signing_key"]

Handler = Callable[[MavMessage, float], None]


class ServiceTimes(TypedDict):
    """Wall time of the link's service() calls, ms (None before any)."""

    p50: float | None
    p99: float | None
    max: float | None
    calls: int


class GcsSummary(TypedDict):
    """The ``gcs`` section of the summaries: what crossed the ground-station link and what it refused
    (counts by message type, reason or result)."""

    endpoints: list[str]
    datagrams_in: int
    datagrams_out: int
    frames_in: int
    frames_sent: int
    received: dict[str, int]
    rejects: dict[str, int]
    security_rejects: dict[str, int]
    signing: bool
    signature_failures: dict[str, int]
    missions_accepted: int
    missions_rejected: int
    mission_acks: dict[str, int]
    mission: dict[str, int]
    command_acks: dict[str, int]
    commands: dict[str, int]
    param_rejects: int
    encode_errors: dict[str, int]
    failsafe_events: int
    failsafe_active: bool
    service_ms: ServiceTimes


class GcsLink:
    """MAVLink 2 ground-station endpoint(s) of one vessel; the autopilot's ``telemetry`` object."""

    def __init__(self, params: GcsParams, devices: GcsDevices, geo: LocalFrame, *,
                 chart_size: tuple[float, float] | None = None,
                 clock: Callable[[], float] = time.monotonic, log: Callable[[str], None] | None = None) -> None:
        """The link on its opened ``devices`` (:func:`~.devices.open_gcs_devices`; the link owns and
        closes them); ``geo``: the vessel's NED frame; ``chart_size``: (rows, columns) of the chart."""
        self.params = params
        self.sysid, self.compid = devices.system_id, devices.component_id
        self.geo = geo
        self.clock = clock
        self.log: Callable[[str], None] = log or (lambda _m: None)
        self.key = devices.key
        self.transports: list[Transport] = devices.transports
        self.security: Counter[str] = devices.security   # refusals by reason: the gate's, the limits', the peer tables'
        self._datagrams_out_closed = 0      # per-peer sends of transports already closed
        self.addresses = [t.address for t in self.transports]
        codec = devices.codec
        system_id, component_id = devices.system_id, devices.component_id
        self.received: Counter[str] = Counter()
        self.rejects: Counter[str] = Counter()
        self.datagrams_in = 0               # UDP datagrams / TCP reads from ground stations
        self.guard = ReplayGuard(self.key) if self.key is not None else None
        self.gate = SecurityGate(self.key, params.allowed_sysids, self.security)
        self.limiter = ReadLimiter(self.security)
        self._parsers: dict[Hashable, FrameParser] = {}
        self.service_ms = StreamingPercentiles()   # wall time of each service() call, ms
        self._backlog: list[tuple[Transport, Hashable]] = []   # stream peers whose parser holds frames not yet decoded

        self.out = Outbox(codec, self.transports, devices.mirror, self.log)
        self.view = VehicleView(system_id, component_id, geo, chart_size)
        self.identity = Identity(params.identity, codec, self.view)
        self.failsafe = GcsFailsafe(self.out, self.view, params.failsafe_timeout, params.failsafe_action,
                                    require_signed=self.key is not None)
        self.mission_service = MissionService(self.out, self.view, self._mission_current,
                                              max_items=params.max_mission_items,
                                              item_timeout=params.mission_timeout, retries=params.mission_retries,
                                              home_item=self.identity.home_item)
        self.telemetry = TelemetryService(self.out, self.view, clock, self.identity,
                                          failsafe_active=lambda: self.failsafe.active,
                                          link_errors=lambda: sum(self.rejects.values()),
                                          mission_total=self.mission_service.total)
        self.parameter = ParameterService(self.out, self.view, self.security)
        self.command = CommandService(self.out, self.view, self.failsafe, self._mission_current)
        self.command.register(self.telemetry.commands())
        self.handlers: dict[str, Handler] = {}
        for service in (self.failsafe, self.telemetry, self.mission_service, self.parameter, self.command):
            table = service.handlers()
            twice = set(table) & set(self.handlers)
            if twice:
                raise ValueError(f"messages handled twice: {sorted(twice)}")
            self.handlers.update(table)

    @classmethod
    def open(cls, params: GcsParams, system_id: int, component_id: int, geo: LocalFrame, *,
             mirror_to: tuple[str, ...] = (), mirror_from: str = "127.0.0.1:0",
             chart_size: tuple[float, float] | None = None, clock: Callable[[], float] = time.monotonic,
             log: Callable[[str], None] | None = None) -> GcsLink:
        """A link that opens its own devices (:func:`~.devices.open_gcs_devices`), for tests and
        tools; the vessel computer's assembly opens them with its other devices."""
        devices = open_gcs_devices(params, system_id, component_id, mirror_to=mirror_to,
                                   mirror_from=mirror_from, clock=clock)
        return cls(params, devices, geo, chart_size=chart_size, clock=clock, log=log)

    # -- wiring ---------------------------------------------------------------------------------
    def attach(self, api: VehicleApi) -> None:
        """Connect to the vessel through its command API: its mission, its parameters and ours."""
        self.view.api = api
        self.mission_service.attach(api.mission())
        self.parameter.attach(ParamTable([*api.parameters(), *self.parameters()]))

    def parameters(self) -> list[Param]:
        """The link's own tunables: the GCS failsafe's and the system id."""
        return bind(self.failsafe, self.identity)

    # The vessel's side, as the services see it (tests set ``api`` and ``status`` directly).
    @property
    def api(self) -> VehicleApi | None:
        return self.view.api

    @api.setter
    def api(self, api: VehicleApi | None) -> None:
        self.view.api = api

    @property
    def status(self) -> VehicleStatus | None:
        return self.view.status

    @status.setter
    def status(self, status: VehicleStatus | None) -> None:
        self.view.status = status

    @property
    def mission(self) -> MissionServer | None:
        return self.mission_service.server

    @property
    def params_table(self) -> ParamTable | None:
        return self.parameter.table

    @property
    def sent(self) -> int:
        return self.out.sent

    @property
    def encode_errors(self) -> Counter[str]:
        return self.out.encode_errors

    # -- sending --------------------------------------------------------------------------------
    def forward(self, name: str, *fields: object) -> None:
        """Encode message ``name`` (e.g. "ais_vessel") with the vessel's ids and send it to every GCS."""
        self.out.send(name.lower(), *fields)

    def statustext(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        self.out.statustext(text, severity)

    def mission_item_reached(self, seq: int) -> None:
        self.out.send("mission_item_reached", seq)

    def heartbeat(self) -> None:
        self.telemetry.heartbeat()

    def _mission_current(self) -> None:
        self.telemetry.mission_current()

    def on_frame(self, status: VehicleStatus) -> None:
        """Per control frame: the streams that are due at the frame's simulated time, progress events."""
        try:
            self.view.t, self.view.status = status.t, status
            self.telemetry.on_frame()
        except Exception as exc:  # telemetry must never stop the control loop
            self._internal_error("on_frame", exc)

    def _internal_error(self, where: str, exc: Exception) -> None:
        self.out.encode_errors[where] += 1
        if self.out.encode_errors[where] == 1:
            self.log(f"gcs: {where}: {type(exc).__name__}: {exc}")

    # -- receiving ------------------------------------------------------------------------------
    def service(self) -> None:
        """Between frames: read the transports (within the frame budget), answer, run timeouts and the failsafe."""
        start = time.perf_counter()
        try:
            self._service()
        except Exception as exc:  # e.g. a socket error: the control loop goes on
            self._internal_error("service", exc)
        self.service_ms.add((time.perf_counter() - start) * 1e3)

    def _parser(self, tr: Transport, peer: Hashable) -> FrameParser:
        key = peer if tr.stream else "udp"   # datagrams: one parser (no partial frames kept)
        parser = self._parsers.get(key)
        if parser is None:
            parser = self._parsers[key] = FrameParser(self.guard)
        return parser

    def _service(self) -> None:
        now = self.clock()
        budget = FRAME_BUDGET
        # Streams cut by the last call's budget first: their frames are already here.
        backlog, self._backlog = self._backlog, []
        for tr, peer in backlog:
            if peer not in self._parsers:
                continue   # the connection closed
            if budget <= 0:
                self._backlog.append((tr, peer))
            else:
                budget = self._consume(tr, peer, b"", budget, now)
        for tr in self.transports:
            if budget <= 0:
                break
            # A stream peer is read once per call, and not while its parser still holds frames.
            hold = {peer for t, peer in self._backlog if t is tr}
            for peer, data in tr.receive(max_reads=1 if tr.stream else budget, hold=hold):
                if tr.stream and not data:
                    self._parsers.pop(peer, None)
                    continue
                self.datagrams_in += 1
                if budget > 0:
                    budget = self._consume(tr, peer, data, budget, now)
                elif tr.stream and self._parser(tr, peer).defer(data):
                    self._backlog.append((tr, peer))   # a stream's bytes are kept for the next call
                else:
                    self.security["frame_budget"] += 1
        self.parameter.tick()
        self.mission_service.tick(now)
        self.failsafe.check(now)
        self.telemetry.keep_alive()

    def _consume(self, tr: Transport, peer: Hashable, data: bytes, budget: int, now: float) -> int:
        """Decode and handle one read's frames within ``budget``; the budget left."""
        parser = self._parser(tr, peer)
        parsed = parser.parse(data, keep=tr.stream, max_frames=budget)
        budget -= len(parsed.msgs) + len(parsed.rejects)
        if parsed.over_budget_bytes:
            if tr.stream and parser.mav.buf_len() > 0:
                self._backlog.append((tr, peer))   # the rest of the stream next call
            else:
                self.security["frame_budget"] += 1
        for r in parsed.rejects:
            self.rejects[r] += 1
        for m in parsed.msgs:
            try:
                self._handle(m, now, tr, peer)
            except Exception as exc:  # absurd fields must never stop the boat
                self.rejects["handler_error"] += 1
                self.log(f"gcs: {m.get_type()} dropped: {type(exc).__name__}: {exc}")
        return budget

    def _handle(self, m: MavMessage, now: float, tr: Transport | None = None, peer: Hashable = None) -> None:
        kind = m.get_type()
        self.received[kind] += 1
        if m.get_srcSystem() == self.sysid and m.get_srcComponent() == self.compid:
            return  # our own frames looped back
        if not self.gate.allows(m, kind):
            self.command.refuse(m)
            self.mission_service.refuse(m)
            return
        if tr is not None:
            tr.heard(peer, self.gate.peer_rank(m, kind))   # a sender is a peer only past the gate (issue 31)
        if not self.limiter.allows(m, kind, now):
            return
        self.out.record(bytes(m.get_msgbuf()))   # only what passed the gate reaches the run's tap
        handler = self.handlers.get(kind)
        if handler is not None:
            handler(m, now)

    # -- end ------------------------------------------------------------------------------------
    def summary(self) -> GcsSummary:
        """The link's counters (the autopilot's summary and the run's summary.json carry them as "gcs").

        Datagrams count what crossed the sockets (out: one per peer a frame went to); frames count MAVLink
        messages (in: valid ones only, by type in ``received``; out: each frame once, fanned out or not).
        ``security_rejects`` counts, by reason, the writes the gate refused and the reads the limits refused.
        """
        out, server = self.out, self.mission_service.server
        acks = out.mission_acks
        return GcsSummary(
            endpoints=[f"{h}:{p}" for h, p in self.addresses],
            datagrams_in=self.datagrams_in,
            datagrams_out=self._datagrams_out_closed + sum(tr.sent for tr in self.transports),
            frames_in=sum(self.received.values()),
            frames_sent=out.sent,
            received=dict(self.received),
            rejects=dict(self.rejects),
            security_rejects=dict(self.security),
            signing=self.key is not None,
            signature_failures=dict(self.guard.refused) if self.guard is not None else {},
            missions_accepted=server.stats.get("uploads_accepted", 0) if server is not None else 0,
            missions_rejected=sum(n for r, n in acks.items() if r != "MAV_MISSION_ACCEPTED"),
            mission_acks=dict(acks),
            mission=dict(server.stats) if server is not None else {},
            command_acks=dict(out.command_acks),
            commands=dict(out.commands),
            param_rejects=self.parameter.table.rejected if self.parameter.table is not None else 0,
            encode_errors=dict(out.encode_errors),
            failsafe_events=self.failsafe.events,
            failsafe_active=self.failsafe.active,
            service_ms=ServiceTimes(p50=self.service_ms.percentile(50), p99=self.service_ms.percentile(99),
                                    max=self.service_ms.max if self.service_ms.count else None,
                                    calls=self.service_ms.count),
        )

    def close(self) -> None:
        for tr in self.transports:
            self._datagrams_out_closed += tr.sent
            tr.close()
        self.transports.clear()
        out = getattr(self, "out", None)
        if out is not None:
            out.close()
