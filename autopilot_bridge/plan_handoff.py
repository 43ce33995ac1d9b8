"""The vessel computer's side of the planner worker (step 2 of autopilot_bridge/autopilot.py).

One request at a time: a local planning cycle is submitted from the position predicted at the end
of its deadline, and its answer is collected without blocking (real time), or at exactly
``planning_deadline`` later in simulated time (lockstep: the simulator waits for us, so waiting
costs no simulated time and runs are repeatable). Answers for a route that has since changed are
dropped. What the computer does with an answer (checks, commitment, following) stays in
:class:`autopilot_bridge.autopilot.Autopilot`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.local_planning import CycleInput, LocalPlan, WorldUpdate, ned_to_map
from autopilot_bridge.navigation import NavState
from autopilot_bridge.parameters import Tunable
from autopilot_bridge.planning_worker import PlannerWorker, PlanRequest
from planner.params import SEED_MAX

if TYPE_CHECKING:
    from autopilot_bridge.computer_setup import AutopilotStats
    from autopilot_bridge.obstacle_map import SensedObstacles
    from autopilot_bridge.traffic_awareness import TrafficAwareness


def cycle_seed(run_seed: int, cycle: int) -> int:
    """The planner's seed of planning cycle ``cycle`` of a run seeded ``run_seed``: the two mixed, kept
    within the planner's signed 64 bits (``planner.params.SEED_MAX``; identity for the seeds that fit)."""
    return (run_seed * 100003 + cycle) % (SEED_MAX + 1)


class PlanHandoff:
    """Submits planning cycles to ``worker`` and collects their answers.

    It owns the planning deadline (PLN_DEADLINE, at most 0.95 x the planning period); ``speed()`` is
    the speed set-point now (m/s, the vehicle's), with which the traffic assessment predicts the boat.
    ``event(t, text)`` records what the computer should tell (a restarted worker); counters go to
    the computer's ``stats`` (planning cycles, planner waits in lockstep, rejected answers)."""

    deadline = Tunable("PLN_DEADLINE", 0.05, lambda o: 0.95 * o.p.planning_period, "s",
                       "hard deadline of one local planning cycle (the watchdog's)")

    def __init__(self, worker: PlannerWorker[CycleInput, LocalPlan], params: AutopilotParams, lockstep: bool, seed: int,
                 stats: AutopilotStats, event: Callable[[float, str], None], speed: Callable[[], float]) -> None:
        self.worker, self.p, self.lockstep, self.seed = worker, params, lockstep, seed
        self.deadline = params.planning_deadline
        self.stats, self._event, self.speed = stats, event, speed
        self.sensed_at_submit = 0        # sensed obstacles known when the pending cycle was submitted
        self.reset()

    def reset(self) -> None:
        """Start over (the simulator restarted): cycle numbers from 1 again, nothing pending."""
        self.cycle = 0
        self.stale_cycle = 0             # answers of cycles up to this one are for an older route
        self.pending_since: float | None = None  # simulated time (s) of the pending request
        self.traffic_planned = False     # the pending/last cycle planned around ships

    def route_changed(self) -> None:
        """Whatever the worker is planning now is for the old route: its answer will be dropped."""
        self.stale_cycle = self.cycle

    def submit(self, s: NavState, sensed: SensedObstacles, traffic: TrafficAwareness | None,
               world_update: WorldUpdate | None) -> None:
        """Hand the next cycle to the worker, planned from where the vessel (estimate ``s``, NED)
        will be at the end of the planning deadline; ``traffic``: TrafficAwareness or None;
        ``world_update``: what the worker must use instead of its initial World (None: nothing)."""
        lead = self.deadline
        north = s.x + (s.u * math.cos(s.psi) - s.v * math.sin(s.psi)) * lead
        east = s.y + (s.u * math.sin(s.psi) + s.v * math.cos(s.psi)) * lead
        # The path is a ground track that the guidance steers as a course (Helm._control turns
        # the hull by the drift angle): it starts along the course over ground, not the heading.
        # From the heading, in a cross-current each cycle's path began turned by the drift angle,
        # the compensation turned the hull further the same way, and the vessel spiralled off.
        x, y, heading = ned_to_map(north, east, s.course(self.p.min_turn_speed))
        self.cycle += 1
        self.sensed_at_submit = sensed.count
        snap = None if traffic is None else traffic.snapshot(s.t + lead, x, y, heading, self.speed())
        self.traffic_planned = snap is not None   # ships move: their cycle's newest plan always wins
        request = PlanRequest(
            cycle=self.cycle,
            problem=CycleInput(x, y, heading, s.t + lead, cycle_seed(self.seed, self.cycle),
                               sensed.cells() if self.sensed_at_submit else None, sensed.version,
                               traffic=snap, world=world_update),
            deadline_s=self.deadline,
            iterations=self.p.lockstep_iterations if self.lockstep else None,
        )
        if self.lockstep:
            # Simulated time stands still while a (re)started worker starts up: lockstep stays repeatable.
            self.worker.wait_ready(self.p.lockstep_planner_timeout)
        if self.worker.submit(request):
            self.stats.planning_cycles += 1
            self.pending_since = s.t

    def collect(self, t: float) -> tuple[LocalPlan | None, bool]:
        """(the pending cycle's plan if it is due and usable, whether this frame waited for the
        planner): in lockstep such a frame measures the planner, not the control loop."""
        if self.pending_since is None:
            return None, False
        waited = False
        if self.lockstep:
            if t + 1e-9 < self.pending_since + self.deadline:
                return None, False
            # Simulated time stands still while we wait: bounded by the watchdog's wall limit.
            waited = True
            w0 = time.perf_counter()
            reply = self.worker.wait(self.p.lockstep_planner_timeout)
            self.stats.planner_waits += 1
            self.stats.planner_wait_ms.append((time.perf_counter() - w0) * 1e3)
            if reply is None and self.worker.busy and self.worker.watchdog(now=time.monotonic() + 1e9):
                self._event(t, "planner hung: worker killed and restarted")
        else:
            reply = self.worker.poll()
            if reply is None:
                if self.worker.watchdog():
                    self._event(t, "planner overran its deadline: worker killed and restarted")
                    self.pending_since = None
                return None, False
        self.pending_since = None
        if reply is None:
            return None, waited
        if reply.error:
            self.stats.plans_rejected["planner_error"] += 1
            self._event(t, f"planner error: {reply.error}")
            return None, waited
        if reply.cycle <= self.stale_cycle:
            self.stats.plans_rejected["for_an_older_route"] += 1
            return None, waited
        return reply.result, waited
