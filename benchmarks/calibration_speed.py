"""Runtime of each calibration method on 60 s of data at 1 kHz with 6 joints (er20).

Pre-processing is included (it is part of each method's runtime). Also reports the time of the
regressor evaluation alone and ratios in the same run, because the machine is noisy.

    python benchmarks/calibration_speed.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import time

from leadthrough.data.preprocess import preprocess
from leadthrough.excitation.design import ExcitationConfig, design_excitation
from leadthrough.identification.api import METHODS, IdentifyConfig, identify
from leadthrough.identification.observations import build_observations
from leadthrough.robot import load_robot
from leadthrough.sim.calibration_set import record_excitation
from leadthrough.sim.plant import PLANT_NAMES
from leadthrough.sim.robot import SimConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--plant", choices=PLANT_NAMES, default=PLANT_NAMES[0],
                        help="simulated plant (default realistic; ideal: the plant before "
                             "issue 24)")
    args = parser.parse_args()
    robot = load_robot("er20")
    exc = design_excitation(robot, ExcitationConfig(starts=1, seed=0))
    rec = record_excitation(robot, exc, args.seconds, SimConfig(seed=1, plant=args.plant)).measured
    print(f"data: {args.seconds:g} s at 1 kHz, {robot.n} joints ({rec.samples} samples)")
    t0 = time.perf_counter()
    data = preprocess(rec, robot)
    t_pre = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_observations(robot, data)
    t_obs = time.perf_counter() - t0
    print(f"pre-processing        : {t_pre:7.2f} s")
    print(f"regressors            : {t_obs:7.2f} s ({data.samples} samples after decimation)")
    times = {}
    for m in METHODS:
        # eq. 21 as the paper writes it (no load term): the README's figures
        res = identify(rec, robot, m, IdentifyConfig(load_friction=False))
        times[m] = res.runtime_s
        print(f"{m:<22}: {res.runtime_s:7.2f} s  (J = {res.J:.2f}, {res.iterations} it.)")
    print(f"proposed / ols-cv     : {times['proposed'] / times['ols-cv']:7.1f} x")
    print(f"consistent / proposed : {times['consistent'] / times['proposed']:7.3f}"
          "   (goal <= 0.2)")
    print("goal: proposed <= 60 s")


if __name__ == "__main__":
    main()
