"""``leadthrough robots``: list built-in robots, or check one robot and report its dynamics."""

from __future__ import annotations

import argparse
import json
from typing import Any

from leadthrough.dynamics.base_parameters import compute_base_parameters
from leadthrough.robot.description import BUILTIN_ROBOTS, Robot, load_robot

__all__ = ["register", "robot_summary"]


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "robots",
        help="list robots and their base-parameter counts",
        description="Load robots (built-in names or robot TOML paths), validate them, and "
                    "print joints, drives and the number of base (identifiable) parameters.",
        epilog="example: leadthrough robots --robot er20 --base",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", action="append", metavar="ROBOT",
                   help="built-in name or robot TOML path (repeatable; default: all built-in)")
    p.add_argument("--base", action="store_true", help="also list the base parameters")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def robot_summary(robot: Robot, with_base: bool = False) -> dict[str, Any]:
    """Figures describing one robot (joints, drives, base-parameter count)."""
    base = compute_base_parameters(robot.model)
    out: dict[str, Any] = {
        "name": robot.name,
        "urdf": str(robot.drive_file.urdf_path),
        "dof": robot.n,
        "tcp_frame": robot.tcp_frame,
        "standard_parameters": 10 * robot.n,
        "base_parameters": base.count,
        "joints": [
            {"name": j.name, "gear_ratio": j.gear_ratio, "torque_constant_Nm_per_A":
             j.torque_constant, "max_torque_Nm": j.max_torque, "max_current_A": j.max_current}
            for j in robot.joints
        ],
    }
    if with_base:
        out["base"] = [{"name": n, "expression": e}
                       for n, e in zip(base.names, base.expressions, strict=True)]
    return out


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough robots``."""
    specs = args.robot or list(BUILTIN_ROBOTS)
    summaries = [robot_summary(load_robot(s), args.base) for s in specs]
    if args.json:
        print(json.dumps({"robots": summaries}, indent=2))
        return 0
    print(f"{'robot':<8} {'dof':>3} {'standard':>9} {'base':>5}  tcp")
    for s in summaries:
        print(f"{s['name']:<8} {s['dof']:>3} {s['standard_parameters']:>9} "
              f"{s['base_parameters']:>5}  {s['tcp_frame']}")
        if args.base:
            for b in s["base"]:
                print(f"    {b['name']:<16} = {b['expression']}")
    return 0
