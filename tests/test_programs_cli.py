"""``leadthrough teach`` writing robot programs, end to end on a synthetic guiding session.

The session is the seam of tests/test_teach.py (ER20, 0.4 m line with a 2 mm wobble) with four
marks: P0 on the approach, P1 and P2 at the line's ends, P3 on the retreat. Each program file is
read back with its language's parser and solved back with our inverse kinematics, and must give
the joints of the program's targets; the welding line must be one linear move between the fitted
endpoints.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leadthrough.cli import main
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.inverse_kinematics import pose_of
from leadthrough.session_format import SessionEvent, SessionLog, save_session
from leadthrough.teach import teach_session
from leadthrough.teach.programs import LANGUAGES, ProgramOptions, render_robot_program
from leadthrough.teach.programs.parsed import solve_back
from leadthrough.teach.programs.targets import tool_from_xyzabc
from test_programs_syntax import check_lines, check_structure
from test_teach import DT, _assert_fails_cleanly, _log, _make_seam

SUFFIX = {name: lang.suffix for name, lang in LANGUAGES.items()}


@pytest.fixture(scope="module")
def four_marks(er20: Robot, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SessionLog]:
    log, _, _ = _make_seam(er20, 0.002)
    marks = [SessionEvent(0.8, "mark", "P0"), SessionEvent(6.9, "mark", "P3")]
    log = replace(log, events=[*log.events, *marks])
    return save_session(log, tmp_path_factory.mktemp("programs") / "seam.parquet"), log


def _files(out: Path) -> dict[str, str]:
    paths = [out] + ([out.with_suffix(".dat")] if out.suffix == ".src" else [])
    return {p.suffix: p.read_text(encoding="utf-8") for p in paths}


@pytest.mark.parametrize("joint_space", [False, True], ids=["poses", "joints"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_cli_writes_a_program_that_solves_back(
        er20: Robot, four_marks: tuple[Path, SessionLog], tmp_path: Path, language: str,
        joint_space: bool, capsys: pytest.CaptureFixture[str]) -> None:
    session, log = four_marks
    out = tmp_path / f"{'SEAM' if language == 'tp' else 'seam'}{SUFFIX[language]}"
    argv = ["teach", str(session), "-o", str(out), "--tool", "0,0,300,0,0,0", "--json"]
    assert main(argv + (["--joint-space"] if joint_space else [])) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == language and info["round_trip_max_deg"] <= 0.01
    files = _files(out)
    assert sorted(info["files"]) == sorted(str(out.with_suffix(s)) for s in files)
    for suffix, text in files.items():
        check_lines(suffix, text)
    check_structure(files, out.stem)
    program = teach_session(log, er20)
    options = ProgramOptions(name=out.stem, speed_m_s=0.1, joint_space=joint_space,
                             tool=tool_from_xyzabc([0, 0, 300, 0, 0, 0]))
    targets = render_robot_program(program, er20, language, options).targets
    parsed = LANGUAGES[language].parse(files)
    q = solve_back(parsed, er20)
    assert np.degrees(np.abs(q - np.array([t.q for t in targets]))).max() <= 0.01
    labels = [t.label for t in targets]
    assert labels[0] == "P0" and labels[-1] == "P3"
    assert joint_space or labels.index("P2") == labels.index("P1") + 1  # one linear move
    assert np.allclose(parsed.tool.translation, [0.0, 0.0, 0.3])
    line = program.welding_line
    assert line is not None
    if joint_space:  # joint moves along the line stay within the RDP tolerance (1 mm) of it
        i1, i2 = labels.index("P1"), labels.index("P2")
        assert i2 - i1 > 2
        worst = 0.0
        for qa, qb in zip(q[i1:i2], q[i1 + 1:i2 + 1], strict=True):
            for s in np.linspace(0.0, 1.0, 11):
                v = pose_of(er20, (1 - s) * qa + s * qb).translation - line.p1_base
                worst = max(worst, float(np.linalg.norm(v - (v @ line.direction_base)
                                                        * line.direction_base)))
        assert worst < 1e-3
    else:  # the line's ends are the fitted P1, P2 (tool tip 0.3 m along flange z)
        for k, end in ((labels.index("P1"), line.p1_base), (labels.index("P2"), line.p2_base)):
            flange = parsed.moves[k].pose * parsed.tool.inverse()  # type: ignore[operator]
            assert np.linalg.norm(flange.translation - end) < 1e-5  # file decimals


def test_cli_text_summary_and_json_still_default(four_marks: tuple[Path, SessionLog],
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    session, _ = four_marks
    assert main(["teach", str(session), "-o", str(tmp_path / "seam.src")]) == 0
    text = capsys.readouterr().out
    assert "krl solves back to the taught joints within" in text and "seam.dat" in text
    assert (tmp_path / "seam.dat").exists()
    assert main(["teach", str(session), "-o", str(tmp_path / "seam.json"),
                 "--csv", str(tmp_path / "seam.csv")]) == 0
    doc = json.loads((tmp_path / "seam.json").read_text())
    assert doc["format"] == "leadthrough taught path" and (tmp_path / "seam.csv").exists()


def _panda_session(tmp: Path) -> Path:
    panda = load_robot("panda")
    t = np.arange(0.0, 2.0 + DT / 2, DT)
    qa = np.array([0.0, -0.4, 0.1, -2.0, 0.1, 1.6, 0.7])
    q = qa + np.multiply.outer(t / 2.0, np.array([0.2, 0.1, 0.0, 0.2, 0.0, -0.1, 0.0]))
    return save_session(_log(panda, t, q, [(0.2, "P1"), (1.8, "P2")]), tmp / "panda.parquet")


def test_cli_seven_axes_joint_space_only(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    session = _panda_session(tmp_path)
    out = tmp_path / "arm.mod"
    _assert_fails_cleanly(["teach", str(session), "-o", str(out)], tmp_path, capsys,
                          "7-axis arm")
    assert main(["teach", str(session), "-o", str(out), "--joint-space"]) == 0
    assert "rapid solves back" in capsys.readouterr().out
    parsed = LANGUAGES["rapid"].parse({".mod": out.read_text()})
    assert len(parsed.moves[0].q_deg or ()) == 7  # joint 3 in eax_a, not 9E9
    assert re.search(r"jointtarget j1:=\[\[[^\]]*\],\[-?\d+\.\d+,9E9", out.read_text())
    _assert_fails_cleanly(["teach", str(session), "-o", str(tmp_path / "arm.script"),
                           "--joint-space"], tmp_path, capsys, "six joints")


def test_cli_bad_program_options_exit_2_nothing_written(
        four_marks: tuple[Path, SessionLog], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    s = str(four_marks[0])
    src = str(tmp_path / "seam.src")
    cases = [
        (["-o", src, "--format", "tp"], "unsupported output file type"),
        (["-o", str(tmp_path / "1seam.src")], "not a valid program name"),
        (["-o", src, "--zone-mm", "-1"], "--zone-mm"),
        (["-o", src, "--tool", "1,2,3"], "bad tool"),
        (["-o", src, "--tool", "1,2,3,4,5,nan"], "bad tool"),
        (["-o", str(tmp_path / "SEAM.ls"), "--fanuc-cnt", "101"], "--fanuc-cnt"),
        (["-o", src, "--speed", "50"], "joint velocity limit"),
        (["-o", src, "--csv", str(tmp_path / "seam.dat")], "unsupported output file type"),
        (["-o", str(tmp_path / "nope" / "seam.mod")], "output folder does not exist"),
    ]
    for extra, match in cases:
        _assert_fails_cleanly(["teach", s, *extra], tmp_path, capsys, match)
