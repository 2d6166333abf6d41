"""Round trip of the robot program languages on random poses: the largest joint error per robot
and language, and the time per pose.

For each built-in 6-axis robot, N random joint configurations within the limits (every branch the
limits allow, 10° from the wrist singularity; see :mod:`leadthrough.teach.programs.round_trip`)
are written as a program (linear moves to poses with configuration data, or joint moves), read
back with the language's parser and solved back with our inverse kinematics. The Panda (7 axes)
has joint programs only.

Usage::

    python benchmarks/program_round_trip.py [--poses 50] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from leadthrough.robot import load_robot
from leadthrough.teach.programs import LANGUAGES
from leadthrough.teach.programs.round_trip import round_trip_errors, sample_configurations


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"{'robot':6s} {'language':9s} {'moves':6s} {'max joint error':>16s} "
          f"{'ms/pose':>8s}")
    rng = np.random.default_rng(args.seed)
    for name in ("er20", "ur5", "ur10", "panda"):
        robot = load_robot(name)
        if robot.n == 6:
            qs = sample_configurations(robot, args.poses, args.seed)
        else:
            qs = rng.uniform(robot.lower_limits, robot.upper_limits, (args.poses, robot.n))
        for language in LANGUAGES:
            for joint_space in (False, True):
                if robot.n != 6 and (not joint_space or language == "urscript"):
                    continue
                t0 = time.perf_counter()
                err = round_trip_errors(robot, language, qs, joint_space=joint_space)
                ms = 1e3 * (time.perf_counter() - t0) / len(qs)
                print(f"{name:6s} {language:9s} {'joints' if joint_space else 'poses':6s} "
                      f"{err.max():13.2e} deg {ms:8.1f}")


if __name__ == "__main__":
    main()
