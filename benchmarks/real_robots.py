"""All four calibration methods on the real robots in ../shared/data (issue: consistent method).

* UR10e (Mamedov et al.): identify on ur-20_02_10-30sec_12harm, validate on ptp_10_points and
  two other excitation runs. Current × the UR controller's own drive gain = joint torque.
* KUKA KR300 R2500 ultra (Weigand et al.): identify on run A, validate on B and C. Motor torque
  × gear ratio = joint torque; the authors' hydraulic-counterbalance model is subtracted from
  joint 2 (it is not part of eq. 21); positions are the motor encoders scaled to the link (the
  only ones logged on all six axes).

For each robot one table: J and relative torque error ‖e‖/‖τ‖ on every run, per-joint RMS error
on the first validation run, and the smallest pseudo-inertia eigenvalue of each link (negative:
not a physical body).

    python benchmarks/real_robots.py [--out real-results]
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from leadthrough.data.io import load_recording
from leadthrough.data.recording import Recording
from leadthrough.errors import DataWarning
from leadthrough.identification.api import METHODS, IdentifyConfig, evaluate, identify
from leadthrough.robot import Robot, load_robot

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
sys.path.insert(0, str(ROOT / "examples" / "real" / "kr300"))
from hydraulics import without_counterbalance  # noqa: E402


def ur10e_logs() -> tuple[Robot, str, Recording, dict[str, Recording]]:
    """The UR10e: robot, identification run's label, the run, and the held-out runs."""
    folder = ROOT / "examples" / "real" / "ur10e"
    cmap = folder / "columns.toml"
    d = DATA / "ur10e"
    ident = load_recording(d / "identification/ur-20_02_10-30sec_12harm.csv", cmap)
    held = {p: load_recording(d / f"{p}.csv", cmap) for p in (
        "validation/ur-20_01_17-ptp_10_points", "identification/ur-20_02_12-40sec_12harm",
        "identification/ur-20_02_12-50sec_12harm")}
    return load_robot(folder / "robot.toml"), "30sec_12harm", ident, \
        {Path(k).name.replace("ur-20_", ""): v for k, v in held.items()}


def kr300_logs() -> tuple[Robot, str, Recording, dict[str, Recording]]:
    """The KR300 (A2's counterbalance removed): as :func:`ur10e_logs`."""
    folder = ROOT / "examples" / "real" / "kr300"
    d = DATA / "kr300"

    def load(name: str) -> Recording:
        return without_counterbalance(load_recording(d / name, folder / "columns.toml"),
                                      d / "facts.toml")

    return load_robot(folder / "robot.toml"), "A", load("FF_A_identification.mat"), \
        {"B": load("FF_B_validation.mat"), "C": load("FF_C_validation.mat")}


def run_robot(robot: Robot, id_label: str, ident: Recording, held: dict[str, Recording]
              ) -> dict:
    # eq. 21 as the paper writes it (no load term): the README's figures
    cfg = IdentifyConfig(load_friction=False)
    rows = {}
    for m in METHODS:
        res = identify(ident, robot, m, cfg)
        val = {k: evaluate(res.params, robot, v, cfg) for k, v in held.items()}
        first = next(iter(val.values()))
        rows[m] = {"J": res.J, "rel_id": res.stats.rel_error_pct,
                   "J_val": {k: s.J for k, s in val.items()},
                   "rel_val": {k: s.rel_error_pct for k, s in val.items()},
                   "rms_first_val": first.rms.tolist(),
                   "min_pseudo_inertia_eig": res.min_pseudo_inertia_eig.tolist(),
                   "runtime_s": res.runtime_s}
    labels = list(held)
    head = (f"| method | J ({id_label}) | rel. error ({id_label}) | "
            + " | ".join(f"rel. error ({k})" for k in labels)
            + f" | RMS per joint on {labels[0]} [N·m] | min pseudo-inertia eig per link "
              "[kg·m²] | runtime [s] |")
    lines = [head, "|" + "---|" * (len(labels) + 6)]
    for m, r in rows.items():
        lines.append(
            f"| {m} | {r['J']:.2f} | {r['rel_id']:.2f} % | "
            + " | ".join(f"{r['rel_val'][k]:.2f} %" for k in labels)
            + " | " + ", ".join(f"{v:.2f}" for v in r["rms_first_val"])
            + " | " + ", ".join(f"{v:.2g}" for v in r["min_pseudo_inertia_eig"])
            + f" | {r['runtime_s']:.1f} |")
    table = "\n".join(lines)
    ratio = {k: rows["consistent"]["rel_val"][k] / rows["ols-cv"]["rel_val"][k] for k in labels}
    return {"table": table, "rows": rows, "consistent_over_ols_cv": ratio}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("real-results"))
    args = parser.parse_args()
    if not DATA.is_dir():
        print(f"{DATA} not found: the real-robot logs are not shipped with the package")
        return
    args.out.mkdir(parents=True, exist_ok=True)
    results = {}
    md = ["# Calibration on real robots", ""]
    for name, loader in (("UR10e", ur10e_logs), ("KR300", kr300_logs)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            robot, label, ident, held = loader()
        res = run_robot(robot, label, ident, held)
        results[name] = res
        ratio = ", ".join(f"{k}: {v:.2f}" for k, v in res["consistent_over_ols_cv"].items())
        print(f"\n{name}\n{res['table']}\n"
              f"held-out relative error, consistent / ols-cv: {ratio} (goal <= 0.95)")
        md += [f"## {name}", "", res["table"], "",
               f"consistent / ols-cv relative error held out: {ratio}", ""]
    (args.out / "real_robots.json").write_text(json.dumps(results, indent=2,
                                                          default=np.asarray(0).tolist))
    (args.out / "real_robots.md").write_text("\n".join(md))
    print(f"\nwritten to {args.out}/")


if __name__ == "__main__":
    main()
