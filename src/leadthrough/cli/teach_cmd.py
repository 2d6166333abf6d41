"""``leadthrough teach``: waypoints and the welding line from a guiding session (paper Fig. 6)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from leadthrough.errors import DataError, TeachError, UnknownRobotError
from leadthrough.fileio import require_folder
from leadthrough.robot.description import Robot, load_robot
from leadthrough.session.record import SessionLog, load_session
from leadthrough.teach.export import line_to_dict, write_program_csv, write_program_json
from leadthrough.teach.program import TaughtProgram, teach_session

__all__ = ["register", "summary"]

_DESCRIPTION = """\
Make the taught program of a guiding session: the measured TCP path (forward kinematics of the
measured joints) from the operator's first mark to the last, simplified to waypoints by
Ramer-Douglas-Peucker (every mark kept), the welding line fitted between two marks (default P1 and
P2) with the path's max and RMS deviation from it, and a check of the waypoints against the joint
position and speed limits at the programmed TCP speed.

The session needs at least two marks. -o writes the JSON program; a CSV of the same waypoints is
written only if --csv names it. Nothing is written if any check fails.
"""

_EPILOG = """\
examples:
  leadthrough teach seam.parquet -o seam.json
  leadthrough teach seam.parquet --tolerance-mm 0.5 --speed 0.05 -o seam.json --csv seam.csv
  leadthrough teach path.parquet --no-line -o path.json --json
"""


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "teach", help="waypoints and welding line from a guiding session",
        description=_DESCRIPTION, epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("session", type=Path, help="session .parquet written by the guiding loop")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="PATH.json",
                   help="JSON program to write")
    p.add_argument("--csv", type=Path, default=None, metavar="PATH.csv",
                   help="also write the waypoints as CSV (joint and Cartesian, units in header)")
    p.add_argument("--tolerance-mm", type=float, default=1.0, metavar="MM",
                   help="RDP tolerance: largest distance of a dropped TCP position from the "
                        "waypoint path [mm] (default 1.0)")
    p.add_argument("--speed", type=float, default=0.1, metavar="M_PER_S",
                   help="programmed linear TCP speed for the joint speed check [m/s] "
                        "(default 0.1)")
    p.add_argument("--orientation-speed", type=float, default=0.5, metavar="RAD_PER_S",
                   help="programmed orientation speed for the joint speed check [rad/s] "
                        "(default 0.5)")
    line = p.add_mutually_exclusive_group()
    line.add_argument("--line", default="P1,P2", metavar="START,END",
                      help="marks at the welding line's ends (default P1,P2)")
    line.add_argument("--no-line", action="store_true",
                      help="no welding line, only the waypoint path")
    p.add_argument("--window-ms", type=float, default=50.0, metavar="MS",
                   help="averaging half-window around each line mark [ms] (default 50)")
    p.add_argument("--robot", default=None, metavar="ROBOT",
                   help="robot TOML (or built-in name) if the session's robot is not built in; "
                        "must be the robot the session was recorded on")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def _line_labels(text: str) -> tuple[str, str]:
    parts = [s.strip() for s in text.split(",")]
    if len(parts) != 2 or not all(parts) or parts[0] == parts[1]:
        raise TeachError("bad welding line marks", field="--line", value=text,
                         expected="two different mark labels, e.g. P1,P2")
    return parts[0], parts[1]


def _check_outputs(args: argparse.Namespace) -> None:
    outputs = [(args.output, ".json", "-o")]
    if args.csv is not None:
        outputs.append((args.csv, ".csv", "--csv"))
    for path, suffix, flag in outputs:
        if path.suffix.lower() != suffix:
            raise DataError("unsupported output file type", source=path, field=flag,
                            value=path.suffix, expected=suffix)
        require_folder(path)


def _robot_for(log: SessionLog, spec: str | None, session: Path) -> Robot:
    try:
        return load_robot(spec if spec is not None else log.robot)
    except UnknownRobotError as e:
        if spec is not None:
            raise
        raise TeachError("session robot is not a built-in robot", source=session,
                         field="robot", value=log.robot,
                         expected="--robot naming its robot TOML file") from e


def summary(program: TaughtProgram, session: Path, output: Path,
            csv_path: Path | None) -> dict[str, Any]:
    """JSON-ready figures of a taught program (as printed by ``--json``)."""
    line = program.welding_line
    return {
        "session": str(session), "robot": program.robot, "marks": list(program.marks),
        "path_samples": program.path_samples, "waypoints": len(program.waypoints),
        "tolerance_mm": program.tolerance_mm,
        "programmed_speed_m_s": program.limits.programmed_speed_m_s,
        "program_duration_s": program.limits.program_duration_s,
        "max_joint_speed_ratio": program.limits.max_speed_ratio,
        "welding_line": None if line is None else {
            k: v for k, v in line_to_dict(line).items() if k not in ("direction", "samples")},
        "transitions": [{"t_s": e.t, "label": e.label, "cause": e.cause}
                        for e in program.transitions],
        "output": str(output), "csv": None if csv_path is None else str(csv_path),
    }


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough teach``."""
    line = None if args.no_line else _line_labels(args.line)
    _check_outputs(args)
    if args.csv is not None and args.csv.resolve() == args.output.resolve():
        raise DataError("JSON and CSV outputs are the same file", source=args.csv,
                        expected="two different files")
    log = load_session(args.session)
    robot = _robot_for(log, args.robot, args.session)
    program = teach_session(log, robot, tolerance_mm=args.tolerance_mm, speed_m_s=args.speed,
                            line=line, window_s=args.window_ms * 1e-3,
                            orientation_speed_rad_s=args.orientation_speed,
                            source=str(args.session))
    existed = args.output.exists()
    write_program_json(program, args.output)
    if args.csv is not None:
        try:
            write_program_csv(program, args.csv)
        except BaseException:
            if not existed:  # no JSON without its CSV
                args.output.unlink(missing_ok=True)
            raise
    info = summary(program, args.session, args.output, args.csv)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    wl = program.welding_line
    text = (f"{len(program.waypoints)} waypoints (tolerance {program.tolerance_mm:g} mm) from "
            f"{program.path_samples} samples, marks {', '.join(program.marks)}")
    if wl is not None:
        text += (f"; welding line {wl.start_label}->{wl.end_label} {wl.length_m * 1e3:.1f} mm, "
                 f"deviation max {wl.max_deviation_mm:.2f} mm, rms {wl.rms_deviation_mm:.2f} mm")
    text += (f"; program {program.limits.program_duration_s:.2f} s at "
             f"{program.limits.programmed_speed_m_s:g} m/s, max joint speed "
             f"{100 * program.limits.max_speed_ratio:.0f} % of limit")
    outs = str(args.output) + ("" if args.csv is None else f", {args.csv}")
    print(f"{text}; wrote {outs}")
    if program.transitions:
        print("note: safety transitions between the marks: " + ", ".join(
            f"{e.label} at {e.t:.3f} s ({e.cause})" for e in program.transitions))
    return 0
