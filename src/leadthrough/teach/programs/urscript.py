"""URScript program of a taught path (Universal Robots script manual, "Module motion": ``movej``,
``movel``, ``set_tcp``; poses ``p[x, y, z, rx, ry, rz]`` in metres and a rotation vector in
radians; joints in radians; ``a`` acceleration, ``v`` speed, ``r`` blend radius [m]).

``movel`` carries no configuration: the controller solves each pose nearest the current joints
(``get_inverse_kin(x, qnear)``). So the program first moves with ``movej`` to the first
target's taught joints, and each ``movel`` then continues in that configuration. The joint-space
variant uses ``movej`` to every target, at the leading joint's speed of the segment.

Layout follows public URScript programs (a single ``def name(): … end`` as the controller runs
it, e.g. ``UniversalRobots/Universal_Robots_ROS_Driver``
``ur_robot_driver/resources/ros_control.urscript``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from leadthrough.errors import TeachError
from leadthrough.teach.programs.grammar import (
    COMMENT_CHARSET,
    Rule,
    comment_text,
    read_statements,
)
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    APPROACH_JOINT_SPEED,
    ProgramOptions,
    ProgramTarget,
    canonical_sign,
    check_writer_inputs,
    fmt,
)

__all__ = ["parse_urscript", "render_urscript"]

_ACC_LIN = 1.2  # [m/s²] UR's default tool acceleration
_ACC_JOINT = 1.4  # [rad/s²] UR's default joint acceleration


def _pose(p: pin.SE3) -> str:
    rv = Rotation.from_matrix(p.rotation).as_rotvec()
    if abs(float(np.linalg.norm(rv)) - np.pi) < 1e-9:  # a half turn: r and −r are the same
        rv = canonical_sign(rv)
    return "p[" + ", ".join(fmt(v, 6) for v in (*p.translation, *rv)) + "]"


def _joints(q: np.ndarray) -> str:
    return "[" + ", ".join(fmt(float(v), 6) for v in q) + "]"


def render_urscript(targets: list[ProgramTarget], options: ProgramOptions,
                    header: list[str]) -> dict[str, str]:
    """The script as ``{".script": text}``; arguments as
    :attr:`leadthrough.teach.programs.Language.render`.

    Raises:
        TeachError: Not six joints, or a label, name or number the script cannot hold
            (:func:`~leadthrough.teach.programs.targets.check_writer_inputs`).
    """
    check_writer_inputs(targets, options, "urscript")
    if targets[0].q.size != 6:
        raise TeachError("a UR controller drives six joints", field="robot",
                         value=f"{targets[0].q.size} joints", expected="6 joints for URScript")
    lines = [f"# {comment_text(h)}" for h in header]
    lines.append(f"def {options.name}():")
    lines.append(f"  set_tcp({_pose(options.tool)})")
    if targets[0].label:
        lines.append(f"  # {targets[0].label}")
    lines.append(f"  movej({_joints(targets[0].q)}, a={_ACC_JOINT}, v={APPROACH_JOINT_SPEED})")
    blend = 1e-3 * options.zone_mm
    for t in targets[1:]:
        r = fmt(0.0 if t.exact else blend, 4)
        if t.label:
            lines.append(f"  # {t.label}")
        if options.joint_space:
            v = fmt(max(t.joint_speed_rad_s, 1e-3), 4)
            lines.append(f"  movej({_joints(t.q)}, a={_ACC_JOINT}, v={v}, r={r})")
        else:
            lines.append(f"  movel({_pose(t.pose)}, a={_ACC_LIN}, "
                         f"v={fmt(options.speed_m_s, 4)}, r={r})")
    lines.append("end")
    return {".script": "\n".join(lines) + "\n"}


_N = r"-?\d+\.\d+"  # the fixed-point numbers we write
_SIX = rf"(?P<v>{_N}(?:, {_N}){{5}})"
_RULES = [
    Rule.of("h", rf"# [{COMMENT_CHARSET}]*", "header comment"),
    Rule.of("d", r"def (?P<name>[A-Za-z_][A-Za-z0-9_]*)\(\):", "program definition"),
    Rule.of("t", rf"  set_tcp\(p\[{_SIX}\]\)", "set_tcp"),
    Rule.of("c", rf"  # [{COMMENT_CHARSET}]*", "comment"),
    Rule.of("j", rf"  movej\(\[{_SIX}\], a={_N}, v={_N}(?:, r={_N})?\)", "movej"),
    Rule.of("l", rf"  movel\(p\[{_SIX}\], a={_N}, v={_N}, r={_N}\)", "movel"),
    Rule.of("e", r"end", "end"),
]
#: header comments, def and set_tcp, a movej first, movej or movel, end
_ORDER = [("h", True), ("d", False), ("t", False), ("c?j", False), ("c?[jl]", True), ("e", False)]


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def _se3(values: list[float]) -> pin.SE3:
    return pin.SE3(Rotation.from_rotvec(values[3:6]).as_matrix(), np.array(values[:3]))


def parse_urscript(files: dict[str, str]) -> ParsedProgram:
    """The moves, TCP and name of a URScript program, read strictly: every line must be a
    statement :func:`render_urscript` writes, in its order.

    Raises:
        TeachError: A line or statement order the writer does not emit (naming the line).
    """
    statements = read_statements(files[".script"], _RULES, _ORDER, ".script")
    moves: list[ParsedMove] = []
    tool = pin.SE3.Identity()
    name = ""
    for s in statements:
        if s.code == "d":
            name = s.match.group("name")
        elif s.code == "t":
            tool = _se3(_floats(s.match.group("v")))
        elif s.code == "l":
            moves.append(ParsedMove(pose=_se3(_floats(s.match.group("v")))))
        elif s.code == "j":
            moves.append(ParsedMove(q_deg=tuple(np.degrees(_floats(s.match.group("v"))))))
    return ParsedProgram(tuple(moves), tool, name)
