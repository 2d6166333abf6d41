"""Write a taught program as JSON and CSV (atomically: a failed write leaves no file behind).

JSON (one object)::

    {"format": "leadthrough taught path", "version": 1, "robot": "er20",
     "tcp_frame": "flange", "frame": "base", "joint_names": [...],
     "units": {...}, "programmed_speed_m_s": 0.1, "orientation_speed_rad_s": 0.5,
     "tolerance_mm": 1.0, "program_duration_s": ..., "max_joint_speed_ratio": ...,
     "welding_line": {"start_label", "end_label", "p1_m", "p2_m", "direction", "length_m",
                      "max_deviation_mm", "rms_deviation_mm", "samples"} or null,
     "waypoints": [{"index", "label", "sample", "t_s", "q_rad", "tcp_position_m",
                    "tcp_quat_xyzw"}, ...]}

CSV: ``# key: value`` comment lines (robot, TCP frame, frame, joint names, programmed speed,
tolerance, welding line), then a header naming the units and one row per waypoint::

    index,label,sample,t [s],q1 [rad],...,qn [rad],x [m],y [m],z [m],qx [-],qy [-],qz [-],qw [-]

Positions and orientations are the measured TCP in the robot base frame.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from leadthrough.fileio import atomic_write, atomic_write_text
from leadthrough.teach.line_fit import WeldingLine
from leadthrough.teach.program import TaughtProgram
from leadthrough.teach.programs.grammar import check_target_label, comment_text

__all__ = ["FORMAT_VERSION", "csv_header", "line_to_dict", "program_to_dict",
           "write_program_csv", "write_program_json"]

FORMAT_VERSION = 1
_UNITS = {
    "t_s": "s (session time)",
    "q_rad": "rad",
    "tcp_position_m": "m (base frame)",
    "tcp_quat_xyzw": "unit quaternion x, y, z, w (base frame)",
    "programmed_speed_m_s": "m/s",
    "orientation_speed_rad_s": "rad/s",
    "tolerance_mm": "mm",
    "program_duration_s": "s",
    "length_m": "m",
    "deviation_mm": "mm",
}


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def line_to_dict(line: WeldingLine) -> dict[str, Any]:
    """The welding line as JSON-ready values (metres, millimetres)."""
    return {"start_label": line.start_label, "end_label": line.end_label,
            "p1_m": _floats(line.p1_base), "p2_m": _floats(line.p2_base),
            "direction": _floats(line.direction_base), "length_m": line.length_m,
            "max_deviation_mm": line.max_deviation_mm,
            "rms_deviation_mm": line.rms_deviation_mm, "samples": line.samples}


def _check_labels(program: TaughtProgram) -> None:
    """Every label the export embeds is a mark label (or several joined with ``/``)."""
    for i, label in enumerate(program.waypoints.labels):
        check_target_label(label, i)
    line = program.welding_line
    if line is not None:
        check_target_label(line.start_label, 0)
        check_target_label(line.end_label, 1)


def program_to_dict(program: TaughtProgram) -> dict[str, Any]:
    """The JSON document of a taught program (see the module docstring for its layout).

    Raises:
        TeachError: A label that is not a mark label.
    """
    _check_labels(program)
    w = program.waypoints
    return {
        "format": "leadthrough taught path",
        "version": FORMAT_VERSION,
        "robot": program.robot,
        "tcp_frame": program.tcp_frame,
        "frame": "base",
        "joint_names": list(program.joint_names),
        "units": dict(_UNITS),
        "programmed_speed_m_s": program.limits.programmed_speed_m_s,
        "orientation_speed_rad_s": program.limits.orientation_speed_rad_s,
        "tolerance_mm": program.tolerance_mm,
        "program_duration_s": program.limits.program_duration_s,
        "max_joint_speed_ratio": program.limits.max_speed_ratio,
        "welding_line": None if program.welding_line is None
        else line_to_dict(program.welding_line),
        "waypoints": [
            {"index": i, "label": w.labels[i], "sample": int(w.sample[i]),
             "t_s": float(w.time[i]), "q_rad": _floats(w.q[i]),
             "tcp_position_m": _floats(w.tcp_position_base[i]),
             "tcp_quat_xyzw": _floats(w.tcp_quat_xyzw[i])}
            for i in range(len(w))
        ],
    }


def write_program_json(program: TaughtProgram, path: str | Path) -> Path:
    """Write the program as JSON, atomically.

    Args:
        program: The taught program.
        path: Output file.

    Returns:
        The path written.

    Raises:
        DataError: The output folder does not exist.
    """
    return atomic_write_text(path, json.dumps(program_to_dict(program), indent=2) + "\n")


def csv_header(n_joints: int) -> list[str]:
    """Column names (with units) of the waypoint CSV for ``n_joints`` joints."""
    return (["index", "label", "sample", "t [s]"]
            + [f"q{j + 1} [rad]" for j in range(n_joints)]
            + ["x [m]", "y [m]", "z [m]", "qx [-]", "qy [-]", "qz [-]", "qw [-]"])


def write_program_csv(program: TaughtProgram, path: str | Path) -> Path:
    """Write the waypoints as CSV with a ``# key: value`` header, atomically.

    Args:
        program: The taught program.
        path: Output file.

    Returns:
        The path written.

    Raises:
        DataError: The output folder does not exist.
        TeachError: A label that is not a mark label.
    """
    _check_labels(program)
    w = program.waypoints
    notes = {  # names from the robot file: one comment line each
        "robot": comment_text(program.robot),
        "tcp_frame": comment_text(program.tcp_frame),
        "frame": "base (positions [m], quaternions x, y, z, w)",
        "joints": comment_text(", ".join(program.joint_names)),
        "programmed_speed_m_s": f"{program.limits.programmed_speed_m_s:g}",
        "tolerance_mm": f"{program.tolerance_mm:g}",
    }
    line = program.welding_line
    if line is not None:
        notes["welding_line"] = (
            f"{line.start_label} ({', '.join(f'{v:.6f}' for v in line.p1_base)}) m -> "
            f"{line.end_label} ({', '.join(f'{v:.6f}' for v in line.p2_base)}) m, "
            f"length {line.length_m:.6f} m, max deviation {line.max_deviation_mm:.3f} mm, "
            f"rms {line.rms_deviation_mm:.3f} mm")

    def write(tmp: Path) -> None:
        with tmp.open("w", encoding="utf-8", newline="") as f:
            f.write("# leadthrough waypoints\n")
            for k, v in notes.items():
                f.write(f"# {k}: {v}\n")
            out = csv.writer(f, lineterminator="\n")
            out.writerow(csv_header(len(program.joint_names)))
            for i in range(len(w)):
                out.writerow([i, w.labels[i], int(w.sample[i]), repr(float(w.time[i]))]
                             + [repr(float(v)) for v in w.q[i]]
                             + [repr(float(v)) for v in w.tcp_position_base[i]]
                             + [repr(float(v)) for v in w.tcp_quat_xyzw[i]])

    return atomic_write(path, write)
