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
from leadthrough.teach.programs.grammar import (
    COMMENT_CHARSET,
    Rule,
    Statement,
    comment_text,
    read_statements,
)
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    APPROACH_PERCENT,
    ProgramOptions,
    ProgramTarget,
    axis_merge,
    axis_split,
    canonical_deg,
    check_writer_inputs,
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
    """Remark texts: no ``;`` (it ends a TP statement), at most 32 characters each, only
    characters of a comment (others written as ``?``)."""
    out: list[str] = []
    for line in lines:
        out += textwrap.wrap(comment_text(line.replace(";", ","), exclude=";"), 32) or [""]
    return out


def render_tp(targets: list[ProgramTarget], configs: list[FanucConfig | None],
              options: ProgramOptions, header: list[str]) -> dict[str, str]:
    """The program as ``{".ls": text}``; arguments as
    :attr:`leadthrough.teach.programs.Language.render`.

    Raises:
        TeachError: A label, name or number the program cannot hold
            (:func:`~leadthrough.teach.programs.targets.check_writer_inputs`).
    """
    check_writer_inputs(targets, options, "tp")
    tool = [fmt(v, 3) for v in xyzabc(options.tool)]
    units = ("mm", "mm", "mm", "deg", "deg", "deg")
    tool_lines = [f"UT1 {k} = {v} {u}" for k, v, u in zip("XYZABC", tool, units, strict=True)]
    mn = [f"! {c} ;" for c in [*_remarks(header), *tool_lines]]
    mn += ["UFRAME_NUM=0 ;", "UTOOL_NUM=1 ;"]
    pos: list[str] = []
    speed = fmt(1e3 * options.speed_m_s, 0)
    for i, (t, cfg) in enumerate(zip(targets, configs, strict=True), start=1):
        term = "FINE" if t.exact else f"CNT{options.fanuc_cnt}"
        mn += [f"! {part} ;" for part in t.label.split("/") if part]  # ≤ 32 characters each
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


_N = r"-?\d+\.\d+"  # the fixed-point numbers we write
_K = r" {0,3}(?P<k>\d+):"
_ATTR = {"0": "OWNER\t\t= MNEDITOR;", "2": "PROG_SIZE\t= 0;", "4": "VERSION\t\t= 0;",
         "6": "MEMORY_SIZE\t= 0;", "7": "PROTECT\t\t= READ_WRITE;",
         "8": "TCD:  STACK_SIZE\t= 0,", "9": "      TASK_PRIORITY\t= 50,",
         "A": "      TIME_SLICE\t= 0,", "B": "      BUSY_LAMP_OFF\t= 0,",
         "C": "      ABORT_REQUEST\t= 0,", "D": "      PAUSE_REQUEST\t= 0;",
         "E": "DEFAULT_GROUP\t= 1,*,*,*,*;", "F": "CONTROL_CODE\t= 00000000 00000000;"}
_ATTR_CODES = "0123456789ABCDEF"  # the /ATTR lines in order (1, 3, 5: COMMENT, FILE_NAME,
#                                   LINE_COUNT)
_RULES = [
    Rule.of("p", r"/PROG  (?P<name>[A-Za-z][A-Za-z0-9_]*)", "/PROG"),
    Rule.of("a", r"/ATTR", "/ATTR"),
    *(Rule.of(c, re.escape(text), "/ATTR line") for c, text in _ATTR.items()),
    Rule.of("1", r'COMMENT\t\t= "(?P<comment>[A-Za-z0-9 _]{0,16})";', "COMMENT"),
    Rule.of("3", r"FILE_NAME\t= (?P<name>[A-Za-z][A-Za-z0-9_]*);", "FILE_NAME"),
    Rule.of("5", r"LINE_COUNT\t= (?P<count>\d+);", "LINE_COUNT"),
    Rule.of("m", r"/MN", "/MN"),
    Rule.of("r", rf"{_K}  ! (?P<text>[{COMMENT_CHARSET.replace(';', '')}]{{0,32}}) ;", "remark"),
    Rule.of("f", rf"{_K}  UFRAME_NUM=0 ;", "UFRAME_NUM"),
    Rule.of("g", rf"{_K}  UTOOL_NUM=1 ;", "UTOOL_NUM"),
    Rule.of("J", rf"{_K}J P\[(?P<i>\d+)\] \d{{1,3}}% (?:FINE|CNT\d{{1,3}}) ;", "joint move"),
    Rule.of("L", rf"{_K}L P\[(?P<i>\d+)\] \d+mm/sec (?:FINE|CNT\d{{1,3}}) ;", "linear move"),
    Rule.of("s", r"/POS", "/POS"), Rule.of("P", r"P\[(?P<i>\d+)\]\{", "position"),
    Rule.of("G", r"   GP1:", "GP1"), Rule.of("u", r"\tUF : 0, UT : 1,", "frames"),
    Rule.of("U", r"\tUF : 0, UT : 1,\t\tCONFIG : '(?P<f>[FN]) (?P<u>[UD]) (?P<t>[TB]), "
                 r"(?P<t1>-?\d), (?P<t4>-?\d), (?P<t6>-?\d)',", "frames and configuration"),
    Rule.of("j", rf"\tJ1= +(?P<J1>{_N}) deg,\tJ2= +(?P<J2>{_N}) deg,\tJ3= +(?P<J3>{_N}) deg,",
            "J1-J3"),
    Rule.of("k", rf"\tJ4= +(?P<J4>{_N}) deg,\tJ5= +(?P<J5>{_N}) deg,\tJ6= +(?P<J6>{_N}) deg",
            "J4-J6"),
    Rule.of("K", rf"\tJ4= +(?P<J4>{_N}) deg,\tJ5= +(?P<J5>{_N}) deg,\tJ6= +(?P<J6>{_N}) deg,",
            "J4-J6"),
    Rule.of("e", rf"\tE1= +(?P<E1>{_N}) deg", "E1"),
    Rule.of("x", rf"\tX = +(?P<X>{_N})  mm,\tY = +(?P<Y>{_N})  mm,\tZ = +(?P<Z>{_N})  mm,",
            "X, Y, Z"),
    Rule.of("w", rf"\tW = +(?P<W>{_N}) deg,\tP = +(?P<P>{_N}) deg,\tR = +(?P<R>{_N}) deg",
            "W, P, R"),
    Rule.of("z", r"\};", "end of position"), Rule.of("Z", r"/END", "/END"),
]
#: /PROG, /ATTR, /MN: remarks, frames, a joint move first, moves; /POS: positions; /END
_ORDER = [*((c, False) for c in "pa" + _ATTR_CODES + "m"), ("r", True), ("f", False),
          ("g", False), ("r*J", False), ("r*[JL]", True), ("s", False),
          ("PG(?:ujk|ujKe|Uxw)z", True), ("Z", False)]
_TOOL_REMARK = re.compile(rf"UT1 (?P<key>[XYZABC]) = (?P<v>{_N}) (?:mm|deg)")


def _values(s: Statement) -> dict[str, float]:
    return {k: float(v) for k, v in s.match.groupdict().items() if k.isupper()}


def _tp_pose(v: list[float]) -> pin.SE3:
    rot = Rotation.from_euler("xyz", v[3:6], degrees=True).as_matrix()
    return pin.SE3(rot, 1e-3 * np.asarray(v[:3]))


def _check_mn(statements: list[Statement]) -> pin.SE3:
    """Line numbers 1 … n, LINE_COUNT, names; the tool of the UT1 remarks."""
    by = {s.code: s for s in statements if s.code in "p135"}
    name = by["p"].match.group("name")
    mn = [s for s in statements if s.code in "rfgJL"]
    checks = [("FILE_NAME", by["3"].match.group("name"), name),
              ("COMMENT", by["1"].match.group("comment"), f"leadthrough {name}"[:16]),
              ("LINE_COUNT", int(by["5"].match.group("count")), len(mn))]
    checks += [(f"line {s.line}", int(s.match.group("k")), k)
               for k, s in enumerate(mn, start=1)]
    for field, value, expected in checks:
        if value != expected:
            raise TeachError("a value the program writer does not write", source=".ls",
                             field=field, value=value, expected=str(expected))
    header = mn[:mn.index(next(s for s in mn if s.code == "f"))]
    tool = {m.group("key"): float(m.group("v")) for m in
            (_TOOL_REMARK.fullmatch(s.match.group("text")) for s in header[-6:]) if m}
    if list(tool) != list("XYZABC"):
        raise TeachError("the tool remarks are missing", source=".ls", field="/MN",
                         expected="UT1 X, Y, Z, A, B, C as the last six remarks before "
                                  "UFRAME_NUM")
    return tool_from_xyzabc([tool[k] for k in "XYZABC"])


def _blocks(statements: list[Statement]) -> list[tuple[dict[str, float], re.Match[str] | None]]:
    """Each position P[1], P[2], … in order: (values, CONFIG line or None for the joint
    representation)."""
    out: list[tuple[dict[str, float], re.Match[str] | None]] = []
    values: dict[str, float] = {}
    config: re.Match[str] | None = None
    for s in statements[statements.index(next(s for s in statements if s.code == "s")):]:
        if s.code == "P":
            if s.match.group("i") != str(len(out) + 1):
                raise TeachError("a position out of the order the program writer declares",
                                 source=".ls", field=f"line {s.line}", value=s.match.group(0),
                                 expected=f"P[{len(out) + 1}]")
            values, config = {}, None
        elif s.code == "U":
            config = s.match
        elif s.code == "z":
            out.append((values, config))
        values.update(_values(s))
    return out


def parse_tp(files: dict[str, str]) -> ParsedProgram:
    """The moves, tool and name of a TP program, read strictly: every line must be a
    statement :func:`render_tp` writes, in its order, with the line numbers, LINE_COUNT and
    names it writes; the moves go to P[1], P[2], … in order, each once, a ``J`` to a joint
    position, an ``L`` to a position with configuration.

    Raises:
        TeachError: A line, statement order, value or position the writer does not emit
            (naming the line).
    """
    statements = read_statements(files[".ls"], _RULES, _ORDER, ".ls")
    tool = _check_mn(statements)
    blocks = _blocks(statements)
    moves: list[ParsedMove] = []
    for s in (s for s in statements if s.code in "JL"):
        i = len(moves) + 1
        if s.match.group("i") != str(i) or i > len(blocks) \
                or (blocks[i - 1][1] is None) != (s.code == "J"):
            raise TeachError("a move to another position than the program writer's",
                             source=".ls", field=f"line {s.line}", value=s.match.group(0),
                             expected=f"P[{i}], declared in /POS in the move's representation")
        v, m = blocks[i - 1]
        if m is None:
            extra = [v["E1"]] if "E1" in v else []
            moves.append(ParsedMove(q_deg=axis_merge([v[f"J{j}"] for j in range(1, 7)], extra)))
        else:
            cfg = FanucConfig(m.group("f") == "F", m.group("u") == "U", m.group("t") == "T",
                              (int(m.group("t1")), int(m.group("t4")), int(m.group("t6"))))
            moves.append(ParsedMove(pose=_tp_pose([v[k] for k in "XYZWPR"]), config=cfg))
    if len(moves) != len(blocks):
        raise TeachError("a position no move goes to", source=".ls", field="/POS",
                         value=f"P[{len(moves) + 1}]", expected="one move to each position")
    return ParsedProgram(tuple(moves), tool, statements[0].match.group("name"))

