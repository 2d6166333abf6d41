"""``leadthrough teach``: waypoints and the welding line from a guiding session (paper Fig. 6)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import pinocchio as pin

from leadthrough.errors import DataError, TeachError, UnknownRobotError
from leadthrough.fileio import atomic_write_text, require_folder
from leadthrough.labels import check_label
from leadthrough.robot.description import Robot, load_robot
from leadthrough.session_format import SessionLog, load_session
from leadthrough.teach.export import line_to_dict, program_to_dict, write_program_csv
from leadthrough.teach.program import TaughtProgram, teach_session
from leadthrough.teach.programs import LANGUAGES, ProgramOptions, render_robot_program
from leadthrough.teach.programs.targets import program_name, tool_from_xyzabc

__all__ = ["FORMATS", "SUFFIXES", "register", "summary"]

SUFFIXES = {"json": ".json", **{k: v.suffix for k, v in LANGUAGES.items()}}
FORMATS = tuple(SUFFIXES)

_DESCRIPTION = """\
Make the taught program of a guiding session: the measured TCP path (forward kinematics of the
measured joints) from the operator's first mark to the last, simplified to waypoints by
Ramer-Douglas-Peucker (every mark kept), the welding line fitted between two marks (default P1 and
P2) with the path's max and RMS deviation from it, and a check of the waypoints against the joint
position and speed limits at the programmed TCP speed.

The session needs at least two marks. -o writes the program: JSON (the waypoints with joints and
poses), or a robot program with --format urscript (.script), krl (.src + .dat), tp (FANUC .ls) or
rapid (ABB .mod); the format defaults to -o's suffix. A robot program moves to the first
waypoint's joints, then linearly through the waypoints with the controller's configuration data
(KUKA Status/Turn, FANUC configuration string and turn numbers, ABB confdata), the welding line
P1 -> P2 as one linear move at the programmed speed; --joint-space writes joint moves to the
taught joints instead (the only choice for robots whose configuration data cannot single out the
joints, e.g. 7-axis arms). Each program is read back before it is written: it must hold only the
statements leadthrough writes, in their order, exactly the moves written, and solve back with
our inverse kinematics to the taught joints within 0.01 degree.

Mark labels are names: 1-32 letters, digits, '_', '-', '.' or spaces (not at either end). A
session whose marks carry anything else is refused (exit 2), naming the file, the event and
the label.

A CSV of the waypoints is written only if --csv names it. Nothing is written if any check fails.
"""

_EPILOG = """\
examples:
  leadthrough teach seam.parquet -o seam.json
  leadthrough teach seam.parquet --tolerance-mm 0.5 --speed 0.05 -o seam.json --csv seam.csv
  leadthrough teach path.parquet --no-line -o path.json --json
  leadthrough teach seam.parquet -o seam.src                      # KUKA KRL: seam.src + seam.dat
  leadthrough teach seam.parquet -o SEAM.ls --zone-mm 2 --fanuc-cnt 30
  leadthrough teach seam.parquet -o seam.mod --tool 0,0,350,0,0,0  # ABB RAPID, torch TCP
  leadthrough teach seam.parquet -o seam.script --joint-space      # URScript movej
"""


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "teach", help="waypoints and welding line from a guiding session",
        description=_DESCRIPTION, epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("session", type=Path, help="session .parquet written by the guiding loop")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="PATH",
                   help="program to write: .json, .script, .src (+ .dat), .ls or .mod")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="program format (default: from the suffix of -o)")
    p.add_argument("--joint-space", action="store_true",
                   help="robot programs: joint moves to the taught joints (movej, PTP E6AXIS, "
                        "J P[i] joint positions, MoveAbsJ) instead of linear moves to poses")
    p.add_argument("--zone-mm", type=float, default=1.0, metavar="MM",
                   help="blending radius at waypoints between the marks [mm] (default 1.0; "
                        "0 stops exactly at every waypoint)")
    p.add_argument("--fanuc-cnt", type=int, default=None, metavar="N",
                   help="FANUC TP programs (.ls) only: CNT value (0-100) at blended waypoints "
                        "(default 50)")
    p.add_argument("--tool", default=None, metavar="X,Y,Z,A,B,C",
                   help="program TCP relative to the robot file's TCP frame [mm, deg; A, B, C "
                        "about z, y, x] (default: the robot file's TCP frame; the waypoints and "
                        "the welding line stay those of the robot file's TCP frame)")
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
    return check_label(parts[0], field="--line"), check_label(parts[1], field="--line")


def _format(args: argparse.Namespace) -> str:
    """The program format: --format, else from the suffix of -o."""
    suffix = args.output.suffix.lower()
    by_suffix = {v: k for k, v in SUFFIXES.items()}
    fmt = args.format if args.format is not None else by_suffix.get(suffix)
    if fmt is None or suffix != SUFFIXES[fmt]:
        raise DataError("unsupported output file type", source=args.output, field="-o",
                        value=args.output.suffix,
                        expected=SUFFIXES[fmt] if fmt is not None
                        else ", ".join(SUFFIXES.values()))
    return fmt


def _check_outputs(args: argparse.Namespace, fmt: str) -> list[Path]:
    """The files to write (checked: folders exist, no two the same, CSV suffix)."""
    paths = [args.output] + ([args.output.with_suffix(".dat")] if fmt == "krl" else [])
    if args.csv is not None:
        if args.csv.suffix.lower() != ".csv":
            raise DataError("unsupported output file type", source=args.csv, field="--csv",
                            value=args.csv.suffix, expected=".csv")
        if args.csv.resolve() in {p.resolve() for p in paths}:
            raise DataError("program and CSV outputs are the same file", source=args.csv,
                            expected="two different files")
    for path in [*paths, *([args.csv] if args.csv is not None else [])]:
        require_folder(path)
    return paths


def _refuse_program_settings(args: argparse.Namespace) -> None:
    """A robot program's setting given for the JSON path (which has none of them)."""
    for option, value in (("--fanuc-cnt", args.fanuc_cnt), ("--tool", args.tool),
                          ("--joint-space", args.joint_space or None)):
        if value is not None:
            raise TeachError("a robot program's setting given for a JSON path", field=option,
                             value=value, expected="a robot program (-o .script, .src, .ls "
                                                   "or .mod) with it, or no " + option)


def _options(args: argparse.Namespace, fmt: str) -> ProgramOptions:
    """Program options from the command line (bad values: TeachError naming the flag)."""
    if not (math.isfinite(args.zone_mm) and args.zone_mm >= 0.0):
        raise TeachError("out of range", field="--zone-mm", value=args.zone_mm,
                         expected="a finite blending radius ≥ 0 mm")
    if args.fanuc_cnt is not None and fmt != "tp":
        raise TeachError("a FANUC TP setting given for another format", field="--fanuc-cnt",
                         value=args.fanuc_cnt, expected=f"--fanuc-cnt only with a .ls program "
                                                        f"(this one is {fmt})")
    cnt = ProgramOptions.fanuc_cnt if args.fanuc_cnt is None else args.fanuc_cnt
    if not 0 <= cnt <= 100:
        raise TeachError("out of range", field="--fanuc-cnt", value=cnt,
                         expected="an integer 0 … 100")
    tool = pin.SE3.Identity()
    if args.tool is not None:
        try:
            values = [float(v) for v in args.tool.split(",")]
        except ValueError:
            values = []
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise TeachError("bad tool", field="--tool", value=args.tool,
                             expected="six numbers X,Y,Z,A,B,C [mm, deg]")
        tool = tool_from_xyzabc(values)
    return ProgramOptions(name=program_name(args.output.stem, fmt), speed_m_s=args.speed,
                          orientation_speed_rad_s=args.orientation_speed,
                          zone_mm=args.zone_mm, tool=tool, joint_space=args.joint_space,
                          fanuc_cnt=cnt)


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
            csv_path: Path | None, fmt: str = "json", files: list[Path] | None = None,
            round_trip_deg: float | None = None) -> dict[str, Any]:
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
        "format": fmt, "output": str(output),
        "files": [str(f) for f in (files if files is not None else [output])],
        "round_trip_max_deg": round_trip_deg,
        "csv": None if csv_path is None else str(csv_path),
    }


def _write(args: argparse.Namespace, fmt: str, program: TaughtProgram,
           robot: Robot) -> tuple[list[Path], float | None]:
    """Write the program (and the CSV): all files or none."""
    worst = None
    if fmt == "json":
        files = {args.output: json.dumps(program_to_dict(program), indent=2) + "\n"}
    else:
        rendered = render_robot_program(program, robot, fmt, _options(args, fmt),
                                        str(args.session))
        files = {args.output.with_suffix(k): v for k, v in rendered.files.items()}
        worst = rendered.max_round_trip_deg
    existed = {p: p.exists() for p in files}
    written: list[Path] = []
    try:
        for path, text in files.items():
            written.append(atomic_write_text(path, text))
        if args.csv is not None:
            write_program_csv(program, args.csv)
    except BaseException:
        for path in written:
            if not existed[path]:  # no program without its CSV
                path.unlink(missing_ok=True)
        raise
    return written, worst


def _printable(text: str) -> str:
    """Text from the session file as it may go to a terminal: printable ASCII, others as
    ``?`` (no control sequences), at most 80 characters."""
    return "".join(c if " " <= c <= "~" else "?" for c in text[:80])


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough teach``."""
    line = None if args.no_line else _line_labels(args.line)
    fmt = _format(args)
    _check_outputs(args, fmt)
    if fmt != "json":
        _options(args, fmt)  # bad flags fail before the session is read
    else:
        _refuse_program_settings(args)
    log = load_session(args.session)
    robot = _robot_for(log, args.robot, args.session)
    program = teach_session(log, robot, tolerance_mm=args.tolerance_mm, speed_m_s=args.speed,
                            line=line, window_s=args.window_ms * 1e-3,
                            orientation_speed_rad_s=args.orientation_speed,
                            source=str(args.session))
    files, worst = _write(args, fmt, program, robot)
    info = summary(program, args.session, args.output, args.csv, fmt, files, worst)
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
    if worst is not None:
        text += f"; {fmt} solves back to the taught joints within {worst:.4f} deg"
    outs = ", ".join(str(f) for f in files) + ("" if args.csv is None else f", {args.csv}")
    print(f"{text}; wrote {outs}")
    if program.transitions:
        print("note: safety transitions between the marks: " + ", ".join(
            f"{_printable(e.label)} at {e.t:.3f} s ({_printable(e.cause)})"
            for e in program.transitions))
    return 0
