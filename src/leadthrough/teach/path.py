"""The guided TCP path of a session: forward kinematics of the measured joint positions, and the
operator's marks.

The taught path is the *measured* TCP, ``FK(q)`` with Pinocchio, not the controller's command
``tcp_cmd_base``: the command leads the robot by the servo's tracking lag and, when a limit
brakes the motion, by the part the IK could not follow. A program replays joint positions, so the
pose that belongs to each recorded ``q`` is the one the robot actually reached.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.robot.description import Robot
from leadthrough.session_format import SessionEvent, SessionLog

__all__ = ["TcpPath", "TcpPoses", "check_mark_time", "check_session_robot", "find_mark",
           "forward_tcp", "tcp_path"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TcpPath:
    """A stretch of a session with the measured TCP pose of every row.

    Attributes:
        sample: Row index in the session, shape (N,).
        time: Time [s], shape (N,).
        q: Measured joint positions [rad], shape (N, n).
        tcp_position_base: Measured TCP position, base frame [m], shape (N, 3).
        tcp_quat_xyzw: Measured TCP orientation in the base frame, unit quaternion (x, y, z, w)
            with w ≥ 0, shape (N, 4).
    """

    sample: NDArray[np.int64]
    time: Array
    q: Array
    tcp_position_base: Array
    tcp_quat_xyzw: Array

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def nearest(self, t: float) -> int:
        """Index (into this path) of the row closest in time to ``t`` [s]."""
        k = int(np.searchsorted(self.time, t))
        if k <= 0:
            return 0
        if k >= len(self):
            return len(self) - 1
        return k - 1 if t - self.time[k - 1] <= self.time[k] - t else k


class TcpPoses(NamedTuple):
    """TCP poses in the base frame.

    Attributes:
        position_base: Positions [m], shape (N, 3).
        quat_xyzw: Unit quaternions (x, y, z, w) with w ≥ 0, shape (N, 4).
    """

    position_base: Array
    quat_xyzw: Array


def forward_tcp(robot: Robot, q: Array) -> TcpPoses:
    """TCP poses of joint configurations (Pinocchio forward kinematics).

    Args:
        robot: The robot (its ``tcp_frame``).
        q: Joint positions [rad], shape (N, n).

    Returns:
        The TCP positions and orientations.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    model, data, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    pos = np.empty((q.shape[0], 3))
    quat = np.empty((q.shape[0], 4))
    for i, qi in enumerate(q):
        pin.forwardKinematics(model, data, qi)
        placement = pin.updateFramePlacement(model, data, fid)
        pos[i] = placement.translation
        quat[i] = pin.Quaternion(placement.rotation).coeffs()
    quat[quat[:, 3] < 0.0] *= -1.0
    return TcpPoses(pos, quat)


def check_session_robot(log: SessionLog, robot: Robot, source: str | None = None) -> None:
    """Check that a session was recorded on ``robot`` and that its time and joints are usable.

    Args:
        log: The session.
        robot: The robot it is meant for.
        source: Session file, for messages.

    Raises:
        TeachError: Another robot's session, joint count mismatch, too few rows, or a time
            column that is not finite and non-decreasing.
    """
    if log.robot != robot.name:
        raise TeachError("session was recorded on another robot", source=source, field="robot",
                         value=log.robot, expected=f"a session of '{robot.name}'")
    if log.n != robot.n:
        raise TeachError("joint count does not match the robot", source=source, field="q",
                         value=log.n, expected=f"{robot.n} joints of '{robot.name}'")
    t = log.time
    if t.shape[0] < 2:
        raise TeachError("session is too short", source=source, field="t", value=t.shape[0],
                         expected="at least 2 rows")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0.0):
        raise TeachError("time is not finite and non-decreasing", source=source, field="t",
                         expected="a session written by 'leadthrough guide'")


def find_mark(log: SessionLog, label: str, source: str | None = None) -> SessionEvent:
    """The operator's mark named ``label``.

    Args:
        log: The session.
        label: Mark name, e.g. ``"P1"``.
        source: Session file, for messages.

    Returns:
        The mark event.

    Raises:
        TeachError: No mark or more than one mark with that name, or a mark outside the
            recorded time range.
    """
    found = [m for m in log.marks if m.label == label]
    names = [m.label for m in log.marks]
    if not found:
        raise TeachError("mark not found in session", source=source, field="marks", value=label,
                         expected=f"a mark '{label}' (marks present: "
                                  f"{', '.join(names) if names else 'none'})")
    if len(found) > 1:
        times = ", ".join(f"{m.t:.3f}" for m in found)
        raise TeachError(f"mark pressed {len(found)} times (at {times} s)", source=source,
                         field="marks", value=label, expected="each mark label exactly once")
    check_mark_time(log, found[0], source)
    return found[0]


def check_mark_time(log: SessionLog, mark: SessionEvent, source: str | None = None) -> None:
    """Raise unless a mark lies within the recorded time.

    Raises:
        TeachError: Naming the mark, its time and the recorded interval.
    """
    if not (log.time[0] <= mark.t <= log.time[-1]):
        raise TeachError("mark time outside the recorded time", source=source,
                         field=f"marks.{mark.label}.t", value=mark.t,
                         expected=f"within [{log.time[0]:.3f}, {log.time[-1]:.3f}] s")


def tcp_path(log: SessionLog, robot: Robot, t_from: float, t_to: float,
             source: str | None = None) -> TcpPath:
    """The rows of a session with ``t_from ≤ t ≤ t_to`` and their measured TCP poses.

    Args:
        log: The session (checked with :func:`check_session_robot` beforehand).
        robot: Its robot.
        t_from: Start time [s].
        t_to: End time [s].
        source: Session file, for messages.

    Returns:
        The path (at least one row: the nearest one if the interval holds none).

    Raises:
        TeachError: Non-finite joint positions in the interval.
    """
    rows = np.flatnonzero((log.time >= t_from) & (log.time <= t_to))
    if rows.size == 0:
        mid = 0.5 * (t_from + t_to)
        rows = np.array([int(np.argmin(np.abs(log.time - mid)))])
    q = log.q[rows]
    bad = np.flatnonzero(~np.all(np.isfinite(q), axis=1))
    if bad.size:
        raise TeachError("non-finite joint position", source=source,
                         field=f"q (row {int(rows[bad[0]])})",
                         expected="finite measured joint positions on the taught path")
    pos, quat = forward_tcp(robot, q)
    return TcpPath(sample=rows.astype(np.int64), time=log.time[rows].copy(), q=q.copy(),
                   tcp_position_base=pos, tcp_quat_xyzw=quat)
