"""FANUC teach pendant program of a taught path, ASCII ``NAME.LS``.

Sections ``/PROG``, ``/ATTR``, ``/MN`` (``L P[i] <speed>mm/sec FINE|CNT<n> ;``, ``J P[i] <n>%
…``), ``/POS`` (``P[i]{ GP1: UF, UT, CONFIG : 'F U T, t1, t4, t6', X, Y, Z [mm], W, P, R
[deg] };`` with R = Rz(R)·Ry(P)·Rx(W), or ``J1 … J6`` [deg] in the joint representation) and
``/END``, as in FANUC's ASCII program listings (FANUC R-30iB HandlingTool operator's manual,
"Program" and "Position data"; public examples: ``ros-industrial/fanuc``
``fanuc_driver/tpe/ros_movesm.ls``, RoboDK's ``Fanuc_R30iA.py`` post-processor, the FANUC output
of ``visose/Robots``). Values have 3 decimals, as the controller lists them. Loading an ``.LS``
on a controller needs FANUC's ASCII upload option (or ROBOGUIDE's MakeTP to compile a ``.TP``).

The user frame is UF 0 (the robot's world = base frame) and the tool UT 1: the controller's tool
frame 1 must hold the TCP this program states in its remarks ``UT1 X = … mm`` … ``UT1 C = … deg``
(X, Y, Z and KUKA-style A, B, C = rotations about z, y, x; FANUC's W, P, R = C, B, A). Remarks
have at most 32 characters and no ``;``. Joint
angles are the robot file's; on a FANUC arm the controller counts J3 relative to the horizontal
(the J2/J3 interaction), which a robot file does not model.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from leadthrough.errors import TeachError
from leadthrough.teach.programs.configuration import FanucConfig
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    APPROACH_PERCENT,
    ProgramOptions,
    ProgramTarget,
    axis_merge,
    axis_split,
    canonical_deg,
    fmt,
    joint_percent,
    tool_from_xyzabc,
    xyzabc,
)

__all__ = ["parse_tp", "render_tp"]


def _wpr(p: pin.SE3) -> tuple[float, ...]:
    w, pp, r = Rotation.from_matrix(p.rotation).as_euler("xyz", degrees=True)
    return (*(1e3 * p.translation), *(canonical_deg(float(v)) for v in (w, pp, r)))


def _pos_block(i: int, t: ProgramTarget, cfg: FanucConfig | None) -> list[str]:
    lines = [f"P[{i}]{{", "   GP1:"]
    if cfg is None:
        main, extra = axis_split(t.q, "FANUC")
        j = [f"{fmt(v, 3):>9}" for v in main]
        e = "".join(f",\n\tE{i + 1}= {fmt(v, 3):>9} deg" for i, v in enumerate(extra))
        lines += ["\tUF : 0, UT : 1,",
                  f"\tJ1= {j[0]} deg,\tJ2= {j[1]} deg,\tJ3= {j[2]} deg,",
                  f"\tJ4= {j[3]} deg,\tJ5= {j[4]} deg,\tJ6= {j[5]} deg{e}"]
    else:
        v = [f"{fmt(x, 3):>9}" for x in _wpr(t.pose)]
        lines += [f"\tUF : 0, UT : 1,\t\tCONFIG : '{cfg.text()}',",
                  f"\tX = {v[0]}  mm,\tY = {v[1]}  mm,\tZ = {v[2]}  mm,",
                  f"\tW = {v[3]} deg,\tP = {v[4]} deg,\tR = {v[5]} deg"]
    return [*lines, "};"]


def _remarks(lines: list[str]) -> list[str]:
    """Remark texts: no ``;`` (it ends a TP statement), at most 32 characters each."""
    out: list[str] = []
    for line in lines:
        out += textwrap.wrap(line.replace(";", ","), 32) or [""]
    return out


def render_tp(targets: list[ProgramTarget], configs: list[FanucConfig | None],
              options: ProgramOptions, header: list[str]) -> dict[str, str]:
    """The program as ``{".ls": text}``; arguments as
    :attr:`leadthrough.teach.programs.Language.render`."""
    tool = [fmt(v, 3) for v in xyzabc(options.tool)]
    units = ("mm", "mm", "mm", "deg", "deg", "deg")
    tool_lines = [f"UT1 {k} = {v} {u}" for k, v, u in zip("XYZABC", tool, units, strict=True)]
    mn = [f"! {c} ;" for c in [*_remarks(header), *tool_lines]]
    mn += ["UFRAME_NUM=0 ;", "UTOOL_NUM=1 ;"]
    pos: list[str] = []
    speed = fmt(1e3 * options.speed_m_s, 0)
    for i, (t, cfg) in enumerate(zip(targets, configs, strict=True), start=1):
        term = "FINE" if t.exact else f"CNT{options.fanuc_cnt}"
        if t.label:
            mn.append(f"! {t.label} ;")
        if cfg is None:
            pct = APPROACH_PERCENT if i == 1 else joint_percent(t.speed_ratio)
            mn.append(f"J P[{i}] {pct}% {term} ;")
        else:
            mn.append(f"L P[{i}] {speed}mm/sec {term} ;")
        pos += _pos_block(i, t, cfg)
    body = [f"{k:4d}:  {line}" if not line.startswith(("J ", "L ")) else f"{k:4d}:{line}"
            for k, line in enumerate(mn, start=1)]
    comment = f"leadthrough {options.name}"[:16]  # a program comment has 16 characters
    attr = ["OWNER\t\t= MNEDITOR;", f'COMMENT\t\t= "{comment}";',
            "PROG_SIZE\t= 0;", f"FILE_NAME\t= {options.name};", "VERSION\t\t= 0;",
            f"LINE_COUNT\t= {len(mn)};", "MEMORY_SIZE\t= 0;", "PROTECT\t\t= READ_WRITE;",
            "TCD:  STACK_SIZE\t= 0,", "      TASK_PRIORITY\t= 50,", "      TIME_SLICE\t= 0,",
            "      BUSY_LAMP_OFF\t= 0,", "      ABORT_REQUEST\t= 0,",
            "      PAUSE_REQUEST\t= 0;", "DEFAULT_GROUP\t= 1,*,*,*,*;",
            "CONTROL_CODE\t= 00000000 00000000;"]
    text = [f"/PROG  {options.name}", "/ATTR", *attr, "/MN", *body, "/POS", *pos, "/END"]
    return {".ls": "\n".join(text) + "\n"}


_NUM = r"-?\d+(?:\.\d*)?"


def _named(block: str, names: tuple[str, ...]) -> list[float]:
    out = []
    for n in names:
        m = re.search(rf"\b{n}\s*=\s*({_NUM})", block)
        if m is None:
            raise TeachError("position value missing", field="/POS", value=n,
                             expected=f"{n} = number")
        out.append(float(m.group(1)))
    return out


def _config(block: str) -> FanucConfig:
    m = re.search(r"CONFIG\s*:\s*'([FN])\s+([UD])\s+([TB])\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*,"
                  r"\s*(-?\d+)\s*'", block)
    if m is None:
        raise TeachError("malformed configuration string", field="/POS CONFIG", value=block,
                         expected="'F|N U|D T|B, t1, t4, t6'")
    return FanucConfig(m.group(1) == "F", m.group(2) == "U", m.group(3) == "T",
                       (int(m.group(4)), int(m.group(5)), int(m.group(6))))


def _tp_pose(v: list[float]) -> pin.SE3:
    rot = Rotation.from_euler("xyz", v[3:6], degrees=True).as_matrix()
    return pin.SE3(rot, 1e-3 * np.asarray(v[:3]))


def parse_tp(files: dict[str, str]) -> ParsedProgram:
    """The moves and tool of a TP program in the subset :func:`render_tp` writes.

    Raises:
        TeachError: A move to an undeclared position, or a malformed position.
    """
    text = files[".ls"]
    blocks = {int(m.group(1)): m.group(2)
              for m in re.finditer(r"P\[(\d+)\]\s*\{(.*?)\};", text, flags=re.DOTALL)}
    tool = pin.SE3.Identity()
    found = [re.search(rf"! UT1 {k} = ({_NUM}) (?:mm|deg) ;", text) for k in "XYZABC"]
    if all(found):
        tool = tool_from_xyzabc([float(m.group(1)) for m in found if m])
    moves = []
    for m in re.finditer(r"^\s*\d+:\s*([JL])\s+P\[(\d+)\]", text, flags=re.MULTILINE):
        block = blocks.get(int(m.group(2)))
        if block is None:
            raise TeachError("move to an undeclared position", field="/MN",
                             value=f"P[{m.group(2)}]", expected="a P[i] in /POS")
        if "CONFIG" in block:
            moves.append(ParsedMove(pose=_tp_pose(_named(block, ("X", "Y", "Z", "W", "P", "R"))),
                                    config=_config(block)))
        else:
            names = tuple(f"J{i}" for i in range(1, 7))
            extra = _named(block, ("E1",)) if re.search(r"\bE1\s*=", block) else []
            moves.append(ParsedMove(q_deg=axis_merge(_named(block, names), extra)))
    return ParsedProgram(tuple(moves), tool)
