"""``leadthrough demo``: the main job on the built-in simulated robot.

It grows with the pipeline. Today it runs, on the simulated ER20-class robot with a fixed seed:
1. the dynamic model: base parameters and K·φ against Pinocchio RNEA and MuJoCo;
2. the simulated robot holding a pose and feeling a 50 N push (currents vs the drive model);
3. the excitation trajectory design (identification and held-out);
4. both recordings at 1 kHz;
5. calibration with all three methods, Table II with the noise floor, and Fig. 3.
It prints a summary and writes a report folder (default ./leadthrough-report): summary.json,
table2.md, params.toml (the paper's method), the recordings and fig3.png.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.data.io import save_recording
from leadthrough.data.preprocess import preprocess
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.fileio import atomic_write_text
from leadthrough.identification.api import METHODS, IdentifyConfig
from leadthrough.identification.comparison import format_table2, ratio_summary
from leadthrough.identification.params_file import save_params
from leadthrough.identification.plots import plot_torque_fit
from leadthrough.identification.proposed import ProposedConfig
from leadthrough.robot.description import load_robot
from leadthrough.sim.calibration_set import compare_on_calibration_set, record_calibration_set
from leadthrough.sim.checks import check_hold, check_push, check_regressor
from leadthrough.sim.robot import SimConfig

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
    p.add_argument("--seed", type=int, default=1, help="simulated robot instance (default: 1)")
    p.add_argument("--out", type=Path, default=Path("leadthrough-report"),
                   help="report folder (default: ./leadthrough-report)")
    p.add_argument("--quick", action="store_true", help="shorter recordings and searches")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough demo``."""
    t_start = time.perf_counter()
    robot = load_robot(args.robot)
    config = SimConfig(seed=args.seed)
    quick = bool(args.quick)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    q0 = np.clip(np.resize(np.array(DEMO_POSE), robot.n), robot.lower_limits, robot.upper_limits)
    say = (lambda s: None) if args.json else (lambda s: print(s, flush=True))
    say(f"leadthrough demo on '{robot.name}' (seed {args.seed}{', quick' if quick else ''})")

    say("[1/5] dynamic model ...")
    reg = check_regressor(robot, samples=200 if quick else 1000, seed=args.seed)
    say(f"      base parameters: {reg.base_parameters} of {10 * robot.n}; K·φ vs pin.rnea "
        f"{reg.rel_error_rnea:.1e}, vs MuJoCo {reg.rel_error_mujoco:.1e}, "
        f"Y_base·β vs K·φ {reg.rel_error_base:.1e} (relative)")

    say("[2/5] simulated robot: hold a pose, then a 50 N push at the TCP ...")
    h = check_hold(robot, config, q0)
    push = check_push(robot, config, q0, np.array([50.0, 0, 0, 0, 0, 0]))
    say(f"      max joint error {1e3 * h.max_joint_error.max():.2e} mrad; currents vs gravity "
        f"{h.error_in_sigma.max():.2f} σ; push vs -J^T·F/(R·Kt) {push.error_in_sigma.max():.2f} σ"
        " (σ: current noise)")

    say("[3/5] excitation design and [4/5] recordings ...")
    duration = 20.0 if quick else 60.0
    exc_cfg = ExcitationConfig(starts=1 if quick else 2, seed=0,
                               max_iterations=60 if quick else 100)
    cal = record_calibration_set(robot, seed=args.seed, duration=duration,
                                 excitation_config=exc_cfg, progress=lambda s: say("      " + s))
    save_recording(cal.identification.measured, out / "identification.parquet")
    save_recording(cal.held_out.measured, out / "held_out.parquet")

    say("[5/5] calibration: " + ", ".join(METHODS) + " ...")
    cfg = IdentifyConfig(proposed=ProposedConfig(generations=60 if quick else 150,
                                                 polish_iterations=150 if quick else 300))
    result = compare_on_calibration_set(robot, cal, METHODS, cfg,
                                        progress=lambda s: say("      " + s))
    comp, floors = result.comparison, result.floors
    table = format_table2(comp, floors)
    ratios = ratio_summary(comp, floors)
    best = comp.results["proposed"]
    save_params(out / "params.toml", robot, "proposed", best.params, best.stats)
    held = preprocess(cal.held_out.measured, robot, cfg.preprocess)
    plot_torque_fit(out / "fig3.png", robot, held, {m: comp.results[m].params for m in METHODS},
                    title=f"{robot.name} (simulated), held-out trajectory")
    atomic_write_text(out / "table2.md", "# Table II (simulated "
                      f"{robot.name}, seed {args.seed})\n\n{table}\n")
    say("\nTable II (mean [N·m], std/max torque [%], J [N·m]):\n" + table + "\n")
    for label, r in ratios.items():
        say(f"  {label}: J(proposed)/J(ols-cv) = {r['proposed/ols-cv']:.2f} (paper 0.77), "
            f"J(proposed)/noise floor = {r['proposed/floor']:.2f}")

    total = time.perf_counter() - t_start
    summary: dict[str, Any] = {
        "robot": robot.name, "seed": args.seed, "quick": quick,
        "base_parameters": reg.base_parameters,
        "regressor_rel_error": {"rnea": reg.rel_error_rnea, "mujoco": reg.rel_error_mujoco,
                                "base": reg.rel_error_base},
        "hold": {"max_joint_error_rad": float(h.max_joint_error.max()),
                 "current_error_sigma": h.error_in_sigma.tolist()},
        "push_50N_x": {"current_error_sigma": push.error_in_sigma.tolist(),
                       "max_deflection_rad": push.max_deflection},
        "excitation_condition_number": cal.excitation.condition_number,
        "table2": ratios,
        "runtime_s": {m: comp.results[m].runtime_s for m in METHODS},
        "total_s": total,
    }
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2))
    say(f"\nreport written to {out}/ ({total:.0f} s)")
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0
