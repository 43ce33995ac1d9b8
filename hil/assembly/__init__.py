"""Assembly of the two processes from a configuration and a scenario: the vessel computer
(:mod:`hil.assembly.computer`) and the simulator (:mod:`hil.assembly.simulator`). The commands
(`hil autopilot`, `hil sim`) parse their options and run what these build."""

from hil.assembly.computer import (
    build,
    computer_config,
    computer_settings,
    max_time_step,
    planning_world,
    run_options,
)
from hil.assembly.simulator import SimulatorParts, build_simulator, scenario_world, simulator_settings

__all__ = ["SimulatorParts", "build", "build_simulator", "computer_config", "computer_settings", "max_time_step",
           "planning_world", "run_options", "scenario_world", "simulator_settings"]
