"""Check a taught waypoint path against the robot's joint position and speed limits at a
programmed speed, before it is exported.

Timing model of a program (per segment k−1 → k): the TCP moves at the programmed linear speed
v_prog [m/s] and turns at most at the programmed orientation speed ω_prog [rad/s], so the segment
takes T_k = max(L_k / v_prog, θ_k / ω_prog), L_k the segment length and θ_k the rotation angle
between the two waypoint orientations. The joint speeds it needs are |Δq_k| / T_k [rad/s] (the
mean over the segment, a lower bound of the peak a controller with blends will need), compared
with the robot's joint velocity limits (``velocity_limit`` of the robot TOML). Waypoint joint
positions must lie within the position limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.robot.description import Robot

__all__ = ["LimitReport", "LimitViolation", "check_limits", "limit_report"]

Array = NDArray[np.float64]

_Q_TOL = 1e-9  # [rad] rounding slack on the position limits
_DEFAULT_ORIENTATION_SPEED = 0.5  # [rad/s] ≈ 29 °/s, programmed reorientation speed


@dataclass(frozen=True)
class LimitViolation:
    """One waypoint outside a limit.

    Attributes:
        kind: ``"position"`` (joint position of a waypoint) or ``"speed"`` (joint speed needed
            on the segment that ends at the waypoint).
        waypoint: Waypoint index (0-based).
        label: Waypoint label (mark name) or ``""``.
        joint: Joint index (0-based).
        joint_name: Joint name.
        value: Offending joint position [rad] or needed joint speed [rad/s].
        limit: Exceeded limit [rad] or [rad/s].
        max_speed_m_s: For ``"speed"``: highest programmed linear speed at which this segment
            fits (None if the segment's orientation change, not its length, sets its time).
        programmed_speed_m_s: The programmed linear speed [m/s].
    """

    kind: str
    waypoint: int
    label: str
    joint: int
    joint_name: str
    value: float
    limit: float
    max_speed_m_s: float | None
    programmed_speed_m_s: float

    def error(self, source: str | None = None) -> TeachError:
        """The one-line error naming the waypoint, the joint, the value and the limit."""
        where = f"waypoint {self.waypoint}" + (f" ({self.label})" if self.label else "")
        joint = f"joint {self.joint + 1} ({self.joint_name})"
        if self.kind == "position":
            bound = (f"≥ {self.limit:.4f} rad (lower position limit)" if self.value < self.limit
                     else f"≤ {self.limit:.4f} rad (upper position limit)")
            return TeachError(f"{where}: {joint} is outside its position limits", source=source,
                              field=f"waypoints[{self.waypoint}].q{self.joint + 1}",
                              value=round(self.value, 6), expected=bound)
        if not math.isfinite(self.value):
            return TeachError(f"{where}: {joint} moves between waypoints {self.waypoint - 1} and "
                              f"{self.waypoint} with the TCP pose unchanged", source=source,
                              field=f"waypoints[{self.waypoint}].q{self.joint + 1}",
                              expected="no configuration change without TCP motion")
        fix = (f"program at most {self.max_speed_m_s:.4f} m/s"
               if self.max_speed_m_s is not None else "lower the orientation speed")
        return TeachError(f"{where}: {joint} needs {self.value:.4f} rad/s on segment "
                          f"{self.waypoint - 1}->{self.waypoint} at "
                          f"{self.programmed_speed_m_s:g} m/s", source=source,
                          field=f"waypoints[{self.waypoint}].qd{self.joint + 1}",
                          value=round(self.value, 6),
                          expected=f"≤ {self.limit:.4f} rad/s joint velocity limit; {fix}")


@dataclass(frozen=True)
class LimitReport:
    """Timing and limit figures of a waypoint path at the programmed speed.

    Attributes:
        programmed_speed_m_s: Linear TCP speed v_prog [m/s].
        orientation_speed_rad_s: Orientation speed ω_prog [rad/s].
        segment_length_m: TCP distance of each segment [m], shape (K−1,).
        segment_rotation_rad: Orientation change of each segment [rad], shape (K−1,).
        segment_time_s: Duration of each segment [s], shape (K−1,).
        joint_speed_rad_s: Mean joint speeds needed [rad/s], shape (K−1, n) (inf for a joint
            motion with no TCP motion).
        speed_ratio: ``joint_speed_rad_s`` / velocity limit, shape (K−1, n).
        max_speed_ratio: Largest entry of ``speed_ratio`` (0 for fewer than 2 waypoints).
        program_duration_s: Sum of the segment times [s].
        violations: Position violations (waypoint order), then speed violations.
    """

    programmed_speed_m_s: float
    orientation_speed_rad_s: float
    segment_length_m: Array
    segment_rotation_rad: Array
    segment_time_s: Array
    joint_speed_rad_s: Array
    speed_ratio: Array
    max_speed_ratio: float
    program_duration_s: float
    violations: tuple[LimitViolation, ...]

    @property
    def ok(self) -> bool:
        """True if no waypoint violates a limit."""
        return not self.violations


def _rotation_angles(quat_xyzw: Array) -> Array:
    dots = np.abs(np.sum(quat_xyzw[1:] * quat_xyzw[:-1], axis=1))
    norms = np.linalg.norm(quat_xyzw[1:], axis=1) * np.linalg.norm(quat_xyzw[:-1], axis=1)
    return np.asarray(2.0 * np.arccos(np.clip(dots / norms, 0.0, 1.0)))


def limit_report(q: Array, tcp_position_base: Array, tcp_quat_xyzw: Array, robot: Robot,
                 speed_m_s: float = 0.1, *,
                 orientation_speed_rad_s: float = _DEFAULT_ORIENTATION_SPEED,
                 labels: Sequence[str] | None = None) -> LimitReport:
    """Timing of a waypoint path and every limit it violates (does not raise for violations).

    Args:
        q: Waypoint joint positions [rad], shape (K, n).
        tcp_position_base: Waypoint TCP positions, base frame [m], shape (K, 3).
        tcp_quat_xyzw: Waypoint TCP orientations, quaternions (x, y, z, w), shape (K, 4).
        robot: The robot (position limits, ``velocity_limit`` [rad/s], joint names).
        speed_m_s: Programmed linear TCP speed v_prog [m/s], > 0.
        orientation_speed_rad_s: Programmed orientation speed ω_prog [rad/s], > 0.
        labels: Waypoint labels for messages (K strings), or None.

    Returns:
        The report.

    Raises:
        TeachError: Non-positive or non-finite speeds, or arrays of inconsistent shapes.
    """
    for name, v, unit in (("speed_m_s", speed_m_s, "m/s"),
                          ("orientation_speed_rad_s", orientation_speed_rad_s, "rad/s")):
        if not (math.isfinite(v) and v > 0.0):
            raise TeachError("out of range", field=name, value=v,
                             expected=f"a finite programmed speed > 0 {unit}")
    q = np.atleast_2d(np.asarray(q, dtype=float))
    pos = np.atleast_2d(np.asarray(tcp_position_base, dtype=float))
    quat = np.atleast_2d(np.asarray(tcp_quat_xyzw, dtype=float))
    k = q.shape[0]
    if q.shape[1] != robot.n or pos.shape != (k, 3) or quat.shape != (k, 4):
        raise TeachError("inconsistent waypoint arrays", field="waypoints",
                         value=(q.shape, pos.shape, quat.shape),
                         expected=f"shapes (K, {robot.n}), (K, 3), (K, 4)")
    names = list(labels) if labels is not None else [""] * k
    lo, hi, vmax = robot.lower_limits, robot.upper_limits, robot.velocity_limit
    violations: list[LimitViolation] = []
    for i in range(k):
        for j in range(robot.n):
            if q[i, j] < lo[j] - _Q_TOL or q[i, j] > hi[j] + _Q_TOL:
                violations.append(LimitViolation(
                    "position", i, names[i], j, robot.joint_names[j], float(q[i, j]),
                    float(lo[j] if q[i, j] < lo[j] else hi[j]), None, speed_m_s))
    length = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    angle = _rotation_angles(quat) if k > 1 else np.zeros(0)
    t_lin, t_rot = length / speed_m_s, angle / orientation_speed_rad_s
    seg_t = np.maximum(t_lin, t_rot)
    dq = np.abs(np.diff(q, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(dq <= _Q_TOL, 0.0, dq / seg_t[:, None])
    ratio = speed / vmax
    for s in range(k - 1):
        for j in range(robot.n):
            if ratio[s, j] > 1.0:
                t_need = dq[s, j] / vmax[j]
                v_ok = float(length[s] / t_need) if t_lin[s] >= t_rot[s] and length[s] > 0 \
                    else None
                violations.append(LimitViolation(
                    "speed", s + 1, names[s + 1], j, robot.joint_names[j], float(speed[s, j]),
                    float(vmax[j]), v_ok, speed_m_s))
    return LimitReport(
        programmed_speed_m_s=float(speed_m_s),
        orientation_speed_rad_s=float(orientation_speed_rad_s),
        segment_length_m=length, segment_rotation_rad=angle, segment_time_s=seg_t,
        joint_speed_rad_s=speed, speed_ratio=ratio,
        max_speed_ratio=float(ratio.max()) if ratio.size else 0.0,
        program_duration_s=float(seg_t.sum()), violations=tuple(violations))


def check_limits(q: Array, tcp_position_base: Array, tcp_quat_xyzw: Array, robot: Robot,
                 speed_m_s: float = 0.1, *,
                 orientation_speed_rad_s: float = _DEFAULT_ORIENTATION_SPEED,
                 labels: Sequence[str] | None = None, source: str | None = None) -> LimitReport:
    """Like :func:`limit_report`, but raise for the first violation.

    Args:
        q: Waypoint joint positions [rad], shape (K, n).
        tcp_position_base: Waypoint TCP positions, base frame [m], shape (K, 3).
        tcp_quat_xyzw: Waypoint TCP orientations, quaternions (x, y, z, w), shape (K, 4).
        robot: The robot.
        speed_m_s: Programmed linear TCP speed v_prog [m/s], > 0.
        orientation_speed_rad_s: Programmed orientation speed ω_prog [rad/s], > 0.
        labels: Waypoint labels for messages, or None.
        source: Session file, for messages.

    Returns:
        The report (with no violations).

    Raises:
        TeachError: Naming the first offending waypoint (index, label), joint, value and limit:
            position violations first, then joint speeds.
    """
    report = limit_report(q, tcp_position_base, tcp_quat_xyzw, robot, speed_m_s,
                          orientation_speed_rad_s=orientation_speed_rad_s, labels=labels)
    if report.violations:
        raise report.violations[0].error(source)
    return report
