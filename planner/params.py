"""Parameters of the local planner: the ``[planner]`` section of the configuration.

The planner library imports nothing of ours, so the fields carry the project's metadata
convention (``help``, ``unit``, ``gt``/``ge``/``lt``/``le``) through ``dataclasses.field``
directly; ``hil.config`` checks the bounds on load. Defaults and their sources are explained in
``docs/planner.md`` and in ``configs/default.toml``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal


@dataclass(frozen=True)
class PlannerEntry:
    """One planner of the registry: adding a planner is its class and one entry in ``REGISTRY``.
    Commands (choices), experiments (labels, seeds), figures (colours), ``make_planner`` and the
    warm-up all read the table."""

    name: str      # the configuration's and the command line's name
    label: str     # short name in tables and legends
    colour: str    # matplotlib colour of its paths in figures
    target: str    # "module:Class", a planner.core.TreePlanner subclass, imported on first use


# The order fixes the per-algorithm planner seeds of the Monte Carlo experiments (hil.experiment).
REGISTRY: tuple[PlannerEntry, ...] = (
    PlannerEntry("rrt-star", "RRT*", "tab:blue", "planner.rrt_star:RRTStar"),
    PlannerEntry("informed-rrt-star", "IRRT*", "tab:orange", "planner.informed_rrt_star:InformedRRTStar"),
    PlannerEntry("ddrrt-star", "DDRRT*", "red", "planner.ddrrt_star:DDRRTStar"),
)
ENTRIES = {e.name: e for e in REGISTRY}
ALGORITHM_NAMES = tuple(e.name for e in REGISTRY)
if TYPE_CHECKING:
    AlgorithmName = str
else:  # the names as a Literal read from the table (hil.config offers them as choices)
    AlgorithmName = Literal[ALGORITHM_NAMES]
Objective = Literal["length", "current"]
DYNAMIC_DOMAINS = ("off", "constant", "adaptive")
FAILED_EXTENSIONS = ("collision", "collision+turn")
ALPHA_Y_REFERENCES = ("current", "resultant")
OBJECTIVES = ("length", "current")
SEED_MAX = 2**63 - 1  # the compiled generator (numpy.random.seed under numba) takes a signed 64-bit integer


def _p(help: str, unit: str = "", *, gt: float | None = None, ge: float | None = None, lt: float | None = None,
       le: float | None = None, default: object = None) -> Any:   # a field specifier: Any, as dataclasses.field's own
    meta = {"help": help, "unit": unit, "gt": gt, "ge": ge, "lt": lt, "le": le}
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class PlannerParams:
    """Tuning of the sampling-based local planners (map frame: x east, y north, metres)."""

    algorithm: AlgorithmName = _p(
        "planner: " + " | ".join(ALGORITHM_NAMES), default="ddrrt-star")
    objective: Objective = _p(
        "path cost: 'length' (Euclidean) or 'current' (cost distance D_C of eq. (12))", default="current")
    step: float = _p("maximum extension length of one tree edge", "m", gt=0, default=4.0)
    speed: float = _p("planning speed v (DR = dr_factor v sigma_t, turning radius factor * v)", "m/s",
                      gt=0, default=2.0)
    sigma_t: float = _p("duration sigma_t of one path extension", "s", gt=0, default=2.0)
    dr_factor: float = _p("DR = dr_factor * v * sigma_t, the dynamic-domain radius of eq. (11)", "",
                          gt=0, default=10.0)
    dynamic_domain: Literal["off", "constant", "adaptive"] = _p(
        "DDRRT*'s dynamic domain DD of eq. (11), a disc of radius DD about a node (Yershova et al. 2005): "
        "'off' keeps DD infinite; 'constant' sets DD = DR at a node's first failed extension (the paper); "
        "'adaptive' also shrinks DD by (1 - dd_alpha) at every further failure and grows it by (1 + dd_alpha) "
        "at every success (Jaillet et al. 2005). Samples outside the domains of all k nearest nodes are "
        "dropped (docs/planner.md)", default="adaptive")
    dd_radius: float = _p(
        "DDRRT*: the radius a node's dynamic domain takes at its first failed extension; 0 = DR of eq. (11) "
        "(dr_factor v sigma_t = 40 m, the paper's, which exceeds the 33 m perceptual radius and never acts: "
        "docs/planner.md)", "m", ge=0, default=0.0)
    failed_extension: Literal["collision", "collision+turn"] = _p(
        "DDRRT*: what counts as a failed extension that bounds a node's dynamic domain: 'collision' only, or "
        "'collision+turn' (also an edge outside the turning-radius fan of section 2.4, as the paper counts "
        "constraint violations)", default="collision")
    png_repair: bool = _p(
        "DDRRT*: move a PGNode that lies in an obstacle, outside the sampling domain or in another free region "
        "to the nearest usable cell centre, and stop drawing it once a tree node sits on it (issue 34)",
        default=False)
    alpha_y: Literal["current", "resultant"] = _p(
        "the disturbance alpha_y of eqs. (11)-(12) is measured against: 'current' alone, or 'resultant' of the "
        "current and the wave drift (section 3.4: 'the resultant moment direction of current and wave "
        "moments'; PlanningProblem.wave_drift)", default="current")
    dd_alpha: float = _p("adaptive dynamic domain: relative growth on success / shrink on failure", "", ge=0, lt=1,
                         default=0.1)
    dd_min_factor: float = _p("adaptive dynamic domain: DD never shrinks below dd_min_factor * step", "", gt=0,
                              default=1.0)
    d_alpha: float = _p("D_alpha of eqs. (11)-(12)", "", gt=0, default=1.0)
    gamma_alpha: float = _p("gamma_alpha of eqs. (11)-(12)", "", ge=0, default=0.1)
    k_nearest: int = _p("k nearest tree nodes examined per sample by DDRRT* (the least, with k_growth)", "",
                        ge=1, le=64, default=5)
    k_growth: float = _p("DDRRT*: 0 keeps k fixed (the paper); > 0 grows k to ceil(k_growth log n), capped "
                         "at 64, as k-nearest RRT* needs for asymptotic optimality (OMPL: 1.1 e (1 + 1/d) = 4.48)",
                         "", ge=0, default=2.0)
    png_probability: float = _p("probability P of sampling the PNG node (section 3.2)", "", ge=0, le=1,
                                default=0.2)
    png_nav_ratio: float = _p("effective navigation ratio N of theta' = N q' (section 3.2)", "", gt=0,
                              default=3.0)
    png_tolerance: float = _p("stop iterating eqs. (7)-(8) when delta-q changes less than this", "rad",
                              gt=0, default=1e-3)
    png_max_iterations: int = _p("cap on the iterations of eqs. (7)-(8)", "", ge=1, default=20)
    goal_bias: float = _p("probability of sampling the goal (when the PNG node is not drawn)", "",
                          ge=0, le=1, default=0.05)
    goal_tolerance: float = _p("a node this close to the goal tries the exact connection", "m", gt=0,
                               default=2.0)
    turn_radius_factor: float = _p(
        "minimum turning radius = factor * speed (1.5 in section 2.4); 0 disables the fan limit", "",
        ge=0, default=1.5)
    rewire_gamma: float = _p(
        "RRT* near radius = rewire_gamma * gamma*_RRT (log n / n)^(1/2), capped by step (OMPL's rewire factor)",
        "", gt=0, default=1.1)
    safety_radius: float = _p("obstacle inflation by the vessel's safety radius", "m", ge=0, default=2.0)
    velocity_inflation_gain: float = _p(
        "extra inflation per m/s of velocity towards an obstacle (section 3.3)", "s", ge=0, default=1.0)
    perceptual_radius: float = _p("radius of the perceptual domain (33 m in section 4.2)", "m", gt=0,
                                  default=33.0)
    max_nodes: int = _p("capacity of the tree (the planner stops when full)", "", ge=2, default=200_000)
    seed: int = _p("seed of the planner's random numbers (same seed -> same path)", "", ge=0, le=SEED_MAX, default=1)

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHM_NAMES:
            raise ValueError(f"algorithm: must be one of {', '.join(ALGORITHM_NAMES)} (got {self.algorithm!r})")
        if self.dynamic_domain not in DYNAMIC_DOMAINS:
            raise ValueError(f"dynamic_domain: must be one of {', '.join(DYNAMIC_DOMAINS)} "
                             f"(got {self.dynamic_domain!r})")
        if self.failed_extension not in FAILED_EXTENSIONS:
            raise ValueError(f"failed_extension: must be one of {', '.join(FAILED_EXTENSIONS)} "
                             f"(got {self.failed_extension!r})")
        if self.alpha_y not in ALPHA_Y_REFERENCES:
            raise ValueError(f"alpha_y: must be one of {', '.join(ALPHA_Y_REFERENCES)} (got {self.alpha_y!r})")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective: must be one of {', '.join(OBJECTIVES)} (got {self.objective!r})")

    @property
    def dynamic_domain_radius(self) -> float:
        """DR of eq. (11): dr_factor * v * sigma_t (m)."""
        return self.dr_factor * self.speed * self.sigma_t

    @property
    def dynamic_domain_start(self) -> float:
        """DD of a node after its first failed extension (m): dd_radius, or DR when that is 0."""
        return self.dd_radius if self.dd_radius > 0 else self.dynamic_domain_radius

    @property
    def turning_radius(self) -> float:
        """Minimum turning radius of section 2.4 (m); 0 = no kinematic limit."""
        return self.turn_radius_factor * self.speed

    @property
    def max_turn_angle(self) -> float:
        """Half-angle of the fan of section 2.4 (rad): the heading change of an arc of length step
        on the minimum turning circle, step / R_min (pi when the limit is disabled)."""
        r = self.turning_radius
        if r <= 0:
            return math.pi
        return min(math.pi, self.step / r)
