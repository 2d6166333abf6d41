"""Teach-in from a guiding session: the taught waypoint path and the welding line (paper Fig. 6).

The operator guides the TCP and presses "mark point" at P1, P2, ... . From the session:

1. the measured TCP path (forward kinematics of the measured joints, see
   :mod:`leadthrough.teach.path`) from the first mark to the last;
2. its waypoints: Ramer–Douglas–Peucker on the TCP positions with a tolerance [mm], every mark
   kept as a waypoint (labelled with its name), each waypoint with its recorded joint
   configuration and TCP orientation;
3. the welding line between two marks (default P1 → P2), fitted by total least squares, with the
   path's deviation from it (:mod:`leadthrough.teach.line_fit`);
4. a check of the waypoints against the joint position and speed limits at the programmed speed
   (:mod:`leadthrough.teach.limits_check`).

A session needs at least two marks: the taught path runs from the first mark to the last, and
the approach before it and the retreat after it are not part of the program.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.labels import check_label
from leadthrough.robot.description import Robot
from leadthrough.session_format import SessionEvent, SessionLog
from leadthrough.teach.limits_check import LimitReport, check_limits
from leadthrough.teach.line_fit import WeldingLine, fit_welding_line
from leadthrough.teach.path import check_mark_time, check_session_robot, find_mark, tcp_path
from leadthrough.teach.simplify import rdp_indices

__all__ = ["TaughtProgram", "Waypoints", "check_events", "teach_session"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Waypoints:
    """Kept points of the taught path (K waypoints, n joints).

    Attributes:
        sample: Row of each waypoint in the session, shape (K,).
        time: Session time of each waypoint [s], shape (K,).
        q: Measured joint positions [rad], shape (K, n).
        tcp_position_base: Measured TCP position, base frame [m], shape (K, 3).
        tcp_quat_xyzw: Measured TCP orientation, base frame, quaternion (x, y, z, w), shape (K, 4).
        labels: Mark name of each waypoint (``"P1"``; several joined with ``"/"`` if pressed on
            the same row) or ``""``, K strings.
    """

    sample: NDArray[np.int64]
    time: Array
    q: Array
    tcp_position_base: Array
    tcp_quat_xyzw: Array
    labels: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class TaughtProgram:
    """The result of a teach-in.

    Attributes:
        robot: Robot name.
        joint_names: Joint names, in column order of ``waypoints.q``.
        tcp_frame: The TCP frame whose pose the waypoints give.
        waypoints: The simplified path.
        welding_line: The fitted line between the two line marks, or None if not requested.
        limits: Timing and limit figures at the programmed speed (no violations).
        tolerance_mm: RDP tolerance used [mm].
        path_samples: Number of recorded rows from the first to the last mark.
        marks: Mark labels in time order.
        transitions: Safety state transitions between the first and the last mark (a fault
            there means the robot stopped while the hand went on: check the path).
    """

    robot: str
    joint_names: tuple[str, ...]
    tcp_frame: str
    waypoints: Waypoints
    welding_line: WeldingLine | None
    limits: LimitReport
    tolerance_mm: float
    path_samples: int
    marks: tuple[str, ...]
    transitions: tuple[SessionEvent, ...] = ()


def check_events(log: SessionLog, source: str | None = None) -> None:
    """Check the session's events as read from its file: each has a kind, a finite time and
    text fields, and each mark's label is a name (:func:`leadthrough.labels.check_label`: it
    ends up in program comments, file names and pages).

    Args:
        log: The session.
        source: Session file, for messages.

    Raises:
        LabelError: A mark label that is not a name, naming ``events[i].label`` and the label.
        TeachError: An event whose kind, time or text is not of its type, naming
            ``events[i]`` and the field.
    """
    for i, e in enumerate(log.events):
        if e.kind == "mark":
            check_label(e.label, source=source, field=f"events[{i}].label")
        for name in ("kind", "label", "cause"):
            if not isinstance(getattr(e, name), str):
                raise TeachError("not a text", source=source, field=f"events[{i}].{name}",
                                 value=getattr(e, name), expected="a string")
        if isinstance(e.t, bool) or not isinstance(e.t, numbers.Real) \
                or not math.isfinite(e.t):
            raise TeachError("not a finite time", source=source, field=f"events[{i}].t",
                             value=e.t, expected="a finite event time [s]")


def teach_session(log: SessionLog, robot: Robot, *, tolerance_mm: float = 1.0,
                  speed_m_s: float = 0.1, line: tuple[str, str] | None = ("P1", "P2"),
                  window_s: float = 0.05, orientation_speed_rad_s: float = 0.5,
                  source: str | None = None) -> TaughtProgram:
    """Make the taught program of a guiding session.

    Args:
        log: The session (with the operator's marks as events).
        robot: The robot it was recorded on.
        tolerance_mm: RDP tolerance: largest distance of a dropped TCP position from the
            waypoint polyline [mm], ≥ 0.
        speed_m_s: Programmed linear TCP speed for the limit check [m/s], > 0.
        line: Labels of the marks at the welding line's start and end, or None for no line.
        window_s: Half-width of the averaging window around each line mark [s].
        orientation_speed_rad_s: Programmed orientation speed for the limit check [rad/s].
        source: Session file, for messages.

    Returns:
        The waypoints, the welding line and the limit figures.

    Raises:
        TeachError: Another robot's session, fewer than two marks, a missing or repeated line
            mark, a degenerate line, bad settings, or a waypoint outside the joint position or
            speed limits (naming the waypoint, joint, value and limit).
        LabelError: A mark label (or a line end) that is not a name
            (:func:`leadthrough.labels.check_label`), naming the session file, the event and
            the label.
    """
    if not (math.isfinite(tolerance_mm) and tolerance_mm >= 0.0):
        raise TeachError("out of range", field="tolerance_mm", value=tolerance_mm,
                         expected="a finite RDP tolerance ≥ 0 mm")
    if not (math.isfinite(window_s) and window_s >= 0.0):
        raise TeachError("out of range", field="window_s", value=window_s,
                         expected="a finite averaging half-window ≥ 0 s")
    check_session_robot(log, robot, source)
    check_events(log, source)
    for end in line or ():
        check_label(end, source=source, field="line")
    marks = log.marks
    if len(marks) < 2:
        raise TeachError("session has no marks" if not marks else "session has only one mark",
                         source=source, field="marks",
                         value=", ".join(m.label for m in marks) or None,
                         expected="at least two operator marks (P1, P2, ...): the taught path "
                                  "runs from the first mark to the last")
    for m in marks:
        check_mark_time(log, m, source)
    line_times = None
    if line is not None:
        line_times = (find_mark(log, line[0], source).t, find_mark(log, line[1], source).t)
    t_first, t_last = min(m.t for m in marks), max(m.t for m in marks)
    full = tcp_path(log, robot, t_first - window_s, t_last + window_s, source)
    inside = np.flatnonzero((full.time >= t_first) & (full.time <= t_last))
    if inside.size == 0:  # marks between two rows: take the nearest row
        inside = np.array([full.nearest(t_first)])
    lo, hi = int(inside[0]), int(inside[-1]) + 1
    seg_time = full.time[lo:hi]
    labels_at: dict[int, list[str]] = {}
    for m in marks:
        k = int(np.argmin(np.abs(seg_time - m.t)))
        labels_at.setdefault(k, []).append(m.label)
    kept = rdp_indices(full.tcp_position_base[lo:hi], tolerance_mm * 1e-3, keep=labels_at)
    rows = kept + lo
    waypoints = Waypoints(
        sample=full.sample[rows], time=full.time[rows], q=full.q[rows],
        tcp_position_base=full.tcp_position_base[rows], tcp_quat_xyzw=full.tcp_quat_xyzw[rows],
        labels=tuple("/".join(labels_at.get(int(k), [])) for k in kept))
    welding = None
    if line is not None and line_times is not None:
        welding = fit_welding_line(full, line_times[0], line_times[1], labels=line,
                                   window_s=window_s, source=source)
    limits = check_limits(waypoints.q, waypoints.tcp_position_base, waypoints.tcp_quat_xyzw,
                          robot, speed_m_s, orientation_speed_rad_s=orientation_speed_rad_s,
                          labels=waypoints.labels, source=source)
    return TaughtProgram(robot=robot.name, joint_names=robot.joint_names,
                         tcp_frame=robot.tcp_frame, waypoints=waypoints, welding_line=welding,
                         limits=limits, tolerance_mm=float(tolerance_mm),
                         path_samples=hi - lo, marks=tuple(m.label for m in marks),
                         transitions=tuple(e for e in log.events if e.kind == "transition"
                                           and t_first <= e.t <= t_last))
