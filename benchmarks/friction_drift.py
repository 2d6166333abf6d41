"""Friction that drifts: parameters identified on the cold robot, used on a warm one, with and
without the friction check (issue 24, "friction that drifts").

Per robot instance (seed) on the realistic plant: calibrate cold (excitation + friction sweep,
``identify_with_sweep``); warm the robot up by ``--warm-up`` minutes of production-like motion
(the plant's thermal model: friction falls as the joints heat); record a friction check
(``FRICTION_CHECK``, 13 s) and refresh the friction (:func:`refresh_friction`). The reference is
a full friction sweep on the robot at the same temperature (the friction points, no model). It
prints, per joint, the largest relative error of the model's friction over the reference's
points at guiding speeds (0.02–0.3 rad/s): cold parameters on the cold robot (the calibration's
own error), cold parameters on the warm robot (the drift), refreshed parameters on the warm
robot (after the check), and the check's scales.

    python benchmarks/friction_drift.py [--seeds 3 4 5] [--warm-up 60]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import stribeck_friction
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.excitation.friction_sweep import FRICTION_CHECK
from leadthrough.identification.api import identify_with_sweep
from leadthrough.identification.friction_refresh import refresh_friction
from leadthrough.identification.friction_sweep import SweepPoints, sweep_points
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import record_calibration_set, record_friction_sweep

GUIDING = (0.02, 0.3)


def _error(robot: Robot, p: DriveModelParameters, ref: SweepPoints) -> NDArray[np.float64]:
    """Largest |model / measured − 1| per joint over the reference points at guiding speeds."""
    assert p.stribeck is not None
    out = np.zeros(robot.n)
    for j in range(robot.n):
        v, f = ref.speed[j], ref.friction[j]
        sel = (v >= GUIDING[0]) & (v <= GUIDING[1])
        qd = np.zeros((int(sel.sum()), robot.n))
        qd[:, j] = v[sel]
        model = stribeck_friction(qd, robot.gear_ratio, p.stribeck)[:, j]
        out[j] = float(np.max(np.abs(model / f[sel] - 1.0)))
    return out


def _row(label: str, x: NDArray[np.float64], pct: bool = True) -> str:
    cells = " ".join(f"{100 * v:6.1f}" if pct else f"{v:6.3f}" for v in x)
    return f"  {label:<34} {cells}"


def run_seed(robot: Robot, seed: int, warm_s: float) -> NDArray[np.float64]:
    """Print one robot instance's table; returns [cold/cold, cold/warm, refreshed/warm] maxima."""
    t0 = time.perf_counter()
    q0 = guide_start_pose(robot)
    cal = record_calibration_set(robot, seed=seed, duration=30.0,
                                 excitation_config=ExcitationConfig(starts=1, max_iterations=60))
    sweep = record_friction_sweep(robot, seed=seed, run=2, q_start=q0)
    cold = identify_with_sweep(cal.identification.measured, sweep.measured, robot).result.params
    ref_cold = sweep_points(record_friction_sweep(robot, seed=seed, run=6, q_start=q0).measured,
                            robot)
    ref_warm = sweep_points(record_friction_sweep(robot, seed=seed, run=6, q_start=q0,
                                                  warm_up_s=warm_s).measured, robot)
    check = record_friction_sweep(robot, seed=seed, run=5, q_start=q0,
                                  sweep_config=FRICTION_CHECK, warm_up_s=warm_s)
    done = refresh_friction(cold, check.measured, robot)
    rows = np.array([_error(robot, cold, ref_cold), _error(robot, cold, ref_warm),
                     _error(robot, done.params, ref_warm)])
    print(f"seed {seed} ({time.perf_counter() - t0:.0f} s); friction error at "
          f"{GUIDING[0]}-{GUIDING[1]} rad/s [%] per joint:")
    print(_row("cold params, cold robot", rows[0]))
    print(_row(f"cold params, after {warm_s / 60:g} min", rows[1]))
    print(_row("after the friction check", rows[2]))
    print(_row("check's level scale", done.level_scale, pct=False))
    print(_row("check's viscous scale", done.viscous_scale, pct=False))
    return rows.max(axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 4, 5])
    ap.add_argument("--warm-up", type=float, default=60.0, help="minutes")
    ap.add_argument("--robot", default="er20")
    args = ap.parse_args()
    robot = load_robot(args.robot)
    worst = np.array([run_seed(robot, s, 60.0 * args.warm_up) for s in args.seeds])
    print(f"over seeds {args.seeds}, worst joint [%]: cold params on the cold robot "
          f"{100 * worst[:, 0].max():.1f}, on the warm robot {100 * worst[:, 1].max():.1f}, "
          f"after the check {100 * worst[:, 2].max():.1f}")


if __name__ == "__main__":
    main()
