"""The targets of a robot program made from a taught path, and the options every language shares.

Program (all languages):

1. a joint move to the first waypoint's taught joints (unambiguous start, at a slow joint speed);
2. linear moves through the simplified waypoints, blended (``zone``) except at the marks and at
   the last target, where the robot stops exactly;
3. the welding line replaces the waypoints between its two marks: one linear move from the fitted
   P1 to the fitted P2 at the programmed speed (orientation of the P1 and P2 waypoints; their
   joints solved from the marks' taught joints, the same configuration). A joint-space program
   cannot move linearly: it gets joint moves through points of the line, as many as keep the
   flange within the RDP tolerance of the line (checked at each segment's middle).

The tool option moves the programmed TCP from the robot file's TCP frame by a fixed offset (a
torch tip): poses are then the tool's, and each program declares that tool. The waypoints and the
welding line are still those of the robot file's TCP frame (where the session measured the
path); with the orientation constant along the seam, as in welding, the tool tip's line is
straight too. For a torch whose tip traced the seam, put the torch in the robot TOML's TCP frame
so that the line is fitted at the tip.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.errors import TeachError
from leadthrough.robot.description import Robot
from leadthrough.robot.inverse_kinematics import newton_pose, pose_of
from leadthrough.teach.limits_check import limit_report
from leadthrough.teach.line_fit import WeldingLine
from leadthrough.teach.program import TaughtProgram
from leadthrough.teach.programs.grammar import (
    NAME_RULES,
    check_program_name,
    check_target_label,
    finite,
)

__all__ = ["APPROACH_JOINT_SPEED", "APPROACH_PERCENT", "ProgramOptions", "ProgramTarget",
           "axis_merge", "axis_split", "canonical_deg", "canonical_sign", "check_writer_inputs",
           "degrees", "fmt", "joint_percent", "program_name", "program_targets",
           "tool_from_xyzabc", "xyzabc"]

Array = NDArray[np.float64]

APPROACH_JOINT_SPEED = 0.25  # [rad/s] URScript joint move to the first target (≈ 14 °/s)
APPROACH_PERCENT = 10  # [% of the joint speed limits] KRL, FANUC joint move to the first target


@dataclass(frozen=True)
class ProgramOptions:
    """Settings of an exported program.

    Attributes:
        name: Program name (a valid identifier of the language; the file's stem).
        speed_m_s: Programmed TCP speed of the linear moves [m/s].
        orientation_speed_rad_s: Programmed reorientation speed [rad/s].
        zone_mm: Blending radius at intermediate waypoints [mm] (0: exact stops everywhere).
        tool: TCP of the program relative to the robot file's TCP frame.
        joint_space: Joint moves to the taught joints instead of linear moves to poses.
        fanuc_cnt: FANUC ``CNT`` value (0–100) at blended waypoints.
    """

    name: str
    speed_m_s: float
    orientation_speed_rad_s: float = 0.5
    zone_mm: float = 1.0
    tool: pin.SE3 = field(default_factory=pin.SE3.Identity)
    joint_space: bool = False
    fanuc_cnt: int = 50


@dataclass(frozen=True)
class ProgramTarget:
    """One move of the program.

    Attributes:
        label: Mark name or "".
        q: Taught (or solved) joint positions [rad], shape (n,).
        pose: Programmed TCP (tool included) in the base frame.
        exact: Stop exactly (marks, first and last target).
        joint_speed_rad_s: Speed of the leading joint on the segment ending here [rad/s].
        speed_ratio: The largest joint speed over its velocity limit on that segment [-] (≤ 1).
    """

    label: str
    q: Array
    pose: pin.SE3
    exact: bool
    joint_speed_rad_s: float
    speed_ratio: float


def fmt(x: float, decimals: int) -> str:
    """A fixed-point number without a negative zero.

    Raises:
        TeachError: ``x`` is not finite (``nan`` or ``inf`` in a program would be read as a
            name).
    """
    text = f"{finite(x, 'number'):.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def canonical_deg(angle: float) -> float:
    """An angle [deg] in (−180°, 180°] (−180° ± 1e-6° written as 180°, below every file's
    decimals)."""
    return angle + 360.0 if angle <= -180.0 + 1e-6 else angle


def xyzabc(pose: pin.SE3) -> tuple[float, ...]:
    """X, Y, Z [mm] and KUKA A, B, C [deg]: R = Rz(A)·Ry(B)·Rx(C)."""
    a, b, c = Rotation.from_matrix(pose.rotation).as_euler("ZYX", degrees=True)
    return (*(1e3 * pose.translation), *(canonical_deg(float(v)) for v in (a, b, c)))


def canonical_sign(v: Array) -> Array:
    """``v`` or ``−v``, whichever has its first entry of magnitude > 1e-9 positive."""
    nz = np.flatnonzero(np.abs(v) > 1e-9)
    return -v if nz.size and v[nz[0]] < 0.0 else v


def tool_from_xyzabc(values: tuple[float, ...] | list[float]) -> pin.SE3:
    """Placement from X, Y, Z [mm] and A, B, C [deg] (KUKA ZYX, R = Rz(A)·Ry(B)·Rx(C))."""
    rot = Rotation.from_euler("ZYX", values[3:6], degrees=True).as_matrix()
    return pin.SE3(rot, 1e-3 * np.asarray(values[:3], dtype=float))


def program_name(stem: str, language: str) -> str:
    """The program name for a file stem (the controllers name a program after its file).

    Raises:
        TeachError: The stem is not a valid name in ``language``.
    """
    pattern, rule = NAME_RULES[language]
    if not re.fullmatch(pattern, stem):
        raise TeachError("output file name is not a valid program name", field="-o",
                         value=stem, expected=f"{language} program name: {rule}")
    return stem.upper() if language == "tp" else stem


def _line_target(robot: Robot, line: WeldingLine, q: Array, end: int) -> tuple[Array, pin.SE3]:
    """Joints and flange pose at a fitted welding line end (orientation of the mark's pose)."""
    goal = pose_of(robot, q)
    goal.translation = np.array(line.p1_base if end == 0 else line.p2_base, dtype=float)
    res = newton_pose(robot, goal, q)
    if not res.converged:
        label = line.start_label if end == 0 else line.end_label
        raise TeachError("the fitted welding line end is not reachable in the taught "
                         "configuration", field=f"welding_line.{label}",
                         value=round(res.error, 6), expected="a reachable line end")
    return res.q, goal


def _split_line(robot: Robot, a: tuple[Array, pin.SE3], b: tuple[Array, pin.SE3],
                tolerance_m: float, depth: int = 0) -> list[tuple[Array, pin.SE3]]:
    """Points along the line a → b (b included) such that joint moves between them keep the
    flange within ``tolerance_m`` of the line at each segment's middle.

    The line moves the position linearly and the orientation by slerp, as a controller's linear
    move does; each point is solved from the joints of the previous one (same configuration).
    """
    (qa, ta), (qb, tb) = a, b
    mid = pin.SE3(ta.rotation @ pin.exp3(0.5 * pin.log3(ta.rotation.T @ tb.rotation)),
                  0.5 * (ta.translation + tb.translation))
    q_lin = 0.5 * (qa + qb)
    deviation = float(np.linalg.norm(pose_of(robot, q_lin).translation - mid.translation))
    if deviation <= tolerance_m or depth >= 10:
        return [b]
    res = newton_pose(robot, mid, q_lin)
    if not res.converged:
        raise TeachError("a point of the welding line is not reachable in the taught "
                         "configuration", field="welding_line", value=round(res.error, 6),
                         expected="a line reachable without a configuration change")
    m = (res.q, mid)
    return (_split_line(robot, a, m, tolerance_m, depth + 1)
            + _split_line(robot, m, b, tolerance_m, depth + 1))


def _mark_index(labels: tuple[str, ...], mark: str) -> int:
    return next(k for k, lab in enumerate(labels) if mark in lab.split("/"))


def _rows(program: TaughtProgram, robot: Robot, tool: pin.SE3,
          joint_space: bool) -> list[tuple[str, Array, pin.SE3, int]]:
    """Label, joints, programmed TCP and waypoint index of each target."""
    w = program.waypoints
    line = program.welding_line
    ends: dict[int, int] = {}
    if line is not None:
        ends = {_mark_index(w.labels, line.start_label): 0,
                _mark_index(w.labels, line.end_label): 1}
    lo, hi = (min(ends), max(ends)) if ends else (-1, -1)
    rows: list[tuple[str, Array, pin.SE3, int]] = []
    for k in range(len(w)):
        if lo < k < hi:
            continue  # the welding line replaces the guided path between its marks
        if line is not None and k in ends:
            q, flange = _line_target(robot, line, w.q[k], ends[k])
            if joint_space and k == hi:  # joint moves along the line, not one across it
                a = (rows[-1][1], rows[-1][2] * tool.inverse())
                for qm, tm in _split_line(robot, a, (q, flange),
                                          1e-3 * program.tolerance_mm)[:-1]:
                    rows.append(("", qm, tm * tool, k))
        else:
            q, flange = w.q[k], pose_of(robot, w.q[k])
        rows.append((w.labels[k], q, flange * tool, k))
    return rows


def program_targets(program: TaughtProgram, robot: Robot, options: ProgramOptions,
                    source: str | None = None) -> list[ProgramTarget]:
    """The moves of the program, checked against the joint limits at the programmed speed.

    Args:
        program: The taught program (waypoints and welding line).
        robot: Its robot.
        options: Tool and speeds.
        source: Session file, for messages.

    Returns:
        The targets, first the start of the path.

    Raises:
        TeachError: A line end that cannot be reached, or a target outside the joint position
            or speed limits (naming the taught waypoint, joint, value and limit).
    """
    rows = _rows(program, robot, options.tool, options.joint_space)
    q_all = np.array([r[1] for r in rows])
    pos = np.array([r[2].translation for r in rows])
    quat = np.array([pin.Quaternion(r[2].rotation).coeffs() for r in rows])
    rep = limit_report(q_all, pos, quat, robot, options.speed_m_s,
                       orientation_speed_rad_s=options.orientation_speed_rad_s,
                       labels=[r[0] for r in rows])
    if rep.violations:  # named by the taught waypoint the target stands for
        first = rep.violations[0]
        raise replace(first, waypoint=rows[first.waypoint][3]).error(source)
    ratio = np.vstack([np.zeros((1, robot.n)), rep.speed_ratio])
    speed = np.vstack([np.zeros((1, robot.n)), rep.joint_speed_rad_s])
    last = len(rows) - 1
    return [ProgramTarget(label=lab, q=q, pose=pose, exact=bool(lab) or i in (0, last),
                          joint_speed_rad_s=float(speed[i].max()),
                          speed_ratio=float(min(1.0, ratio[i].max())))
            for i, (lab, q, pose, _) in enumerate(rows)]


def joint_percent(ratio: float) -> int:
    """A joint move's speed in % of the joint speed limits, at least the ratio needed."""
    return max(1, min(100, math.ceil(100.0 * ratio - 1e-9)))


def degrees(q: Array) -> list[float]:
    """Joint angles [deg]."""
    return [math.degrees(float(v)) for v in q]


def axis_split(q: Array, language: str) -> tuple[list[float], list[float]]:
    """Joint angles [deg] as robot axes 1–6 and extended axes (``E1`` …) of a joint target.

    A 7-axis arm's third joint (the redundant one) is the first extended axis, as KUKA carries an
    LBR's joint 3 as ``E1`` on a KR C controller and ABB carries the IRB 14000's third joint in
    ``eax_a``; the other six are axes 1–6.

    Raises:
        TeachError: Fewer than 6 or more than 7 joints.
    """
    deg = degrees(q)
    if len(deg) == 6:
        return deg, []
    if len(deg) == 7:
        return [deg[0], deg[1], *deg[3:]], [deg[2]]
    raise TeachError(f"a {language} joint target holds 6 robot axes (+ the redundant joint of a "
                     "7-axis arm)", field="robot", value=f"{len(deg)} joints",
                     expected="6 or 7 joints")


def axis_merge(main: list[float], extra: list[float]) -> tuple[float, ...]:
    """Inverse of :func:`axis_split`: joint angles [deg] in the robot's joint order."""
    return tuple(main) if not extra else (main[0], main[1], extra[0], *main[2:])


def check_writer_inputs(targets: list[ProgramTarget], options: ProgramOptions,
                        language: str) -> None:
    """What a program writer embeds, checked before it writes a line: the program name, every
    target's label (mark labels only), finite joints, poses, speeds and zone, the FANUC CNT.

    Raises:
        TeachError: Naming the offending field and value.
    """
    check_program_name(options.name, language)
    if not targets:
        raise TeachError("a program without targets", field="targets", value=0,
                         expected="at least one target")
    for i, t in enumerate(targets):
        check_target_label(t.label, i)
        values = [*np.ravel(t.q), *np.ravel(t.pose.homogeneous), t.joint_speed_rad_s,
                  t.speed_ratio]
        if not all(math.isfinite(float(v)) for v in values):
            raise TeachError(f"target {i}: a non-finite joint, pose or speed",
                             field=f"targets[{i}]", expected="finite numbers")
    for name in ("speed_m_s", "orientation_speed_rad_s"):
        value = finite(getattr(options, name), name)
        if value <= 0.0:
            raise TeachError("out of range", field=name, value=value, expected="> 0")
    if finite(options.zone_mm, "zone_mm") < 0.0:
        raise TeachError("out of range", field="zone_mm", value=options.zone_mm,
                         expected="≥ 0 mm")
    if not np.all(np.isfinite(options.tool.homogeneous)):
        raise TeachError("a non-finite tool", field="tool", expected="finite numbers")
    cnt = options.fanuc_cnt
    if isinstance(cnt, bool) or not isinstance(cnt, int) or not 0 <= cnt <= 100:
        raise TeachError("out of range", field="fanuc_cnt", value=cnt,
                         expected="an integer 0 … 100")
