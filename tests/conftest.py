"""Shared fixtures: the repository root and runners for the `hil` command, as a real subprocess and
in-process (hil.cli.main); the test tiers."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def repo() -> Path:
    return REPO


def run_hil(*args: str, timeout: float = 300, env: dict | None = None,
            cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `python -m hil ARGS` as a subprocess (the way a user runs it) and capture its output."""
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run(
        [sys.executable, "-m", "hil", *args],
        capture_output=True, text=True, timeout=timeout, env=full_env, cwd=cwd or REPO,
    )


@pytest.fixture
def hil():
    return run_hil


@pytest.fixture
def hil_main(capsys):
    """Like ``hil``, but in-process through hil.cli.main (argument and configuration errors)."""
    from support.cli import run_cli

    def run(*args: str, timeout: float | None = None) -> subprocess.CompletedProcess:
        return run_cli(capsys, *args)   # no timeout in-process: nothing runs long

    return run


# -- test tiers --------------------------------------------------------------------------------
# Every test is in exactly one tier, from its module (and `slow`, which always means e2e):
#   unit         in-process, no sockets, no subprocesses: seconds for the whole tier;
#   integration  one component over real sockets, subprocesses, CAN buses or a short campaign;
#   e2e          whole HIL runs (simulator + vessel computer + tap), ground-station sessions,
#                User-Mode Linux, and everything marked `slow`.
# `pytest -m "not e2e"` is the developer's loop; the README's command and CI run every tier.
# A new test module must be listed here: collection fails otherwise, so no test falls through.
UNIT_MODULES = frozenset("""
    can_codec can_esc charts collision_cone colregs colregs_oracle config config_layers control current_field
    current_curvilinear current_sources current_tally current_window docs_examples geodesy ardupilot_fence
    global_route guidance_kernel mavlink_crc mavlink_fast_path mission_executor modes navigation navigation_fast
    battery_monitor config_ranges encounter_route online percentiles plan_commitment plan_start_course readiness
    planner_algorithms planner_config planner_cost planner_dynamic_domain planner_fence planner_gridmap
    planner_issue34 flow_optimum planner_registry planner_stable_argsort planner_tree_golden thread_cpu_deadline
    planner_guidance planner_kgrowth planner_metrics planner_postprocess process_logging reactive route_planning
    run_judging run_plot scenarios sim_sensors sim_vessel sim_waves simulator_assembly summaries tiers tracking_stats
    traffic_planning vehicle world_keeper
""".split())
INTEGRATION_MODULES = frozenset("""
    ardupilot_json
    autopilot_link battery bench_can_flood bench_frame bench_planner busy_poll cli computer_assembly connection cpu_load
    executors
    gcs_esc_telemetry
    gcs_fuzz first_run friction gcs_security gcs_lockout gcs_link gcs_mission geo_cli hil_link_fast_path montecarlo
    output placement plan_cli planner_warmup
    planning_worker range_sensing
    readme security_gates sim_link sim_pause sim_pipeline sim_udp startup_errors tap_fast_path traffic_ais
    vehicle_commands vessel_parameters warm_up
""".split())
E2E_MODULES = frozenset("""
    ardupilot_sitl by_hand can_vcan colregs_loop example_world gcs_chaos gcs_mavproxy gcs_mavsdk gcs_rover
    gcs_session gcs_telemetry_truth hil_faults hil_loop hil_vcan holding_ground instances
    mission_done route_mission security_loop sparse_routes
""".split())
TIERS = ("unit", "integration", "e2e")


def pytest_configure(config: pytest.Config) -> None:
    # A suite started as a background job of a non-interactive shell (`cmd &`) has SIGINT ignored, and
    # an ignored signal stays ignored across exec: every `hil` subprocess would then ignore the Ctrl-C
    # that the interrupt tests send. Python's own handler is reset by exec, so the children start with
    # SIGINT as a terminal gives it.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    for tier, what in zip(TIERS, ("in-process, no sockets or subprocesses",
                                  "one component over real sockets, subprocesses or buses",
                                  "whole HIL runs, ground-station sessions, User-Mode Linux"), strict=True):
        config.addinivalue_line("markers", f"{tier}: {what} (tests/conftest.py)")


def tier_of(module: str, slow: bool) -> str:
    """The tier of a test in ``tests/test_<module>.py``; raises for a module no tier lists."""
    if slow or module in E2E_MODULES:
        return "e2e"
    if module in INTEGRATION_MODULES:
        return "integration"
    if module in UNIT_MODULES:
        return "unit"
    raise pytest.UsageError(f"tests/test_{module}.py is in no test tier: add it to tests/conftest.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        module = item.path.stem.removeprefix("test_")
        item.add_marker(tier_of(module, item.get_closest_marker("slow") is not None))
