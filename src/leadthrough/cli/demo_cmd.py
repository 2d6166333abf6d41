"""``leadthrough demo``: the main job on the built-in simulated robot.

It grows with the pipeline. Today it runs, on the simulated ER20-class robot with a fixed seed:
1. the dynamic model: base parameters and K·φ against Pinocchio RNEA and MuJoCo;
2. the simulated robot holding a pose under gravity (joint error, currents vs gravity torque);
3. a 50 N push at the TCP (current change vs −J^T·F/(R·Kt));
4. the simulation speed as a multiple of real time.
Figures are printed and, with ``--out``, written to ``summary.json`` in that folder.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.fileio import atomic_write_text
from leadthrough.robot.description import load_robot
from leadthrough.sim.checks import check_hold, check_push, check_regressor
from leadthrough.sim.robot import SimConfig, SimRobot

__all__ = ["register", "run"]

DEMO_POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "demo",
        help="run the pipeline on the built-in simulated robot",
        description=__doc__,
        epilog="example: leadthrough demo --out ./leadthrough-report",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", default="er20", help="robot (default: er20)")
    p.add_argument("--seed", type=int, default=1, help="simulator seed (default: 1)")
    p.add_argument("--out", type=Path, default=None, help="folder for summary.json")
    p.add_argument("--quick", action="store_true", help="fewer samples, shorter runs")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _sim_speed(sim: SimRobot, seconds: float) -> float:
    steps = int(seconds / sim.config.timestep)
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    return seconds / (time.perf_counter() - t0)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough demo``."""
    robot = load_robot(args.robot)
    config = SimConfig(seed=args.seed)
    samples = 200 if args.quick else 1000
    q0 = np.clip(np.resize(np.array(DEMO_POSE), robot.n), robot.lower_limits, robot.upper_limits)
    say = (lambda s: None) if args.json else print
    say(f"leadthrough demo on '{robot.name}' (seed {args.seed})")
    say("[1/4] dynamic model ...")
    reg = check_regressor(robot, samples=samples, seed=args.seed)
    say(f"      base parameters: {reg.base_parameters} of {10 * robot.n}; K·φ vs pin.rnea "
        f"{reg.rel_error_rnea:.1e}, vs MuJoCo {reg.rel_error_mujoco:.1e}, "
        f"Y_base·β vs K·φ {reg.rel_error_base:.1e} (relative)")
    say("[2/4] simulated robot holds a pose under gravity ...")
    h = check_hold(robot, config, q0, duration=1.0 if args.quick else 2.0)
    say(f"      max joint error {1e3 * h.max_joint_error.max():.2e} mrad; "
        f"current vs gravity torque: max {h.error_in_sigma.max():.2f} σ of the sensor noise")
    say("[3/4] 50 N push at the TCP ...")
    push = check_push(robot, config, q0, np.array([50.0, 0, 0, 0, 0, 0]))
    say(f"      current change vs -J^T·F/(R·Kt): max {push.error_in_sigma.max():.2f} σ; "
        f"max deflection {1e3 * push.max_deflection:.3f} mrad")
    say("[4/4] simulation speed ...")
    speed = _sim_speed(SimRobot(robot, config, q0=q0), 2.0 if args.quick else 5.0)
    say(f"      {speed:.1f}× real time at {1.0 / config.timestep:.0f} Hz")
    summary = {
        "robot": robot.name,
        "seed": args.seed,
        "base_parameters": reg.base_parameters,
        "regressor_rel_error": {"rnea": reg.rel_error_rnea, "mujoco": reg.rel_error_mujoco,
                                "base": reg.rel_error_base},
        "hold": {"max_joint_error_rad": float(h.max_joint_error.max()),
                 "current_error_sigma": h.error_in_sigma.tolist()},
        "push_50N_x": {"current_error_sigma": push.error_in_sigma.tolist(),
                       "max_deflection_rad": push.max_deflection},
        "sim_speed_x_realtime": speed,
    }
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        path = atomic_write_text(args.out / "summary.json", json.dumps(summary, indent=2))
        say(f"summary written to {path}")
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0
