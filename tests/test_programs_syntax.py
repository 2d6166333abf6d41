"""Syntax of the program subset each language writes, checked line by line and for structure.

The line grammars below are the subset we emit, written from the languages' references and
checked against the layout of public programs (not committed here):

* KRL: ``ros-industrial/kuka_experimental`` ``kuka_kss_hw_interface/krl/KSS_86/Program/ROS/
  ros_krlptp.src`` (``&ACCESS``/``&REL`` header, ``DEF name ( )``, ``BAS (#INITMOV,0 )``,
  ``PTP … C_PTP``, ``END``) and KUKA-generated ``.dat`` files (``DECL E6POS XP1={X …,Y …,Z …,
  A …,B …,C …,S 6,T 50,E1 0.0,…,E6 0.0}``);
* FANUC TP: ``ros-industrial/fanuc`` ``fanuc_driver/tpe/ros_movesm.ls`` (``/PROG``, ``/ATTR``
  keys, ``/MN`` lines ``   n:  … ;`` and ``   n:J … CNT …;``, ``/POS``, ``/END``) and controller
  listings with ``P[i]{ GP1: UF : 0, UT : 1, CONFIG : 'N U T, 0, 0, 0', X = … mm, … };``;
* RAPID: ``ros-industrial/abb`` ``abb_driver/rapid/ROS_motion.mod`` (``MODULE``, ``PROC
  main()``, ``MoveAbsJ target, speed, zone, tool0;``, ``ENDPROC``, ``ENDMODULE``) and RobotStudio
  modules with ``CONST robtarget p:=[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[9E+09,…]];``;
* URScript: ``UniversalRobots/Universal_Robots_ROS_Driver`` ``ur_robot_driver/resources/
  ros_control.urscript`` (``def name():`` … ``end``) and the script manual's ``movel(p[…], a=…,
  v=…, r=…)``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

N = r"-?\d+\.\d+"  # the fixed-point numbers we write
INT = r"-?\d+"


def _seq(item: str, n: int) -> str:
    return ",".join([item] * n)


KRL_SRC = [r"&ACCESS RVP", r"&REL \d+", r"DEF \w+\( \)", r"BAS \(#INITMOV,0\)",
           r"BAS \(#VEL_PTP,\d+\)", r"\$BASE=\$NULLFRAME", r"\$TOOL=TOOL_LT",
           rf"\$VEL\.CP={N}", rf"\$VEL\.ORI[12]={N}", rf"\$APO\.CDIS={N}", r"\$APO\.CPTP=\d+",
           r"; .*", r"PTP XP\d+( C_PTP)?", r"LIN XP\d+( C_DIS)?", r"END"]
KRL_DAT = [r"&ACCESS RVP", r"&REL \d+", r"DEFDAT \w+ PUBLIC", r"; .*",
           rf"DECL FRAME TOOL_LT=\{{X {N},Y {N},Z {N},A {N},B {N},C {N}\}}",
           rf"DECL E6AXIS XP\d+=\{{A1 {N},A2 {N},A3 {N},A4 {N},A5 {N},A6 {N}(,E1 {N})?\}}",
           rf"DECL E6POS XP\d+=\{{X {N},Y {N},Z {N},A {N},B {N},C {N},S \d,T \d+,"
           r"E1 0\.0,E2 0\.0,E3 0\.0,E4 0\.0,E5 0\.0,E6 0\.0\}", r"ENDDAT"]
TP = [r"/PROG  \w+", r"/ATTR", r"[A-Z_]+\t+= .*;", r"TCD:  STACK_SIZE\t= 0,",
      r"      [A-Z_]+\t= \d+[,;]", r"/MN", r" {0,3}\d+:  ! [^;]* ;",
      r" {0,3}\d+:  U(FRAME|TOOL)_NUM=\d ;",
      r" {0,3}\d+:J P\[\d+\] \d{1,3}% (FINE|CNT\d{1,3}) ;",
      r" {0,3}\d+:L P\[\d+\] \d+mm/sec (FINE|CNT\d{1,3}) ;", r"/POS", r"P\[\d+\]\{", r"   GP1:",
      r"\tUF : 0, UT : 1,", r"\tUF : 0, UT : 1,\t\tCONFIG : '[FN] [UD] [TB], -?\d, -?\d, -?\d',",
      rf"\tJ1= +{N} deg,\tJ2= +{N} deg,\tJ3= +{N} deg,",
      rf"\tJ4= +{N} deg,\tJ5= +{N} deg,\tJ6= +{N} deg,?", rf"\tE1= +{N} deg",
      rf"\tX = +{N}  mm,\tY = +{N}  mm,\tZ = +{N}  mm,",
      rf"\tW = +{N} deg,\tP = +{N} deg,\tR = +{N} deg",
      r"\};", r"/END"]
RAPID = [r"MODULE \w+", r"  ! .*", rf"  CONST speeddata v_lt:=\[{_seq(N, 2)},5000,1000\];",
         rf"  CONST zonedata z_lt:=\[FALSE,{_seq(N, 6)}\];",
         rf"  CONST jointtarget j\d+:=\[\[{_seq(N, 6)}\],\[(({N}|9E9),){{5}}9E9\]\];",
         rf"  CONST robtarget p\d+:=\[\[{_seq(N, 3)}\],\[{_seq(N, 4)}\],\[{_seq(INT, 4)}\],"
         rf"\[{_seq('9E9', 6)}\]\];",
         rf"  PERS tooldata tool_lt:=\[TRUE,\[\[{_seq(N, 3)}\],\[{_seq(N, 4)}\]\],\[.*\]\];",
         r"  PROC main\(\)", r"    Conf[JL] \\On;", r"    ! .*",
         r"    MoveAbsJ j\d+,(v100|v_lt),(fine|z_lt),(tool0|tool_lt);",
         r"    MoveL p\d+,v_lt,(fine|z_lt),(tool0|tool_lt)\\WObj:=wobj0;", r"  ENDPROC",
         r"ENDMODULE"]
URSCRIPT = [r"# .*", r"def \w+\(\):", rf"  set_tcp\(p\[{', '.join([N] * 6)}\]\)", r"  # .*",
            rf"  movej\(\[{', '.join([N] * 6)}\], a={N}, v={N}(, r={N})?\)",
            rf"  movel\(p\[{', '.join([N] * 6)}\], a={N}, v={N}, r={N}\)", r"end"]

GRAMMARS = {".src": KRL_SRC, ".dat": KRL_DAT, ".ls": TP, ".mod": RAPID, ".script": URSCRIPT}


def check_lines(suffix: str, text: str) -> None:
    """Every line matches one rule of the language's subset."""
    rules = [re.compile(r) for r in GRAMMARS[suffix]]
    for k, line in enumerate(text.splitlines(), start=1):
        assert any(r.fullmatch(line) for r in rules), f"{suffix} line {k}: {line!r}"


def _ranges(values: list[float], lo: float, hi: float) -> bool:
    return all(lo <= v <= hi for v in values)


def check_structure(files: dict[str, str], stem: str) -> None:
    """Language-level rules beyond single lines (names, declarations, ranges, counts)."""
    if ".src" in files:
        src, dat = files[".src"], files[".dat"]
        assert re.search(rf"^DEF {stem}\( \)$", src, re.M) and src.rstrip().endswith("END")
        assert re.search(rf"^DEFDAT {stem} PUBLIC$", dat, re.M) and dat.rstrip().endswith("ENDDAT")
        declared = set(re.findall(r"DECL E6(?:POS|AXIS) (XP\d+)", dat))
        assert set(re.findall(r"^(?:PTP|LIN) (XP\d+)", src, re.M)) <= declared
        for s, t in re.findall(r",S (\d+),T (\d+),", dat):
            assert 0 <= int(s) <= 7 and 0 <= int(t) <= 63
        abc = [float(v) for v in re.findall(rf"[ABC] ({N})(?=[,}}])", dat)]
        assert _ranges(abc, -180.0, 180.0)
    if ".ls" in files:
        ls = files[".ls"]
        lines = ls.splitlines()
        assert lines[0] == f"/PROG  {stem.upper()}" and lines[-1] == "/END"
        mn = lines[lines.index("/MN") + 1:lines.index("/POS")]
        assert [int(line.split(":")[0]) for line in mn] == list(range(1, len(mn) + 1))
        assert f"LINE_COUNT\t= {len(mn)};" in ls
        used = set(re.findall(r"[JL] P\[(\d+)\]", "\n".join(mn)))
        assert used <= set(re.findall(r"^P\[(\d+)\]\{", ls, re.M))
        assert all(0 <= int(c) <= 100 for c in re.findall(r"CNT(\d+)", ls))
        assert all(1 <= int(p) <= 100 for p in re.findall(r" (\d+)% ", ls))
    if ".mod" in files:
        mod = files[".mod"]
        assert mod.startswith(f"MODULE {stem}\n") and mod.rstrip().endswith("ENDMODULE")
        for quat in re.findall(rf"\],\[({_seq(N, 4)})\],\[", mod):
            q = [float(v) for v in quat.split(",")]
            assert abs(math.sqrt(sum(v * v for v in q)) - 1.0) < 1e-7 and q[0] >= 0.0
        for cfx in re.findall(rf"\],\[{_seq(INT, 3)},({INT})\],\[9E9", mod):
            assert 0 <= int(cfx) <= 7
    if ".script" in files:
        for rv in re.findall(rf"p\[{_seq(N, 3).replace(',', ', ')}, ({N}), ({N}), ({N})\]",
                             files[".script"]):
            assert float(np.linalg.norm([float(v) for v in rv])) <= math.pi + 1e-6


GOLDEN = Path(__file__).parent / "data" / "programs"


@pytest.mark.parametrize("folder", sorted(p.name for p in GOLDEN.iterdir()))
def test_golden_files_are_in_the_subset(folder: str) -> None:
    files = {p.suffix.lower(): p.read_text(encoding="utf-8")
             for p in (GOLDEN / folder).iterdir()}
    for suffix, text in files.items():
        check_lines(suffix, text)
    check_structure(files, "seam")


def test_grammar_rejects_what_is_not_in_the_subset() -> None:
    bad = {".src": "LIN XP1 C_VEL", ".dat": "DECL E6POS XP1={X 1,Y 2}",
           ".ls": "   1:L P[1] 100mm/sec ;", ".mod": "    MoveL p1 v_lt,fine,tool0;",
           ".script": "  movel(p[0.1, 0.2], a=1.2, v=0.1)"}
    for suffix, line in bad.items():
        with pytest.raises(AssertionError):
            check_lines(suffix, line)
