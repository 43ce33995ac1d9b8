"""The planner's parameters a ground station may tune in flight (the local planner runs in the worker
process: its values travel to it with every planning cycle, :class:`autopilot_bridge.local_planning.WorldUpdate`)."""

from __future__ import annotations

from autopilot_bridge.parameters import Tunable
from planner.params import PlannerParams


class PlannerTuning:
    """PLN_PERCEPT_RAD and PLN_PNG_PROB, from the run's :class:`planner.params.PlannerParams`."""

    perceptual_radius = Tunable("PLN_PERCEPT_RAD", 5.0, 200.0, "m",
                                "radius of the perceptual domain (33 m in section 4.2 of the paper)")
    png_probability = Tunable("PLN_PNG_PROB", 0.0, 1.0, "", "probability of sampling the PNG node (section 3.2)")

    def __init__(self, initial: PlannerParams) -> None:
        self.initial = initial
        self.perceptual_radius = initial.perceptual_radius
        self.png_probability = initial.png_probability

    def overrides(self) -> dict[str, float]:
        """The values that differ from the worker's initial ones (PlannerParams field -> value)."""
        now = {"perceptual_radius": self.perceptual_radius, "png_probability": self.png_probability}
        return {k: v for k, v in now.items() if v != getattr(self.initial, k)}
