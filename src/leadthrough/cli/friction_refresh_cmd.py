"""``leadthrough refresh-friction PARAMS CHECK -o NEW``: the identified friction rescaled to a
friction check (see :mod:`leadthrough.identification.friction_refresh`)."""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.cli.arg_checks import check_output
from leadthrough.data.io import load_recording
from leadthrough.identification.friction_refresh import refresh_friction, require_eq15
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import ParamsFile, load_params, save_params
from leadthrough.robot.description import Robot, load_robot

__all__ = ["register"]

_DESCRIPTION = """\
Gear friction falls as the robot warms up (tens of percent over the first hour of work, the
viscous part most): parameters identified on a cold robot overestimate it on a warm one, and the
other way round. Before guiding, run a friction check (about 15 s of slow out-and-back motion,
no one touching the robot):

  leadthrough excite --robot er20 --friction-check -o check.csv
  leadthrough record ... --trajectory check.csv -o check.parquet
  leadthrough refresh-friction params.toml check.parquet -o params_now.toml

Each joint's friction keeps its identified shape and gets two scales, one for the Coulomb,
Stribeck and load part and one for the viscous part, fitted to the check's friction points; the
links, rotor inertias, offsets and noise figures are kept. Scales outside [0.25, 4] are refused
(not a drift: the wrong params file or robot)."""


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser("refresh-friction", help="rescale the friction to a friction check",
                       description=_DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("params", type=Path, help="identified parameters (with a friction sweep)")
    p.add_argument("check", type=Path, help="recording of a friction check (or sweep)")
    p.add_argument("--robot", default="er20")
    p.add_argument("--columns", type=Path, default=None, help="column map of the recording")
    p.add_argument("-o", "--output", type=Path, required=True, help="refreshed params .toml")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def _k_omega(path: Path) -> float:
    """K_ω of a params file that :func:`load_params` has read (kept in the new file)."""
    meta = tomllib.loads(path.read_text(encoding="utf-8")).get("meta", {})
    value = meta.get("k_omega", 1.0)
    return float(value) if isinstance(value, int | float) else 1.0


def _stats(pf: ParamsFile, robot: Robot, k_omega: float) -> ResidualStats:
    """The params file's residual figures, as :func:`save_params` writes them."""
    n = robot.n
    return ResidualStats(mean=pf.noise_mean, std=pf.noise_std,
                         std_pct_max=100.0 * pf.noise_std / robot.max_torque, rms=pf.noise_std,
                         rel_error_pct=float("nan"), J=pf.J, k_omega=k_omega,
                         samples=np.zeros(n, dtype=np.int64))


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough refresh-friction``."""
    check_output(args.output, (".toml",), (("the params", args.params),
                                           ("the check recording", args.check),
                                           ("--columns", args.columns)))
    robot = load_robot(args.robot)
    pf = load_params(args.params, robot)
    require_eq15(pf.params, args.params)     # before the check recording is read
    check = load_recording(args.check, args.columns)
    check.check_joint_range(robot)
    done = refresh_friction(pf.params, check, robot)
    stats = _stats(pf, robot, _k_omega(args.params))
    save_params(args.output, robot, pf.method, done.params, stats, sim_seed=pf.sim_seed,
                friction_sweep=pf.friction_sweep)
    rows = [{"joint": name, "level_scale": float(a), "viscous_scale": float(b),
             "viscous_fitted": bool(s), "viscous_at_bound": bool(bound),
             "error_before": float(e0), "error_after": float(e1),
             "points": int(done.points.speed[j].size)}
            for j, (name, a, b, s, bound, e0, e1) in enumerate(zip(
                robot.joint_names, done.level_scale, done.viscous_scale, done.separable,
                done.viscous_at_bound, done.error_before, done.error_after, strict=True))]
    if args.json:
        print(json.dumps({"robot": robot.name, "joints": rows, "output": str(args.output)},
                         indent=2))
        return 0
    print("joint      level  viscous  friction error at the check: before -> after")
    for r in rows:
        visc = f"{r['viscous_scale']:.3f}" if r["viscous_fitted"] else "  = level"
        visc += " (bound)" if r["viscous_at_bound"] else ""
        print(f"{r['joint']:<10} {r['level_scale']:.3f}  {visc:>8}  "
              f"{100 * r['error_before']:5.1f} % -> {100 * r['error_after']:5.1f} %")
    print(f"refreshed parameters written to {args.output}")
    return 0
