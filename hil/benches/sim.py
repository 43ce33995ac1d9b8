"""`hil bench sim`: RK4 model steps per second, and lockstep HIL steps per second over loopback UDP."""

from __future__ import annotations

import argparse
import subprocess
import time
from typing import TYPE_CHECKING

from hil.console import emit, load_settings, progress
from hil.errors import RunFailed
from hil.processes import stop as stop_process
from hil.sim_client import HilClient, sim_command, start_simulator

if TYPE_CHECKING:
    from hil.settings import HilConfig

GOAL_LOCKSTEP_STEPS_PER_S = 2000.0


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "sim", parents=parents,
        help="simulator speed: RK4 model steps/s and lockstep HIL steps/s over loopback UDP",
        description="Measures (1) RK4 steps per second of the vessel model alone, (2) frames per second "
                    "of the simulator core in-process (model + sensors + MAVLink encoding, no sockets) and "
                    "(3) lockstep HIL steps per second with `hil sim --lockstep` in its own process and a "
                    f"trivial constant-thrust controller in this one. Goal: >= {GOAL_LOCKSTEP_STEPS_PER_S:g} "
                    "lockstep steps/s.",
    )
    p.add_argument("--model-steps", type=int, default=200_000, metavar="N",
                   help="RK4 steps for the model measurement (default: 200000)")
    p.add_argument("--lockstep-steps", type=int, default=20_000, metavar="N",
                   help="lockstep HIL steps over UDP (default: 20000, i.e. 200 s simulated at 100 Hz)")
    p.set_defaults(func=run, seed=None, speedup=None)


def bench_model(cfg: HilConfig, n: int) -> float:
    """RK4 steps per second of the hull (``simulator.vessel.hull_rk4_step``, the simulator's
    integration: thrust, waves and current held); compiled before the clock starts."""
    from simulator.vessel import Vessel, hull_rk4_step

    vessel = Vessel(cfg.vessel)
    tau = vessel.propulsion(vessel.thrust(0.8), vessel.thrust(0.6))
    tau_w, cur = (1.0, 2.0, 0.3), (0.1, 0.2)
    s = (0.0,) * 6
    k, dt = vessel.coefficients, float(cfg.sim.dt)
    hull_rk4_step(s, dt, tau, tau_w, cur, k)
    t0 = time.perf_counter()
    for _ in range(n):
        s = hull_rk4_step(s, dt, tau, tau_w, cur, k)
    return n / (time.perf_counter() - t0)


def bench_core(cfg: HilConfig, n: int) -> float:
    """Frames per second of SimulatorCore (step + frame encoding), no sockets."""
    from hil.assembly.simulator import simulator_settings
    from simulator.core import Command, SimulatorCore

    core = SimulatorCore(simulator_settings(cfg))
    t0 = time.perf_counter()
    for _ in range(n):
        core.frame()
        core.apply(Command(core.time_usec, 0.8, 0.6))
        core.step()
    return n / (time.perf_counter() - t0)


def bench_lockstep(args: argparse.Namespace, cfg: HilConfig, n: int) -> dict:
    """Lockstep steps/s measured by the controller between the first and the last frame."""
    args.duration = n * (1.0 / cfg.sensors.imu.rate_hz)
    client = HilClient()
    proc = start_simulator(sim_command(args, client.port, lockstep=True),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        first = client.next_frame(timeout=30.0)
        if first is None or first.time_usec is None:
            raise RunFailed("bench sim: no first frame from the simulator")
        t0 = time.perf_counter()
        steps, t_usec = 0, first.time_usec
        while steps < n:
            client.command(t_usec, 0.8, 0.6)
            frame = client.next_frame(timeout=10.0)
            if frame is None or frame.time_usec is None:
                raise RunFailed(f"bench sim: simulator stopped answering after {steps} steps")
            t_usec = frame.time_usec
            steps += 1
        wall = time.perf_counter() - t0
    finally:
        stop_process(proc)
        client.close()
    return {"steps": steps, "wall_s": wall, "steps_per_s": steps / wall}


def run(args: argparse.Namespace) -> int:
    from common.mavlink import CRC_BACKEND

    cfg = load_settings(args)
    progress(f"bench sim: RK4 model, {args.model_steps} steps")
    model = bench_model(cfg, args.model_steps)
    progress(f"bench sim: simulator core in-process, {args.lockstep_steps} frames")
    core = bench_core(cfg, args.lockstep_steps)
    progress(f"bench sim: lockstep over loopback UDP, {args.lockstep_steps} steps")
    lock = bench_lockstep(args, cfg, args.lockstep_steps)
    rate = cfg.sensors.imu.rate_hz
    summary = {
        "model_rk4_steps_per_s": model,
        "core_frames_per_s": core,
        "lockstep_steps_per_s": lock["steps_per_s"],
        "lockstep_steps": lock["steps"],
        "lockstep_wall_s": lock["wall_s"],
        "lockstep_times_real_time": lock["steps_per_s"] / rate,
        "goal_lockstep_steps_per_s": GOAL_LOCKSTEP_STEPS_PER_S,
        "goal_met": lock["steps_per_s"] >= GOAL_LOCKSTEP_STEPS_PER_S,
        "mavlink_crc": CRC_BACKEND,
    }
    emit(args, summary)
    return 0
