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

import re

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from leadthrough.errors import TeachError
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    APPROACH_JOINT_SPEED,
    ProgramOptions,
    ProgramTarget,
    canonical_sign,
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
    :attr:`leadthrough.teach.programs.Language.render`."""
    if targets[0].q.size != 6:
        raise TeachError("a UR controller drives six joints", field="robot",
                         value=f"{targets[0].q.size} joints", expected="6 joints for URScript")
    lines = [f"# {h}" for h in header]
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


_NUM = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
_LIST = rf"\[\s*({_NUM}(?:\s*,\s*{_NUM})*)\s*\]"


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def _se3(values: list[float]) -> pin.SE3:
    return pin.SE3(Rotation.from_rotvec(values[3:6]).as_matrix(), np.array(values[:3]))


def parse_urscript(files: dict[str, str]) -> ParsedProgram:
    """The moves and TCP of a URScript program in the subset :func:`render_urscript` writes.

    Raises:
        TeachError: A pose or joint list that is not 6 numbers.
    """
    text = files[".script"]
    moves: list[ParsedMove] = []
    tool = pin.SE3.Identity()
    for m in re.finditer(rf"\b(set_tcp|movel|movej)\(\s*(p?){_LIST}", text):
        values = _floats(m.group(3))
        if len(values) != 6:
            raise TeachError("pose or joint list without 6 values", field=m.group(1),
                             value=m.group(0), expected="6 numbers")
        if m.group(1) == "set_tcp":
            tool = _se3(values)
        elif m.group(2):
            moves.append(ParsedMove(pose=_se3(values)))
        else:
            moves.append(ParsedMove(q_deg=tuple(np.degrees(values))))
    return ParsedProgram(tuple(moves), tool)
