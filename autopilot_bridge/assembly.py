"""The vessel computer assembled from the root of its own configuration (:class:`ComputerSettings`).

The package owns this root: each section is typed by the part that reads it, and nothing of the
simulator's or the HIL tool's configuration reaches past it (`hil.assembly.computer` derives a
:class:`ComputerSettings` from the HIL configuration, then only hands it down). :func:`build_computer`
opens the devices (the simulator's HIL link, the DroneCAN thrusters, the ground-station link), starts
the planner worker and builds the :class:`autopilot_bridge.autopilot.Autopilot` on them.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import time
from collections.abc import Callable
from dataclasses import dataclass

from autopilot_bridge.ais_tracking import TrackerParams
from autopilot_bridge.autopilot import Autopilot
from autopilot_bridge.computer_setup import ComputerConfig, Devices, RunOptions
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.devices import open_gcs_devices
from autopilot_bridge.gcs.link import GcsLink
from autopilot_bridge.hil_link import TAKEN, HilLink
from autopilot_bridge.local_planning import CycleInput, LocalPlan, World, online_cycle_handler
from autopilot_bridge.planning_worker import PlannerWorker
from autopilot_bridge.traffic_awareness import TrafficAwareness
from common.can_params import CanParams, open_bus
from common.geodesy import LocalFrame
from common.mavlink import Codec
from common.udp import BusyPoll, UdpEndpoint
from planner.colregs import ColregsParams
from planner.gridmap import OccupancyGrid


class SetupError(ValueError):
    """A device that cannot be opened as configured (an address in use, no such CAN interface): the
    caller reports it in one line."""


@dataclass(frozen=True)
class SimulatorPeer:
    """What the vessel computer knows of the simulator at the other end of its HIL link: its MAVLink
    ids, the component id its truth frames (AIS targets) come from, the compass declination (rad)
    its sensors apply, and the largest forward step (s) of sensor time a frame may take."""

    system_id: int
    component_id: int
    truth_component_id: int
    declination: float
    max_time_step: float


@dataclass(frozen=True)
class ComputerSettings:
    """The root of the vessel computer's configuration: its tuning, the WGS-84 origin of its local
    NED frame (deg, deg, m), the simulator it is linked to, the ground-station link, AIS tracking
    and COLREGs, the CAN bus (``can.actuators == "can"``: thrusters by DroneCAN) and the seed of
    its fault injection."""

    tuning: ComputerConfig
    origin: tuple[float, float, float]
    simulator: SimulatorPeer
    gcs: GcsParams
    tracking: TrackerParams
    colregs: ColregsParams
    can: CanParams
    loss_seed: int


def _no_wait(_group: str) -> None:
    return None   # nothing compiles elsewhere


def build_computer(settings: ComputerSettings, world: World, options: RunOptions, chart_size: tuple[float, float],
                   start: CycleInput, *, planner_factory: str | None = None, sensors_from: str | None = None,
                   wait_for: Callable[[str], object] = _no_wait,
                   log: Callable[[str], None] = lambda _m: None) -> tuple[Autopilot, HilLink]:
    """The autopilot and its devices, with its HIL link to the simulator (the caller reports and closes
    it; the autopilot sees a SensorLink). ``start``: the planning cycle from the scenario's start that
    warms the planner up; ``wait_for(group)``: called before the parts that need a group of compiled
    kernels ("planner", "vessel-computer"). A device that cannot be opened raises :class:`SetupError`,
    with every device opened before it closed again."""
    ap, peer = settings.tuning.params, settings.simulator
    with contextlib.ExitStack() as opened:   # a device that fails closes those opened before it
        try:
            # Each device's parts are opened here and handed over built: first the ground-station
            # link's, then the socket, codecs and CAN bus of common/ and the chart's grid of planner/,
            # then the devices built on them.
            gcs_devices = open_gcs_devices(settings.gcs, ap.system_id, ap.component_id, mirror_to=ap.telemetry_to,
                                           mirror_from=ap.telemetry_from)
            opened.callback(gcs_devices.close)
            geo = LocalFrame(*settings.origin)
            sensors_ep = UdpEndpoint(ap.listen, list(ap.actuators_to), send_loss=ap.send_loss,
                                     recv_loss=ap.recv_loss, loss_seed=settings.loss_seed)
            opened.callback(sensors_ep.close)
            if sensors_from:
                try:
                    sensors_ep.set_peer(sensors_from)   # only the simulator's address
                except (ValueError, OSError) as exc:
                    raise ValueError(f"sensors_from {sensors_from!r}: {exc}") from None
            codec = Codec(ap.system_id, ap.component_id, accept=TAKEN)
            # lockstep: each wait for a frame polls the socket first
            busy = BusyPoll(ap.lockstep_busy_poll) if options.lockstep and ap.lockstep_busy_poll > 0 else None
            bus, receiver = None, None
            if settings.can.actuators == "can":
                from autopilot_bridge.can_actuators import RECEIVED
                from common.dronecan_codec import TransferReceiver

                bus = open_bus(settings.can)
                opened.callback(bus.shutdown)
                receiver = TransferReceiver(list(RECEIVED), nodes=tuple(settings.can.esc_node_ids),
                                            own_nodes=[settings.can.autopilot_node_id])   # the ESCs' transfers
            chart = OccupancyGrid(world.occ.copy(), world.resolution)   # the autopilot's, sensed obstacles added
            link = HilLink(sensors_ep, codec, geo, busy=busy, declination=peer.declination,
                           truth_component_id=peer.truth_component_id, sim_ids=(peer.system_id, peer.component_id),
                           max_time_step=peer.max_time_step, late_window=ap.sim_restart_gap,
                           realtime=not options.lockstep)
            telemetry = GcsLink(settings.gcs, gcs_devices, geo, chart_size=chart_size, log=log)  # rows, columns
            actuators = None
            if bus is not None:
                from autopilot_bridge.can_actuators import CanActuators

                actuators = CanActuators(bus, settings.can, lockstep_token=link if options.lockstep else None,
                                         receiver=receiver)
        except ValueError as exc:
            raise SetupError(str(exc)) from None
        opened.pop_all()   # all open: the caller owns them now
    worker = _planner_worker(world, start, ap.watchdog_grace, planner_factory)   # started last, below
    traffic = TrafficAwareness(settings.tracking, settings.colregs, geo)  # AIS targets, COLREGs encounters
    wait_for("vessel-computer")   # the filter's, guidance's and obstacle map's kernels
    autopilot = Autopilot(settings.tuning, world,
                          Devices(link, worker, telemetry, traffic=traffic, actuators=actuators), options, grid=chart)
    telemetry.attach(autopilot.commands)
    _warm_up_planner(world, start, wait_for, log)
    worker.start()   # forked from the warmed-up process, once every part is built
    return autopilot, link


def _planner_worker(world: World, start: CycleInput, grace_s: float, planner_factory: str | None
                    ) -> PlannerWorker[CycleInput, LocalPlan]:
    """The planner worker, not started yet: :func:`build_computer` starts it after
    :func:`_warm_up_planner`, so that forked workers inherit the compiled kernels."""
    # fork: a restarted worker inherits the world instead of receiving it pickled; with spawn the
    # parent blocks writing ~100 KB into a 64 KB pipe until the new interpreter has started, which
    # stalls the control loop on every watchdog restart.
    start_method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    if planner_factory:
        return PlannerWorker(planner_factory, (), grace_s=grace_s, start_method=start_method, start=False)
    # Each (re)started worker warms up too (its first cycle would pay the fork's page faults).
    return PlannerWorker("autopilot_bridge.local_planning:online_cycle_handler", (world, start),
                         grace_s=grace_s, start_method=start_method, start=False)


def _warm_up_planner(world: World, start: CycleInput, wait_for: Callable[[str], object],
                     log: Callable[[str], None]) -> None:
    """One real planning cycle here from ``start``: it compiles (first run on a machine: ~7 s) or
    loads everything a cycle uses (tree core, grid kernels of pruning and smoothing) once, before the
    control loop starts; forked workers inherit it, so no planning cycle pays for it."""
    t0 = time.monotonic()
    wait_for("planner")
    wait_for("vessel-computer")   # on a cold cache it compiles the planner's tree reuse (hil/warm_up.py)
    online_cycle_handler(world, start)
    spent = time.monotonic() - t0
    if spent > 1.0:
        log(f"autopilot: planner compiled and warmed up in {spent:.1f} s (cached for next time)")
