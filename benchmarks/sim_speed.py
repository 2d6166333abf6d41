"""Simulation speed of the simulated robot, as a multiple of real time.

Runs the full 1 kHz step (sensors, cascaded servo, rich drive train, MuJoCo) on a moving
trajectory, and in the same run times a bare ``mujoco.mj_step`` of the same model and one
``pin.rnea`` call, so the figures can be compared as ratios on a noisy machine.

    python benchmarks/sim_speed.py [--robot er20] [--seconds 20]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
import pinocchio as pin

from leadthrough.robot import load_robot
from leadthrough.sim import SimConfig, SimRobot


def _per_call(fn, calls: int) -> float:
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="er20")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated time [s]")
    args = parser.parse_args()

    robot = load_robot(args.robot)
    sim = SimRobot(robot, SimConfig(seed=0))
    dt = sim.config.timestep
    steps = int(args.seconds / dt)
    t = np.arange(steps) * dt
    mid = 0.5 * (robot.lower_limits + robot.upper_limits)
    amp = 0.2 * (robot.upper_limits - robot.lower_limits) / 2
    q_cmd = mid + amp * np.sin(2 * np.pi * 0.2 * t)[:, None]
    qd_cmd = amp * 2 * np.pi * 0.2 * np.cos(2 * np.pi * 0.2 * t)[:, None]
    sim.reset(q_cmd[0])

    t0 = time.perf_counter()
    for k in range(steps):
        sim.command(q_cmd[k], qd_cmd[k])
        sim.step()
    wall = time.perf_counter() - t0
    step_s = wall / steps

    bare = mujoco.MjData(sim.mj_model)
    bare.qpos[:] = q_cmd[0]
    mj_s = _per_call(lambda: mujoco.mj_step(sim.mj_model, bare), 20000)
    data = robot.model.createData()
    q, v, a = q_cmd[0], qd_cmd[0], np.zeros(robot.n)
    rnea_s = _per_call(lambda: pin.rnea(robot.model, data, q, v, a), 20000)

    print(f"robot: {robot.name}, {args.seconds:g} s simulated at {1 / dt:.0f} Hz")
    print(f"real-time factor      : {args.seconds / wall:8.1f} x  (goal >= 20 x)")
    print(f"full step             : {1e6 * step_s:8.1f} us")
    print(f"bare mujoco.mj_step   : {1e6 * mj_s:8.1f} us   (full step = {step_s / mj_s:.1f} x)")
    print(f"one pin.rnea call     : {1e6 * rnea_s:8.2f} us   (full step = {step_s / rnea_s:.0f} x)")


if __name__ == "__main__":
    main()
