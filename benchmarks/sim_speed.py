"""Simulation speed of the simulated robot, as a multiple of real time, on both plants.

Runs the full 1 kHz step (sensors, cascaded servo, rich drive train, MuJoCo) on a moving
trajectory, on the realistic plant (the default: friction shape, load, temperature, cogging,
late currents) and on the ideal one, interleaved in rounds so that the machine's load hits both
alike; and times a bare ``mujoco.mj_step`` of the same model and one ``pin.rnea`` call, so the
figures can be compared as ratios on a noisy machine.

    python benchmarks/sim_speed.py [--robot er20] [--seconds 20] [--rounds 3]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
import pinocchio as pin

from leadthrough.robot import Robot, load_robot
from leadthrough.sim import PLANT_NAMES, SimConfig, SimRobot


def _per_call(fn, calls: int) -> float:
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls


def _trajectory(robot: Robot, seconds: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(int(seconds / dt)) * dt
    mid = 0.5 * (robot.lower_limits + robot.upper_limits)
    amp = 0.2 * (robot.upper_limits - robot.lower_limits) / 2
    q_cmd = mid + amp * np.sin(2 * np.pi * 0.2 * t)[:, None]
    qd_cmd = amp * 2 * np.pi * 0.2 * np.cos(2 * np.pi * 0.2 * t)[:, None]
    return q_cmd, qd_cmd


def _step_time(sim: SimRobot, q_cmd: np.ndarray, qd_cmd: np.ndarray) -> float:
    """Wall time of one full step [s], over the trajectory."""
    sim.reset(q_cmd[0])
    t0 = time.perf_counter()
    for k in range(q_cmd.shape[0]):
        sim.command(q_cmd[k], qd_cmd[k])
        sim.step()
    return (time.perf_counter() - t0) / q_cmd.shape[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="er20")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated time [s]")
    parser.add_argument("--rounds", type=int, default=3,
                        help="interleaved runs per plant (the fastest counts)")
    args = parser.parse_args()

    robot = load_robot(args.robot)
    sims = {plant: SimRobot(robot, SimConfig(seed=0, plant=plant)) for plant in PLANT_NAMES}
    dt = sims[PLANT_NAMES[0]].config.timestep
    q_cmd, qd_cmd = _trajectory(robot, args.seconds, dt)
    best = dict.fromkeys(PLANT_NAMES, float("inf"))
    for _ in range(args.rounds):
        for plant in PLANT_NAMES:
            best[plant] = min(best[plant], _step_time(sims[plant], q_cmd, qd_cmd))

    sim = sims[PLANT_NAMES[0]]
    bare = mujoco.MjData(sim.mj_model)
    bare.qpos[:] = q_cmd[0]
    mj_s = _per_call(lambda: mujoco.mj_step(sim.mj_model, bare), 20000)
    data = robot.model.createData()
    q, v, a = q_cmd[0], qd_cmd[0], np.zeros(robot.n)
    rnea_s = _per_call(lambda: pin.rnea(robot.model, data, q, v, a), 20000)

    print(f"robot: {robot.name}, {args.seconds:g} s simulated at {1 / dt:.0f} Hz, fastest of "
          f"{args.rounds} interleaved runs per plant")
    for plant, step_s in best.items():
        print(f"{plant:<9} real-time factor {dt / step_s:8.1f} x  (goal >= 20 x), full step "
              f"{1e6 * step_s:7.1f} us = {step_s / mj_s:5.1f} x mj_step")
    ratio = best["realistic"] / best["ideal"]
    print(f"realistic / ideal step time: {ratio:.2f}")
    print(f"bare mujoco.mj_step   : {1e6 * mj_s:8.1f} us")
    print(f"one pin.rnea call     : {1e6 * rnea_s:8.2f} us")


if __name__ == "__main__":
    main()
