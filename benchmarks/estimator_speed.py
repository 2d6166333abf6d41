"""Step time of the real-time external force estimator (one 1 kHz sample), median and p99,
and as a multiple of one pin.rnea call measured in the same run.

    python benchmarks/estimator_speed.py [--steps 20000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.robot import load_robot
from leadthrough.session.loop_config import LoopConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    args = parser.parse_args()
    robot = load_robot("er20")
    params = nominal_drive_parameters(robot)
    rng = np.random.default_rng(0)
    q = 0.5 * (robot.lower_limits + robot.upper_limits) + 0.1 * rng.normal(size=robot.n)
    data = robot.model.createData()
    z = np.zeros(robot.n)
    t0 = time.perf_counter()
    for _ in range(args.steps):
        pin.rnea(robot.model, data, q, z, z)
    rnea = (time.perf_counter() - t0) / args.steps
    print(f"one pin.rnea call: {1e6 * rnea:.2f} us")
    configs = {f"{m}/{a}": EstimatorConfig(method=m, axes=a)
               for m in ("direct", "momentum") for a in ("wrench", "force")}
    # what guiding sessions run: the force fit, commanded-velocity friction with memory and
    # the friction-uncertainty weights (the guiding loop's estimator)
    configs["guiding"] = LoopConfig().estimator
    for label, cfg in configs.items():
        est = ExternalForceEstimator(robot, params, np.zeros(robot.n), cfg,
                                     noise_std=np.ones(robot.n))
        inp, out = est.make_input(), est.make_output()
        est.reset(q)
        est.warm_up()
        times = np.empty(args.steps)
        for k in range(args.steps):
            inp.t = k * 1e-3
            inp.q[:] = q + 1e-3 * np.sin(1e-3 * k)
            inp.current[:] = 0.1
            inp.qd_cmd[:] = 1e-3 * np.cos(1e-3 * k)
            s = time.perf_counter()
            est.update(inp, out)
            times[k] = time.perf_counter() - s
        med, p99 = np.median(times), np.percentile(times, 99)
        print(f"{label:>15}: median {1e6 * med:6.1f} us, p99 {1e6 * p99:6.1f} us "
              f"({med / rnea:.0f}× / {p99 / rnea:.0f}× pin.rnea)   goal p99 <= 20 us")


if __name__ == "__main__":
    main()
