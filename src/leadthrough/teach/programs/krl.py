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
import re

import numpy as np
import pinocchio as pin

from leadthrough.errors import TeachError
from leadthrough.teach.programs.configuration import KukaConfig
from leadthrough.teach.programs.parsed import ParsedMove, ParsedProgram
from leadthrough.teach.programs.targets import (
    APPROACH_PERCENT,
    ProgramOptions,
    ProgramTarget,
    axis_merge,
    axis_split,
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
    :attr:`leadthrough.teach.programs.Language.render`."""
    name = options.name
    dat = ["&ACCESS RVP", "&REL 1", f"DEFDAT {name} PUBLIC", *[f"; {h}" for h in header],
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


_NUM = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"


def _fields(body: str) -> dict[str, float]:
    out = {}
    for part in body.split(","):
        m = re.fullmatch(rf"\s*([A-Z]\d?)\s+({_NUM})\s*", part)
        if m is None:
            raise TeachError("malformed KRL structure value", field="dat", value=part,
                             expected="NAME number")
        out[m.group(1)] = float(m.group(2))
    return out


def _f32(v: float) -> float:
    """The value as KRL stores a REAL (single precision)."""
    return float(np.float32(v))


def parse_krl(files: dict[str, str]) -> ParsedProgram:
    """The moves and tool of a KRL program in the subset :func:`render_krl` writes.

    Values are rounded to single precision, as the controller stores a ``REAL``.

    Raises:
        TeachError: A move to a point the ``.dat`` does not declare, or a malformed point.
    """
    points: dict[str, tuple[str, dict[str, float]]] = {}
    for m in re.finditer(r"DECL\s+(E6POS|E6AXIS|FRAME)\s+(\w+)\s*=\s*\{([^}]*)\}",
                         files[".dat"]):
        points[m.group(2)] = (m.group(1), {k: _f32(v) for k, v in _fields(m.group(3)).items()})
    tool = pin.SE3.Identity()
    tool_name = re.search(r"\$TOOL\s*=\s*(\w+)", files[".src"])
    if tool_name and tool_name.group(1) in points:
        f = points[tool_name.group(1)][1]
        tool = tool_from_xyzabc([f[k] for k in ("X", "Y", "Z", "A", "B", "C")])
    moves = []
    for m in re.finditer(r"^\s*(PTP|LIN)\s+(\w+)", files[".src"], flags=re.MULTILINE):
        if m.group(2) not in points:
            raise TeachError("move to an undeclared point", field="src", value=m.group(2),
                             expected="a point declared in the .dat")
        kind, f = points[m.group(2)]
        if kind == "E6AXIS":
            extra = [f["E1"]] if "E1" in f else []
            moves.append(ParsedMove(q_deg=axis_merge([f[f"A{i}"] for i in range(1, 7)], extra)))
        else:
            pose = tool_from_xyzabc([f[k] for k in ("X", "Y", "Z", "A", "B", "C")])
            moves.append(ParsedMove(pose=pose, config=KukaConfig(int(f["S"]), int(f["T"]))))
    return ParsedProgram(tuple(moves), tool)
