"""ABB RAPID module of a taught path, ``NAME.mod``.

``robtarget`` = [[x, y, z] mm, [q1, q2, q3, q4] quaternion (q1 the scalar part, q1 ≥ 0),
[cf1, cf4, cf6, cfx] ``confdata`` from :func:`~leadthrough.teach.programs.configuration.
abb_config`, external axes 9E9]; moves ``MoveL`` with ``speeddata`` [v_tcp mm/s, v_ori deg/s,
v_leax, v_reax] and ``zonedata`` (``fine`` at the marks and the end); the first move, and every
move in the joint-space variant, is ``MoveAbsJ`` to a ``jointtarget`` [[axes 1–6 deg], [9E9 …]].
``ConfL \\On`` makes the controller check the configuration of each linear move. Tool: ABB's
``tool0`` (the flange) when the program's TCP is the robot file's, else a ``tooldata`` whose load
must be set on the controller (the taught path does not know the tool's mass).

Syntax: ABB "Technical reference manual — RAPID Instructions, Functions and Data types"
(``MoveL``, ``MoveAbsJ``, ``ConfL``, ``robtarget``, ``jointtarget``, ``confdata``,
``speeddata``, ``zonedata``, ``tooldata``); the subset matches public RAPID modules
(``ros-industrial/abb`` ``abb_driver/rapid/ROS_motion.mod``; the RAPID output of ``visose/Robots``,
``src/Robots/Manufacturers/ABB/Rapid.cs``).
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin

from leadthrough.errors import TeachError
from leadthrough.teach.programs.configuration import AbbConfig
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    ProgramOptions,
    ProgramTarget,
    axis_merge,
    axis_split,
    canonical_sign,
    fmt,
)

__all__ = ["parse_rapid", "render_rapid"]

_EXT = "[9E9,9E9,9E9,9E9,9E9,9E9]"


def _pose(p: pin.SE3) -> str:
    x, y, z, w = pin.Quaternion(p.rotation).coeffs()
    quat = canonical_sign(np.array([w, x, y, z]))  # q1 ≥ 0; at q1 = 0 the first non-zero > 0
    pos = ",".join(fmt(v, 4) for v in 1e3 * p.translation)
    return f"[{pos}],[{','.join(fmt(v, 8) for v in quat)}]"


def _joints(q: np.ndarray) -> str:
    main, extra = axis_split(q, "RAPID")
    ext = [fmt(v, 4) for v in extra] + ["9E9"] * (6 - len(extra))
    return f"[[{','.join(fmt(v, 4) for v in main)}],[{','.join(ext)}]]"


def _tool(options: ProgramOptions) -> tuple[str, list[str]]:
    if options.tool.isIdentity():
        return "tool0", []
    return "tool_lt", [f"PERS tooldata tool_lt:=[TRUE,[{_pose(options.tool)}],"
                       "[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];",
                       "! tool_lt load data are placeholders: set the tool's mass, centre of "
                       "gravity and inertia"]


def render_rapid(targets: list[ProgramTarget], configs: list[AbbConfig | None],
                 options: ProgramOptions, header: list[str]) -> dict[str, str]:
    """The module as ``{".mod": text}``; arguments as
    :attr:`leadthrough.teach.programs.Language.render`."""
    tool, decl = _tool(options)
    r = options.zone_mm
    v_ori = fmt(np.degrees(options.orientation_speed_rad_s), 3)
    decl += [f"CONST speeddata v_lt:=[{fmt(1e3 * options.speed_m_s, 3)},{v_ori},5000,1000];",
             f"CONST zonedata z_lt:=[FALSE,{fmt(r, 3)},{fmt(1.5 * r, 3)},{fmt(1.5 * r, 3)},"
             f"{fmt(0.15 * r, 3)},{fmt(1.5 * r, 3)},{fmt(0.15 * r, 3)}];"]
    moves = ["ConfJ \\On;", "ConfL \\On;"]
    for i, (t, cfg) in enumerate(zip(targets, configs, strict=True), start=1):
        zone = "fine" if t.exact else "z_lt"
        if t.label:
            moves.append(f"! {t.label}")
        if cfg is None:
            decl.append(f"CONST jointtarget j{i}:={_joints(t.q)};")
            speed = "v100" if i == 1 else "v_lt"
            moves.append(f"MoveAbsJ j{i},{speed},{zone},{tool};")
        else:
            decl.append(f"CONST robtarget p{i}:=[{_pose(t.pose)},"
                        f"[{cfg.cf1},{cfg.cf4},{cfg.cf6},{cfg.cfx}],{_EXT}];")
            moves.append(f"MoveL p{i},v_lt,{zone},{tool}\\WObj:=wobj0;")
    lines = [f"MODULE {options.name}", *[f"  ! {h}" for h in header],
             *[f"  {d}" for d in decl], "  PROC main()", *[f"    {m}" for m in moves],
             "  ENDPROC", "ENDMODULE"]
    return {".mod": "\n".join(lines) + "\n"}


_NUM = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"


def _nums(text: str) -> list[float]:
    return [float(v) for v in re.findall(_NUM, text)]


def _se3(pos: list[float], quat: list[float]) -> pin.SE3:
    q = pin.Quaternion(quat[0], quat[1], quat[2], quat[3])  # w, x, y, z
    q.normalize()
    return pin.SE3(q.matrix(), 1e-3 * np.asarray(pos))


def parse_rapid(files: dict[str, str]) -> ParsedProgram:
    """The moves and tool of a RAPID module in the subset :func:`render_rapid` writes.

    Raises:
        TeachError: A move to an undeclared target, or a malformed target.
    """
    text = files[".mod"]
    robt = {m.group(1): _nums(m.group(2)) for m in re.finditer(
        r"robtarget\s+(\w+)\s*:=\s*\[(.*?)\]\s*;", text)}
    joint = {m.group(1): _nums(m.group(2)) for m in re.finditer(
        r"jointtarget\s+(\w+)\s*:=\s*\[(.*?)\]\s*;", text)}
    tool = pin.SE3.Identity()
    m_tool = re.search(r"tooldata\s+tool_lt\s*:=\s*\[TRUE,\[\[(.*?)\],\[(.*?)\]\]", text)
    if m_tool:
        tool = _se3(_nums(m_tool.group(1)), _nums(m_tool.group(2)))
    moves = []
    for m in re.finditer(r"^\s*(MoveL|MoveAbsJ)\s+(\w+)", text, flags=re.MULTILINE):
        name = m.group(2)
        if m.group(1) == "MoveAbsJ" and name in joint:
            ext = [v for v in joint[name][6:7] if abs(v) < 9e8]
            moves.append(ParsedMove(q_deg=axis_merge(joint[name][:6], ext)))
        elif m.group(1) == "MoveL" and name in robt and len(robt[name]) >= 11:
            v = robt[name]
            cfg = AbbConfig(*(int(c) for c in v[7:11]))
            moves.append(ParsedMove(pose=_se3(v[:3], v[3:7]), config=cfg))
        else:
            raise TeachError("move to an undeclared or malformed target", field=m.group(1),
                             value=name, expected="a target declared in the module")
    return ParsedProgram(tuple(moves), tool)
