"""Table III: payload weight from motion with the unloaded robot's identified model (simulated
er20), plus the real UR10e payload pair.

    python benchmarks/table3.py [--seconds 240] [--quick] [--seed 1] [--plant realistic|ideal]

Parameters come from calibration on the unloaded simulated robot (--seed, default 1; 60 s),
never from the simulator's truth. Each payload is recorded on its own run of the held-out
trajectory. Every payload is estimated twice per parameter set: as the paper does, from the
unloaded model alone, and against a run of the same trajectory without a payload ("vs
unloaded": ``estimate_payload``'s ``reference``, which cancels the model's own error along the
path). The real UR10e's pair is such a pair of runs, so it is estimated both ways too.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from leadthrough.data.io import load_recording
from leadthrough.demo.guiding_steps import PAPER_WEIGHTS_N, PAYLOAD_RUN_S, payload_table
from leadthrough.errors import DataWarning
from leadthrough.estimation.payload import estimate_payload
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import IdentifyConfig, identify
from leadthrough.robot import load_robot
from leadthrough.sim.calibration_set import record_calibration_set
from leadthrough.sim.plant import PLANT_NAMES

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=PAYLOAD_RUN_S,
                        help="payload run length [s]")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=1, help="simulated robot instance")
    parser.add_argument("--plant", choices=PLANT_NAMES, default=PLANT_NAMES[0],
                        help="simulated plant (default realistic; ideal: the plant before "
                             "issue 24)")
    parser.add_argument("--load-friction", action="store_true",
                        help="identify the load-dependent Coulomb friction too (identify's "
                             "default; without it eq. 21 as the paper writes it)")
    args = parser.parse_args()
    robot = load_robot("er20")
    cal = record_calibration_set(robot, seed=args.seed, duration=20.0 if args.quick else 60.0,
                                 excitation_config=ExcitationConfig(starts=1 if args.quick else 4),
                                 plant=args.plant)
    # eq. 21 as the paper writes it (no load term) unless asked: the README's figures
    cfg = IdentifyConfig(load_friction=args.load_friction)
    models = {m: identify(cal.identification.measured, robot, m, cfg)
              for m in ("proposed", "consistent")}
    print(f"\nTable III (simulated er20 seed {args.seed}, {args.plant} plant, load friction "
          f"{'on' if args.load_friction else 'off'}): weight [N] from motion, payload CoM 0.1 m "
          "along the flange axis")
    print(f"{'true [N]':>9} | " + " | ".join(f"{m:>22}" for m in models)
          + " | " + " | ".join(f"{m + ' vs unloaded':>22}" for m in models))
    table = payload_table(robot, cal, {m: r.params for m, r in models.items()}, seed=args.seed,
                          seconds=args.seconds, plant=args.plant, reference=True)
    for k, weight in enumerate(PAPER_WEIGHTS_N):
        cells = [f"{rows[k].estimated_n:8.2f} ({rows[k].error_pct:+5.2f} %)"
                 for rows in table.values()]
        print(f"{weight:9.2f} | " + " | ".join(f"{c:>22}" for c in cells))
    worst = {m: max(abs(r.error_pct) for r in rows) for m, rows in table.items()}
    print("worst |error|: " + ", ".join(f"{m} {v:.2f} %" for m, v in worst.items())
          + "   (goal <= 1 %; paper: up to 7.84 N, 5.6 %)")

    d = ROOT.parent / "shared" / "data" / "ur10e" / "identification"
    if d.is_dir():
        robot_ur = load_robot(ROOT / "examples" / "real" / "ur10e" / "robot.toml")
        cmap = ROOT / "examples" / "real" / "ur10e" / "columns.toml"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            unloaded = load_recording(d / "ur-20_02_19_14harm50sec.csv", cmap)
            loaded = load_recording(d / "ur-20_02_19_14harm50secLoad.csv", cmap)
        print("\nReal UR10e: identified on the no-load run, payload from the Load run "
              "(true 2.805 kg)")
        for m in ("ols-cv", "proposed", "consistent"):
            res = identify(unloaded, robot_ur, m, cfg)
            est = estimate_payload(loaded, robot_ur, res.params, "motion")
            ref = estimate_payload(loaded, robot_ur, res.params, "motion", reference=unloaded)
            print(f"  {m:<10} {est.mass_kg:.3f} kg ({100 * (est.mass_kg - 2.805) / 2.805:+.1f} %)"
                  f";  vs the unloaded run {ref.mass_kg:.3f} kg "
                  f"({100 * (ref.mass_kg - 2.805) / 2.805:+.1f} %)")


if __name__ == "__main__":
    main()
