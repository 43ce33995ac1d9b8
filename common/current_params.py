"""The ``[current]`` configuration: which current the simulator's truth and the planner share
(:mod:`common.current_sources`), with the constants of eq. (13) (:mod:`common.current_field`).
Declared here, beside the model it configures, so that ``common`` takes it typed; the simulator's
configuration (``simulator.config``) and ``hil.settings.HilConfig`` use it as their ``current``."""

from __future__ import annotations

from dataclasses import dataclass

from common.params import param


@dataclass(frozen=True)
class CurrentParams:
    """The meandering-jet current of eq. (13), constants of section 4.1."""

    enabled: bool = param("apply the current (vessel dynamics are water-relative)")
    b: float = param("mean meander amplitude b of B(t) = b + e cos(omega t + theta_u)")
    c: float = param("phase speed c of the meander (non-dimensional)")
    k_u: float = param("meander wave number k_u (non-dimensional)")
    omega: float = param("frequency omega of the amplitude modulation (non-dimensional)")
    e: float = param("modulation amplitude e")
    theta_u: float = param("modulation phase theta_u", "rad")
    sc: float = param("length scale: non-dimensional coordinate = sc * metres", "1/m", gt=0)
    time_scale: float = param("time scale: non-dimensional time = time_scale * seconds", "1/s", ge=0)
    speed_scale: float = param("velocity of unit stream-function gradient", "m/s", ge=0)
    origin_x: float = param("north coordinate of the jet's origin", "m")
    origin_y: float = param("east coordinate of the jet's axis", "m")
    # The other sources (common.current_sources): a file or a uniform current replaces eq. (13).
    file: str = param("netCDF file of the current (CF eastward/northward_sea_water_velocity on latitude, "
                      "longitude[, time]); relative to the scenario file when a scenario names it; '' = none",
                      default="")
    uniform: tuple[float, ...] = param("a uniform current [east, north]; [] = none", "m/s", ge=-10.0, le=10.0,
                                       default=())
    east_variable: str = param("the file's eastward velocity variable ('' = found by CF standard_name)", default="")
    north_variable: str = param("the file's northward velocity variable ('' = found by CF standard_name)",
                                default="")
    start_time: str = param("the file's time at the run's t = 0 (ISO 8601, UTC; '' = the file's first time)",
                            default="")
    reach: float = param("how far from the geodesy origin a current file is read (0 = all of it; a scenario sets "
                         "it from its map: the corners' distance + 2 km)", "m", ge=0.0, le=1_000_000.0, default=0.0)

    def __post_init__(self) -> None:
        if len(self.uniform) not in (0, 2):
            raise ValueError(f"uniform: expected [east, north] in m/s or [], got {len(self.uniform)} items")
        if self.file and self.uniform:
            raise ValueError("uniform: give either a file or a uniform current, not both")
