"""``leadthrough record --driver D --host H [--port P]``: a trajectory run on a robot controller
(issue 25), logged in the same recording format as the simulator's (see
:mod:`leadthrough.session.trajectory_recording`)."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from leadthrough.data.io import save_recording
from leadthrough.drivers.controllers import CONTROLLERS, connect
from leadthrough.errors import ControlError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.progress import Progress
from leadthrough.robot.description import Robot
from leadthrough.session.trajectory_recording import TrajectoryRunConfig, record_trajectory

__all__ = ["add_driver_arguments", "record_on_robot"]

_SIM_ONLY = ("seed", "run", "payload_mass", "payload_com")


def add_driver_arguments(p: argparse.ArgumentParser) -> None:
    """``--driver``, ``--host``, ``--port`` and ``--approach``."""
    g = p.add_argument_group("on a robot controller")
    g.add_argument("--driver", default=None, choices=sorted(CONTROLLERS),
                   help="the controller's interface (default: the simulated robot)")
    g.add_argument("--host", default=None,
                   help="the controller's address (kuka-rsi: this PC's address to listen on)")
    g.add_argument("--port", type=int, default=None,
                   help="the interface's port (default: its own: 60015, 30004, 49152)")
    g.add_argument("--approach", type=float, default=0.1, metavar="F",
                   help="share of the joint speed and acceleration limits for the move to the "
                        "trajectory's start (0: the robot must already be there; default 0.1)")


def record_on_robot(args: argparse.Namespace, robot: Robot, traj: TrajectorySamples) -> int:
    """Run ``traj`` on the controller of ``args.driver`` and write the recording."""
    for name in _SIM_ONLY:
        if getattr(args, name) is not None:
            raise ControlError("a simulator setting given for a robot",
                               field=f"--{name.replace('_', '-')}", value=getattr(args, name),
                               expected="no simulator settings with --driver")
    config = TrajectoryRunConfig(approach_fraction=args.approach)
    driver = connect(args.driver, robot, args.host, args.port)
    bar = Progress("recording", 1)
    with driver:
        done = record_trajectory(driver, robot, traj, config, progress=bar)
    bar.close()
    save_recording(done.recording, args.output)
    rec = done.recording
    out: dict[str, Any] = {
        "robot": robot.name, "driver": args.driver, "samples": rec.samples,
        "duration_s": rec.duration, "cycle_s": driver.dt, "approach_s": done.approach_s,
        "stale_cycles": done.stale, "signal": "current" if rec.current is not None else "torque",
        "max_following_error_rad": done.max_following_error, "output": str(args.output)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"recorded {rec.duration:.1f} s ({rec.samples} samples at "
              f"{1e3 * driver.dt:g} ms, {done.stale} cycles stale, following error "
              f"<= {np.degrees(done.max_following_error):.3f}°) to {args.output}")
    return 0
