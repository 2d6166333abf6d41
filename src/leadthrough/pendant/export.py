"""The pendant's export: the session, the taught points, and the taught path for teach-in.

Each export goes to a new numbered folder (``export-001``, ``export-002``, ...) under the
pendant's output folder, with:

* ``session.parquet``: the recording kept by the live loop (the last ``record_s`` seconds at
  the controller rate) with the taught points as its marks: ``leadthrough teach`` reads it
  like any session;
* ``points.json``: the taught points in the operator's order (label, time, joint positions,
  TCP pose by Pinocchio's forward kinematics): a point-to-point program;
* ``path.json`` and ``path.csv``: :func:`~leadthrough.teach.program.teach_session` on that
  session (the measured TCP path from the first mark to the last, simplified, the welding line
  P1 → P2 when both are marked, the joint limit check), written by
  :mod:`leadthrough.teach.export`. With fewer than two points, or a path the limit check
  refuses, nothing is written for it and :attr:`Export.note` says why (by waypoint, as
  ``leadthrough teach`` does).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from leadthrough.errors import TeachError
from leadthrough.fileio import atomic_write_text
from leadthrough.pendant.backend import MarkedPoint
from leadthrough.robot.description import Robot
from leadthrough.session_format import SessionLog, save_session
from leadthrough.teach import forward_tcp, teach_session, write_program_csv, write_program_json
from leadthrough.teach.program import TaughtProgram

__all__ = ["POINTS_FORMAT", "Export", "export_taught", "points_to_dict"]

#: ``format`` of ``points.json``.
POINTS_FORMAT = "leadthrough taught points"


@dataclass(frozen=True)
class Export:
    """What an export wrote.

    Attributes:
        folder: The export's folder.
        files: Written files by role (``session``, ``points``, ``path``, ``path_csv``).
        program: The taught path, or None (see ``note``).
        note: Why there is no ``path.json``, or "".
    """

    folder: Path
    files: dict[str, Path]
    program: TaughtProgram | None
    note: str


def points_to_dict(points: list[MarkedPoint], robot: Robot) -> dict[str, object]:
    """The taught points as JSON-ready values (radians, metres, base frame)."""
    rows: list[dict[str, object]] = []
    if points:
        poses = forward_tcp(robot, np.array([p.q for p in points]))
        rows = [{"index": k, "label": p.label, "t_s": float(p.t),
                 "q_rad": [float(v) for v in p.q],
                 "tcp_position_m": [float(v) for v in poses.position_base[k]],
                 "tcp_quat_xyzw": [float(v) for v in poses.quat_xyzw[k]]}
                for k, p in enumerate(points)]
    return {"format": POINTS_FORMAT, "version": 1, "robot": robot.name,
            "tcp_frame": robot.tcp_frame, "frame": "base", "joint_names": list(robot.joint_names),
            "units": {"t_s": "s (session time)", "q_rad": "rad", "tcp_position_m": "m",
                      "tcp_quat_xyzw": "unit quaternion x, y, z, w"},
            "points": rows}


def export_taught(log: SessionLog, points: list[MarkedPoint], robot: Robot, out: Path, *,
                  tolerance_mm: float = 1.0, speed_m_s: float = 0.1) -> Export:
    """Write the session, the points and the taught path into a new folder under ``out``.

    Args:
        log: The live session's recording, its marks the taught points.
        points: The taught points, in the operator's order.
        robot: The robot.
        out: The pendant's output folder (made if missing).
        tolerance_mm: RDP tolerance of the taught path [mm].
        speed_m_s: Programmed TCP speed for the limit check [m/s].

    Returns:
        What was written.
    """
    out.mkdir(parents=True, exist_ok=True)
    folder = _next_folder(out)
    files = {"session": save_session(log, folder / "session.parquet"),
             "points": atomic_write_text(folder / "points.json", json.dumps(
                 points_to_dict(points, robot), indent=2) + "\n")}
    labels = {p.label for p in points}
    line = ("P1", "P2") if {"P1", "P2"} <= labels else None
    try:
        program = teach_session(log, robot, tolerance_mm=tolerance_mm, speed_m_s=speed_m_s,
                                line=line, source=str(files["session"]))
    except TeachError as e:
        return Export(folder, files, None, f"no path.json: {e}")
    files["path"] = write_program_json(program, folder / "path.json")
    files["path_csv"] = write_program_csv(program, folder / "path.csv")
    note = "" if line is not None else "no welding line: mark P1 and P2 for one"
    return Export(folder, files, program, note)


def _next_folder(out: Path) -> Path:
    """``out/export-NNN``, the first number not taken, made."""
    taken = [int(p.name[7:]) for p in out.glob("export-*") if p.name[7:].isdigit()]
    folder = out / f"export-{max(taken, default=0) + 1:03d}"
    folder.mkdir()
    return folder
