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
from leadthrough.teach.programs.grammar import (
    COMMENT_CHARSET,
    Rule,
    Statement,
    comment_text,
    read_statements,
)
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    ProgramOptions,
    ProgramTarget,
    axis_merge,
    axis_split,
    canonical_sign,
    check_writer_inputs,
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
    :attr:`leadthrough.teach.programs.Language.render`.

    Raises:
        TeachError: A label, name or number the module cannot hold
            (:func:`~leadthrough.teach.programs.targets.check_writer_inputs`).
    """
    check_writer_inputs(targets, options, "rapid")
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
    lines = [f"MODULE {options.name}", *[f"  ! {comment_text(h)}" for h in header],
             *[f"  {d}" for d in decl], "  PROC main()", *[f"    {m}" for m in moves],
             "  ENDPROC", "ENDMODULE"]
    return {".mod": "\n".join(lines) + "\n"}


_N = r"-?\d+\.\d+"  # the fixed-point numbers we write


def _seq(item: str, n: int) -> str:
    return ",".join([item] * n)


_POSE = rf"\[(?P<pos>{_seq(_N, 3)})\],\[(?P<quat>{_seq(_N, 4)})\]"
_TOOL = r"(?P<tool>tool0|tool_lt)"
_RULES = [
    Rule.of("M", r"MODULE (?P<name>[A-Za-z][A-Za-z0-9_]*)", "MODULE"),
    Rule.of("h", rf"  ! [{COMMENT_CHARSET}]*", "comment"),
    Rule.of("t", rf"  PERS tooldata tool_lt:=\[TRUE,\[{_POSE}\],"
                 r"\[0\.001,\[0,0,0\.001\],\[1,0,0,0\],0,0,0\]\];", "tooldata"),
    Rule.of("s", rf"  CONST speeddata v_lt:=\[{_seq(_N, 2)},5000,1000\];", "speeddata"),
    Rule.of("z", rf"  CONST zonedata z_lt:=\[FALSE,{_seq(_N, 6)}\];", "zonedata"),
    Rule.of("j", rf"  CONST jointtarget (?P<target>j\d+):=\[\[(?P<q>{_seq(_N, 6)})\],"
                 rf"\[(?P<ext>{_N}|9E9),9E9,9E9,9E9,9E9,9E9\]\];", "jointtarget"),
    Rule.of("r", rf"  CONST robtarget (?P<target>p\d+):=\[{_POSE},"
                 rf"\[(?P<cf>-?\d+,-?\d+,-?\d+,[0-7])\],\[{_seq('9E9', 6)}\]\];", "robtarget"),
    Rule.of("P", r"  PROC main\(\)", "PROC"), Rule.of("J", r"    ConfJ \\On;", "ConfJ"),
    Rule.of("K", r"    ConfL \\On;", "ConfL"),
    Rule.of("c", rf"    ! [{COMMENT_CHARSET}]*", "comment"),
    Rule.of("A", rf"    MoveAbsJ (?P<target>j\d+),(?:v100|v_lt),(?:fine|z_lt),{_TOOL};",
            "MoveAbsJ"),
    Rule.of("L", rf"    MoveL (?P<target>p\d+),v_lt,(?:fine|z_lt),{_TOOL}\\WObj:=wobj0;",
            "MoveL"),
    Rule.of("E", r"  ENDPROC", "ENDPROC"), Rule.of("N", r"ENDMODULE", "ENDMODULE"),
]
#: MODULE, comments, (tool,) speed, zone, targets, PROC, a MoveAbsJ first, moves, the ends
_ORDER = [("M", False), ("h", True), ("(?:th)?", False), ("s", False), ("z", False),
          ("[jr]", True), ("P", False), ("J", False), ("K", False), ("c?A", False),
          ("c?[AL]", True), ("E", False), ("N", False)]


def _nums(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def _se3(pos: list[float], quat: list[float]) -> pin.SE3:
    q = pin.Quaternion(quat[0], quat[1], quat[2], quat[3])  # w, x, y, z
    q.normalize()
    return pin.SE3(q.matrix(), 1e-3 * np.asarray(pos))


def _targets(statements: list[Statement]) -> dict[str, re.Match[str]]:
    """The declared targets j1/p1, j2/p2, … in order, each number once."""
    out: dict[str, re.Match[str]] = {}
    for s in statements:
        if s.code in "jr":
            target = s.match.group("target")
            if target[1:] != str(len(out) + 1):
                raise TeachError("a target out of the order the program writer declares",
                                 source=".mod", field=f"line {s.line}", value=target,
                                 expected=f"j{len(out) + 1} or p{len(out) + 1}")
            out[target] = s.match
    return out


def parse_rapid(files: dict[str, str]) -> ParsedProgram:
    """The moves, tool and name of a RAPID module, read strictly: every line must be a
    statement :func:`render_rapid` writes, in its order; the moves go to the targets in order,
    each once, with the tool the module declares.

    Raises:
        TeachError: A line, statement order or target the writer does not emit (naming the
            line).
    """
    statements = read_statements(files[".mod"], _RULES, _ORDER, ".mod")
    targets = _targets(statements)
    tool = pin.SE3.Identity()
    tool_name = "tool0"
    for s in statements:
        if s.code == "t":
            tool = _se3(_nums(s.match.group("pos")), _nums(s.match.group("quat")))
            tool_name = "tool_lt"
    moves: list[ParsedMove] = []
    for s in (s for s in statements if s.code in "AL"):
        target = s.match.group("target")
        if target != f"{'j' if s.code == 'A' else 'p'}{len(moves) + 1}" \
                or target not in targets or s.match.group("tool") != tool_name:
            raise TeachError("a move to another target or with another tool than the program "
                             "writer's", source=".mod", field=f"line {s.line}",
                             value=s.match.group(0).strip(),
                             expected=f"target number {len(moves) + 1}, declared in the "
                                      f"module, with {tool_name}")
        m = targets[target]
        if s.code == "A":
            ext = [] if m.group("ext") == "9E9" else [float(m.group("ext"))]
            moves.append(ParsedMove(q_deg=axis_merge(_nums(m.group("q")), ext)))
        else:
            cfg = AbbConfig(*(int(c) for c in m.group("cf").split(",")))
            moves.append(ParsedMove(pose=_se3(_nums(m.group("pos")), _nums(m.group("quat"))),
                                    config=cfg))
    if len(moves) != len(targets):
        raise TeachError("a target no move goes to", source=".mod", field="CONST",
                         value=f"target {len(moves) + 1}", expected="one move to each target")
    return ParsedProgram(tuple(moves), tool, statements[0].match.group("name"))
