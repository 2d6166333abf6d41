"""``leadthrough payload``: payload mass (and CoM) from a recording with the payload attached."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from leadthrough.data.io import load_recording
from leadthrough.errors import DataError
from leadthrough.estimation.payload import estimate_payload
from leadthrough.identification.params_file import load_params
from leadthrough.robot.description import load_robot

__all__ = ["register"]


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "payload", help="identify a payload with the unloaded robot's parameters",
        description="Estimate the payload at the flange from a recording made with it attached, "
                    "using parameters identified on the unloaded robot (paper Table III).",
        epilog="example: leadthrough payload loaded.parquet --robot er20 --params params.toml "
               "--json",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path)
    p.add_argument("--robot", default="er20")
    p.add_argument("--params", type=Path, required=True, help="params of the unloaded robot")
    p.add_argument("--reference", type=Path, default=None,
                   help="a recording of the same trajectory without the payload: the payload "
                        "is fitted to the difference of the two runs' residuals, which "
                        "cancels the model's own error along the path (motion only)")
    p.add_argument("--columns", type=Path, default=None, help="column map for a raw log")
    p.add_argument("--method", choices=("motion", "static"), default="motion",
                   help="during motion (default, the paper's) or from static poses")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough payload``."""
    robot = load_robot(args.robot)
    pf = load_params(args.params, robot)
    rec = load_recording(args.recording, args.columns)
    rec.check_joint_range(robot)
    if None not in (rec.sim_seed, pf.sim_seed) and rec.sim_seed != pf.sim_seed:
        raise DataError("recorded on another simulated robot than the params were identified "
                        "on", source=args.recording, field="sim_seed", value=rec.sim_seed,
                        expected=f"{pf.sim_seed} (the params' [meta] sim_seed)")
    reference = None
    if args.reference is not None:
        reference = load_recording(args.reference, args.columns)
        reference.check_joint_range(robot)
        if None not in (rec.sim_seed, reference.sim_seed) and rec.sim_seed != reference.sim_seed:
            raise DataError("recorded on another simulated robot than the payload's recording",
                            source=args.reference, field="sim_seed", value=reference.sim_seed,
                            expected=f"{rec.sim_seed} (the recording's sim_seed)")
    est = estimate_payload(rec, robot, pf.params, args.method, reference=reference)
    out: dict[str, Any] = {"robot": robot.name, "method": est.method, "mass_kg": est.mass_kg,
                           "mass_std_kg": est.mass_std_kg, "weight_N": est.weight_n,
                           "samples": est.samples,
                           "reference": None if args.reference is None else str(args.reference),
                           "reference_shift_s": est.reference_shift_s}
    if est.com_tcp is not None:
        out["com_m"] = [float(v) for v in est.com_tcp]
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        com = "" if est.com_tcp is None else \
            " at CoM (" + ", ".join(f"{v:.3f}" for v in est.com_tcp) + ") m in the TCP frame"
        against = "" if est.reference_shift_s is None else \
            f", against {args.reference} (shifted {est.reference_shift_s:+.3f} s)"
        print(f"payload {est.mass_kg:.3f} ± {est.mass_std_kg:.3f} kg ({est.weight_n:.2f} N)"
              f"{com}{against}")
    return 0
