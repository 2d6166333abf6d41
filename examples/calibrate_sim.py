"""Workflow 1: calibrate the simulated robot (paper Section III-A).

Design an excitation trajectory, record it on the simulated er20, identify the model with the
least-squares baseline [7] and our consistent method (``--method proposed`` in the CLI runs the
paper's, slower), and check both on a held-out recording. Then record a friction sweep (slow
constant-velocity passes, the friction that guiding lives on) and write the guiding parameters:
``consistent`` with its friction from the sweep.

    python examples/calibrate_sim.py [--seconds 20] [--out params.toml]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import evaluate, identify, identify_with_sweep
from leadthrough.identification.params_file import save_params
from leadthrough.robot import load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import record_calibration_set, record_friction_sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=20.0, help="recording length [s]")
    parser.add_argument("--out", type=Path, default=Path("params.toml"))
    args = parser.parse_args()
    robot = load_robot("er20")
    cal = record_calibration_set(robot, seed=1, duration=args.seconds,
                                 excitation_config=ExcitationConfig(starts=1))
    print(f"excitation condition number {cal.excitation.condition_number:.1f}")
    for method in ("ols-cv", "consistent"):
        res = identify(cal.identification.measured, robot, method)
        held = evaluate(res.params, robot, cal.held_out.measured)
        print(f"{method:<10} J identification {res.J:6.2f}, held out {held.J:6.2f} N·m "
              f"({res.runtime_s:.1f} s)")
    sweep = record_friction_sweep(robot, seed=1, run=2, q_start=guide_start_pose(robot))
    guided = identify_with_sweep(cal.identification.measured, sweep.measured, robot)
    held = evaluate(guided.result.params, robot, cal.held_out.measured)
    print(f"consistent + friction sweep ({sweep.measured.duration:.0f} s): J identification "
          f"{guided.result.J:6.2f}, held out {held.J:6.2f} N·m; sweep fit RMS "
          + ", ".join(f"{v:.2f}" for v in guided.sweep.rms) + " N·m")
    save_params(args.out, robot, "consistent", guided.result.params, guided.result.stats,
                friction_sweep=True)
    print(f"-> {args.out} (guiding parameters)")


if __name__ == "__main__":
    main()
