"""KUKA KRL program of a taught path: ``NAME.src`` (moves) and ``NAME.dat`` (points).

Points are ``E6POS`` (X, Y, Z [mm], A, B, C [deg] with R = Rz(A)·Ry(B)·Rx(C), Status ``S`` and
Turn ``T`` from :func:`~leadthrough.teach.programs.configuration.kuka_config`) moved to with
``LIN``, or ``E6AXIS`` (A1 … A6 [deg]) moved to with ``PTP`` in the joint-space variant; the
first move is always ``PTP`` to the taught joints. Speeds: ``$VEL.CP`` [m/s], ``$VEL.ORI1/2``
[deg/s], PTP speed with ``BAS(#VEL_PTP, %)``; blending ``$APO.CDIS`` [mm] with ``C_DIS``
(``C_PTP`` with ``$APO.CPTP`` [%] for PTP); tool ``$TOOL`` = a ``FRAME`` in the ``.dat``, base
``$BASE = $NULLFRAME`` (poses are in the robot's base frame: the robot root must be the world
origin, KUKA's default ``$ROBROOT``, or set ``$BASE`` to the robot root).

Syntax: KUKA System Software 8.3, Operating and Programming Instructions for System
Integrators (``DEF``/``END``, ``DEFDAT``/``ENDDAT``, ``DECL E6POS``, ``LIN``, ``PTP``,
``BAS (#INITMOV,0)``); the subset matches public KRL programs (``ros-industrial/
kuka_experimental``, ``kuka_kss_hw_interface/krl/KSS_86/Program/ROS/ros_krlptp.src``) and the KRL
output of ``visose/Robots`` (``src/Robots/Manufacturers/KUKA/Krl.cs``). KRL ``REAL`` is single
precision: 4 decimals in mm and degrees.
"""

from __future__ import annotations

import math

import numpy as np

from leadthrough.errors import TeachError
from leadthrough.teach.programs.configuration import KukaConfig
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
    check_writer_inputs,
    fmt,
    joint_percent,
    tool_from_xyzabc,
    xyzabc,
)

__all__ = ["parse_krl", "render_krl"]


def _frame(values: tuple[float, ...]) -> str:
    names = ("X", "Y", "Z", "A", "B", "C")
    return ",".join(f"{k} {fmt(v, 4)}" for k, v in zip(names, values, strict=True))


def _axis(q: np.ndarray) -> str:
    main, extra = axis_split(q, "KRL")
    return ",".join([*(f"A{i + 1} {fmt(v, 4)}" for i, v in enumerate(main)),
                     *(f"E{i + 1} {fmt(v, 4)}" for i, v in enumerate(extra))])


def render_krl(targets: list[ProgramTarget], configs: list[KukaConfig | None],
               options: ProgramOptions, header: list[str]) -> dict[str, str]:
    """The program as ``{".src": text, ".dat": text}``; arguments as
    :attr:`leadthrough.teach.programs.Language.render`.

    Raises:
        TeachError: A label, name or number the program cannot hold
            (:func:`~leadthrough.teach.programs.targets.check_writer_inputs`).
    """
    check_writer_inputs(targets, options, "krl")
    name = options.name
    dat = ["&ACCESS RVP", "&REL 1", f"DEFDAT {name} PUBLIC",
           *[f"; {comment_text(h)}" for h in header],
           f"DECL FRAME TOOL_LT={{{_frame(xyzabc(options.tool))}}}"]
    src = ["&ACCESS RVP", "&REL 1", f"DEF {name}( )", "BAS (#INITMOV,0)", "$BASE=$NULLFRAME",
           "$TOOL=TOOL_LT", f"$VEL.CP={fmt(options.speed_m_s, 4)}",
           f"$VEL.ORI1={fmt(math.degrees(options.orientation_speed_rad_s), 4)}",
           f"$VEL.ORI2={fmt(math.degrees(options.orientation_speed_rad_s), 4)}",
           f"$APO.CDIS={fmt(options.zone_mm, 4)}", "$APO.CPTP=50",
           f"BAS (#VEL_PTP,{APPROACH_PERCENT})"]
    for i, (t, cfg) in enumerate(zip(targets, configs, strict=True)):
        point = f"XP{i + 1}"
        if t.label:
            src.append(f"; {t.label}")
        if cfg is None:
            dat.append(f"DECL E6AXIS {point}={{{_axis(t.q)}}}")
            if i > 0:
                src.append(f"BAS (#VEL_PTP,{joint_percent(t.speed_ratio)})")
            src.append(f"PTP {point}" + ("" if t.exact else " C_PTP"))
        else:
            dat.append(f"DECL E6POS {point}={{{_frame(xyzabc(t.pose))},S {cfg.status},"
                       f"T {cfg.turn},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
            src.append(f"LIN {point}" + ("" if t.exact else " C_DIS"))
    src.append("END")
    dat.append("ENDDAT")
    return {".src": "\n".join(src) + "\n", ".dat": "\n".join(dat) + "\n"}


_N = r"-?\d+\.\d+"  # the fixed-point numbers we write
_NAME = r"(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
_POINT = r"(?P<point>XP\d+)"
_FRAME = rf"X {_N},Y {_N},Z {_N},A {_N},B {_N},C {_N}"
_SRC_RULES = [
    Rule.of("A", r"&ACCESS RVP", "&ACCESS"), Rule.of("R", r"&REL \d+", "&REL"),
    Rule.of("D", rf"DEF {_NAME}\( \)", "DEF"),
    Rule.of("I", r"BAS \(#INITMOV,0\)", "BAS (#INITMOV)"),
    Rule.of("B", r"\$BASE=\$NULLFRAME", "$BASE"),
    Rule.of("T", r"\$TOOL=(?P<tool>TOOL_LT)", "$TOOL"),
    Rule.of("V", rf"\$VEL\.CP={_N}", "$VEL.CP"), Rule.of("O", rf"\$VEL\.ORI1={_N}", "$VEL.ORI1"),
    Rule.of("o", rf"\$VEL\.ORI2={_N}", "$VEL.ORI2"),
    Rule.of("Z", rf"\$APO\.CDIS={_N}", "$APO.CDIS"), Rule.of("Y", r"\$APO\.CPTP=\d+", "$APO.CPTP"),
    Rule.of("S", r"BAS \(#VEL_PTP,\d{1,3}\)", "BAS (#VEL_PTP)"),
    Rule.of("c", rf"; [{COMMENT_CHARSET}]*", "comment"),
    Rule.of("P", rf"PTP {_POINT}(?: C_PTP)?", "PTP"),
    Rule.of("L", rf"LIN {_POINT}(?: C_DIS)?", "LIN"),
    Rule.of("E", r"END", "END"),
]
#: the settings, a PTP first, then PTP (each after its speed) or LIN, END
_SRC_ORDER = [*((c, False) for c in "ARDIBTVOoZYS"), ("c?P", False), ("c?(?:SP|L)", True),
              ("E", False)]
_DAT_RULES = [
    Rule.of("A", r"&ACCESS RVP", "&ACCESS"), Rule.of("R", r"&REL \d+", "&REL"),
    Rule.of("D", rf"DEFDAT {_NAME} PUBLIC", "DEFDAT"),
    Rule.of("c", rf"; [{COMMENT_CHARSET}]*", "comment"),
    Rule.of("F", rf"DECL FRAME (?P<point>TOOL_LT)=\{{(?P<v>{_FRAME})\}}", "tool FRAME"),
    Rule.of("X", rf"DECL E6AXIS {_POINT}=\{{(?P<v>A1 {_N},A2 {_N},A3 {_N},A4 {_N},A5 {_N},"
                 rf"A6 {_N}(?:,E1 {_N})?)\}}", "E6AXIS"),
    Rule.of("Q", rf"DECL E6POS {_POINT}=\{{(?P<v>{_FRAME},S [0-7],T \d{{1,2}}),E1 0\.0,E2 0\.0,"
                 r"E3 0\.0,E4 0\.0,E5 0\.0,E6 0\.0\}", "E6POS"),
    Rule.of("E", r"ENDDAT", "ENDDAT"),
]
_DAT_ORDER = [("A", False), ("R", False), ("D", False), ("c", True), ("F", False),
              ("[XQ]", True), ("E", False)]


def _fields(body: str) -> dict[str, float]:
    out = {}
    for part in body.split(","):
        key, value = part.split(" ")
        out[key] = float(value)
    return out


def _f32(v: float) -> float:
    """The value as KRL stores a REAL (single precision)."""
    return float(np.float32(v))


def _points(dat: list[Statement]) -> dict[str, tuple[str, dict[str, float]]]:
    """The .dat's points in order (XP1, XP2, … each once after the tool frame)."""
    points: dict[str, tuple[str, dict[str, float]]] = {}
    for s in dat:
        if s.code in "FXQ":
            point = s.match.group("point")
            if s.code != "F" and point != f"XP{len(points)}":
                raise TeachError("a point out of the order the program writer declares",
                                 source=".dat", field=f"line {s.line}", value=point,
                                 expected=f"XP{len(points)}")
            points[point] = (s.code, {k: _f32(v) for k, v in _fields(s.match.group("v")).items()})
    return points


def parse_krl(files: dict[str, str]) -> ParsedProgram:
    """The moves, tool and name of a KRL program, read strictly: every line of the ``.src``
    and the ``.dat`` must be a statement :func:`render_krl` writes, in its order; the moves
    go to XP1, XP2, … in order, each once, a PTP to an ``E6AXIS``, a LIN to an ``E6POS``.

    Values are rounded to single precision, as the controller stores a ``REAL``.

    Raises:
        TeachError: A line, statement order or point the writer does not emit (naming the
            file and line).
    """
    src = read_statements(files[".src"], _SRC_RULES, _SRC_ORDER, ".src")
    dat = read_statements(files[".dat"], _DAT_RULES, _DAT_ORDER, ".dat")
    name = src[2].match.group("name")
    if dat[2].match.group("name") != name:
        raise TeachError("the .dat belongs to another program", source=".dat", field="DEFDAT",
                         value=dat[2].match.group("name"), expected=name)
    points = _points(dat)
    f = points["TOOL_LT"][1]
    tool = tool_from_xyzabc([f[k] for k in ("X", "Y", "Z", "A", "B", "C")])
    moves: list[ParsedMove] = []
    for s in (s for s in src if s.code in "PL"):
        point = s.match.group("point")
        kind, f = points.get(point, ("", {}))
        if point != f"XP{len(moves) + 1}" or kind != {"P": "X", "L": "Q"}[s.code]:
            raise TeachError("a move to another point than the program writer's", source=".src",
                             field=f"line {s.line}", value=s.match.group(0),
                             expected=f"{'PTP' if s.code == 'P' else 'LIN'} XP{len(moves) + 1} "
                                      "to a point of its kind declared in the .dat")
        if kind == "X":
            extra = [f["E1"]] if "E1" in f else []
            moves.append(ParsedMove(q_deg=axis_merge([f[f"A{i}"] for i in range(1, 7)], extra)))
        else:
            pose = tool_from_xyzabc([f[k] for k in ("X", "Y", "Z", "A", "B", "C")])
            moves.append(ParsedMove(pose=pose, config=KukaConfig(int(f["S"]), int(f["T"]))))
    if len(moves) != len(points) - 1:
        raise TeachError("a point no move goes to", source=".dat", field="DECL",
                         value=f"XP{len(moves) + 1}", expected="one move to each point")
    return ParsedProgram(tuple(moves), tool, name)
