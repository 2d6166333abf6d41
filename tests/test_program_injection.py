"""Robot-program injection through mark labels, refused at every step.

A mark label used to be copied verbatim into a comment of the TP, RAPID, KRL and URScript
programs, and a newline in it ended the comment: the label ``"W1\\n    SetDO do1, 1;\\n
MoveAbsJ [[0,0,0,0,0,0],...],v5000,fine,tool0;"`` gave a RAPID program with a digital output and
an unchecked full-speed move that still "solved back". Here the attack is replayed:

* through a session file written with :func:`~leadthrough.session_format.save_session` whose
  mark label is then altered in the file's metadata, read by ``leadthrough teach``: exit 2, the
  error names the file, the event's field and the label, nothing is written;
* into each of the four program writers directly: refused;
* as a program text with one foreign statement inserted, or one move removed or added: the
  language's strict reader and the move-by-move comparison reject it;
* as a property (hypothesis): every program written from random valid waypoints and labels
  passes the check, and any single line from a set of foreign statements inserted anywhere in
  it is rejected.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from leadthrough.cli import main
from leadthrough.errors import TeachError
from leadthrough.labels import MAX_LABEL_CHARS, LabelError, is_label
from leadthrough.robot import Robot
from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.inverse_kinematics import pose_of
from leadthrough.session_format import SessionEvent, SessionLog, save_session
from leadthrough.teach import teach_session, write_program_csv, write_program_json
from leadthrough.teach.programs import LANGUAGES, check_program, target_configurations
from leadthrough.teach.programs.round_trip import SINGULARITY_MARGIN_DEG, sample_configurations
from leadthrough.teach.programs.targets import ProgramOptions, ProgramTarget
from test_teach import _make_seam

INJECTION = ("W1\n    SetDO do1, 1;\n    MoveAbsJ [[0,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],"
             "v5000,fine,tool0;")
MARKUP = "<img src=x onerror=alert(1)>"
SUFFIX = {"json": ".json", **{name: lang.suffix for name, lang in LANGUAGES.items()}}
NAMES = {"urscript": "seam", "krl": "seam", "tp": "SEAM", "rapid": "seam"}
#: one foreign statement per language: a digital output, as the attack wrote
DIGITAL_OUT = {"rapid": "    SetDO do1, 1;", "tp": "  13:  DO[1]=ON ;", "krl": "$OUT[1]=TRUE",
               "urscript": "  set_digital_out(1, True)"}
#: foreign statements per language: outputs, waits, inline and extra moves, speed overrides
FOREIGN = {
    "rapid": ["    SetDO do1, 1;", "SetDO do1, 1;", "    WaitTime 1;",
              "    MoveAbsJ [[0,0,0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v5000,fine,tool0;",
              "    MoveAbsJ j1,v100,fine,tool0;", "  CONST speeddata v_lt:=[5000.000,500.000,"
              "5000,1000];", "    ! P1\r    SetDO do1, 1;"],
    "tp": ["DO[1]=ON ;", "  13:  DO[1]=ON ;", "  12:J P[1] 100% FINE ;", "  1:  WAIT 1.00(sec) ;",
           "  10:  ! P1 ;", "P[1]{", "OVERRIDE=100% ;"],
    "krl": ["$OUT[1]=TRUE", "LIN XP1", "PTP XP1", "$VEL.CP=2.0000", "BAS (#VEL_PTP,100)",
            "WAIT SEC 1", "DECL E6AXIS XP9={A1 0.0000,A2 0.0000,A3 0.0000,A4 0.0000,"
            "A5 90.0000,A6 0.0000}", "PTP {A1 0,A2 0,A3 0,A4 0,A5 0,A6 0}"],
    "urscript": ["  set_digital_out(1, True)", "set_digital_out(1, True)", "  sleep(1.0)",
                 "  movej([0.000000, 0.000000, 0.000000, 0.000000, 1.570796, 0.000000], "
                 "a=1.4, v=3.14)", "  movel(p[0.9, 0.0, 1.3, 0.0, 3.14, 0.0], a=1.2, v=1.0, "
                 "r=0.0)", "  textmsg(\"x\")", "def seam():", "end"],
}


# ------------------------------------------------------------------------ the session file
def _alter_labels(src: Path, dst: Path, labels: dict[str, object]) -> Path:
    """Copy of a session file with some mark labels replaced in its metadata (as an editor of
    the file would), and the ``events`` index of the first one replaced."""
    table = pq.read_table(src)
    key = b"leadthrough.session"
    meta = json.loads(table.schema.metadata[key])
    for e in meta["events"]:
        if e["kind"] == "mark" and e["label"] in labels:
            e["label"] = labels[e["label"]]
    pq.write_table(table.replace_schema_metadata({key: json.dumps(meta).encode()}), dst)
    return dst


@pytest.fixture(scope="module")
def session(er20: Robot, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SessionLog]:
    """The seam session with marks P0 (approach), P1, P2 (the line) and P3 (retreat)."""
    log, _, _ = _make_seam(er20, 0.002)
    log = replace(log, events=[*log.events, SessionEvent(0.8, "mark", "P0"),
                               SessionEvent(6.9, "mark", "P3")])
    return save_session(log, tmp_path_factory.mktemp("injection") / "seam.parquet"), log


def _teach_fails(argv: list[str], folder: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``teach``: exit 2, one error line, nothing on stdout, nothing written."""
    before = set(folder.iterdir())
    assert main(argv) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert cap.out == "" and "\n" not in err and "Traceback" not in err, err
    assert set(folder.iterdir()) == before
    return err


@pytest.mark.parametrize("label", [INJECTION, MARKUP], ids=["rapid-statements", "html"])
@pytest.mark.parametrize("fmt", list(SUFFIX))
def test_crafted_label_in_the_session_file_is_refused(
        session: tuple[Path, SessionLog], tmp_path: Path, fmt: str, label: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    path, log = session
    index = next(i for i, e in enumerate(log.events) if e.label == "P0")
    altered = _alter_labels(path, tmp_path / "altered.parquet", {"P0": label})
    out = tmp_path / f"{'SEAM' if fmt == 'tp' else 'seam'}{SUFFIX[fmt]}"
    err = _teach_fails(["teach", str(altered), "-o", str(out), "--csv",
                        str(tmp_path / "seam.csv")], tmp_path, capsys)
    assert str(altered) in err and f"field 'events[{index}].label'" in err
    assert repr(label[:40] + ("..." if len(label) > 40 else "")) in err
    # the same session with its labels intact writes the program
    assert main(["teach", str(path), "-o", str(out)]) == 0
    assert out.exists()


@pytest.mark.parametrize(("labels", "match"), [
    ({"P3": "P1"}, "mark pressed 2 times"),  # a duplicate line mark
    ({"P1": "Q1"}, "mark not found"),  # the line's mark renamed
    ({"P0": "P0\nLIN XP1"}, "may not contain '\\n'"),  # once: operands could not be broadcast
    ({"P0": "P1/P2"}, "may not contain '/'"),  # once: a welding line to the wrong waypoint
    ({"P0": 7}, "a label must be a string"),
    ({"P0": "x" * (MAX_LABEL_CHARS + 1)}, "at most 32 characters"),
])
def test_altered_marks_give_a_clear_error_not_a_traceback(
        session: tuple[Path, SessionLog], tmp_path: Path, labels: dict[str, object],
        match: str, capsys: pytest.CaptureFixture[str]) -> None:
    altered = _alter_labels(session[0], tmp_path / "altered.parquet", labels)
    for suffix in (".src", ".ls"):
        err = _teach_fails(["teach", str(altered), "-o", str(tmp_path / f"SEAM{suffix}")],
                           tmp_path, capsys)
        assert str(altered) in err and match in err, err


def test_an_event_time_that_is_not_a_number_is_refused(
        session: tuple[Path, SessionLog], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    table = pq.read_table(session[0])
    key = b"leadthrough.session"
    meta = json.loads(table.schema.metadata[key])
    meta["events"][0]["t"] = "soon"
    altered = tmp_path / "altered.parquet"
    pq.write_table(table.replace_schema_metadata({key: json.dumps(meta).encode()}), altered)
    err = _teach_fails(["teach", str(altered), "-o", str(tmp_path / "seam.mod")], tmp_path,
                       capsys)
    assert "field 'events[0].t' = 'soon': not a finite time" in err


def test_a_crafted_line_mark_on_the_command_line_is_refused(
        session: tuple[Path, SessionLog], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    err = _teach_fails(["teach", str(session[0]), "-o", str(tmp_path / "seam.mod"), "--line",
                        "P1,P2;SetDO do1"], tmp_path, capsys)
    assert "field '--line'" in err and "may not contain ';'" in err


def test_library_teach_session_refuses_a_crafted_label(er20: Robot,
                                                       session: tuple[Path, SessionLog]) -> None:
    log = session[1]
    index = next(i for i, e in enumerate(log.events) if e.label == "P0")
    events = [replace(e, label=INJECTION) if i == index else e for i, e in enumerate(log.events)]
    with pytest.raises(LabelError) as info:
        teach_session(replace(log, events=events), er20, source="seam.parquet")
    assert info.value.source == "seam.parquet" and info.value.field == f"events[{index}].label"


def test_json_and_csv_exports_refuse_a_crafted_label(er20: Robot, tmp_path: Path,
                                                     session: tuple[Path, SessionLog]) -> None:
    program = teach_session(session[1], er20)
    labels = list(program.waypoints.labels)
    labels[1] = INJECTION
    bad = replace(program, waypoints=replace(program.waypoints, labels=tuple(labels)))
    with pytest.raises(TeachError, match="target 1: a label"):
        write_program_csv(bad, tmp_path / "seam.csv")
    with pytest.raises(TeachError, match="target 1: a label"):
        write_program_json(bad, tmp_path / "seam.json")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------ the writers
def _targets(robot: Robot, labels: tuple[str, ...] = ("P1", "", "P2")) -> list[ProgramTarget]:
    """Targets of the golden path (A1 = 0°, 15°, 30°, A5 = 90°)."""
    out = []
    for a1, label in zip((0.0, 15.0, 30.0), labels, strict=True):
        q = np.radians([a1, 0.0, 0.0, 0.0, 90.0, 0.0])
        out.append(ProgramTarget(label, q, pose_of(robot, q), bool(label), 0.2, 0.0674))
    return out


def _render(robot: Robot, language: str, targets: list[ProgramTarget], joint_space: bool = False,
            header: tuple[str, ...] = ("taught path",), changes: dict[str, Any] | None = None,
            ) -> tuple[dict[str, str], list[object], ProgramOptions]:
    configs = target_configurations(language, robot, targets, joint_space)
    options = replace(ProgramOptions(name=NAMES[language], speed_m_s=0.1,
                                     joint_space=joint_space), **(changes or {}))
    return LANGUAGES[language].render(targets, configs, options, list(header)), configs, options


@pytest.mark.parametrize("label", [INJECTION, MARKUP, "P1\nP2", "P1;", "P1 !", "", " P1"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_each_writer_refuses_a_label_that_is_not_a_name(er20: Robot, language: str,
                                                        label: str) -> None:
    if label == "":
        label = "P1//P2"  # an empty part of a joined label
    targets = _targets(er20, ("P1", label, "P2"))
    with pytest.raises(TeachError, match=r"target 1: a label"):
        _render(er20, language, targets)


@pytest.mark.parametrize(("change", "match"), [
    ({"name": "seam()\n  set_digital_out(1, True)\ndef x"}, "not a valid program name"),
    ({"name": "seam;"}, "not a valid program name"),
    ({"speed_m_s": math.nan}, "speed_m_s"),
    ({"zone_mm": math.inf}, "zone_mm"),
    ({"orientation_speed_rad_s": -1.0}, "orientation_speed_rad_s"),
    ({"fanuc_cnt": 101}, "fanuc_cnt"),
])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_each_writer_refuses_a_name_or_number_it_cannot_hold(
        er20: Robot, language: str, change: dict[str, object], match: str) -> None:
    with pytest.raises(TeachError, match=match):
        _render(er20, language, _targets(er20), changes=change)


@pytest.mark.parametrize("language", list(LANGUAGES))
def test_each_writer_refuses_a_non_finite_target(er20: Robot, language: str) -> None:
    targets = _targets(er20)
    targets[2] = replace(targets[2], q=np.array([math.nan, 0.0, 0.0, 0.0, 1.5, 0.0]))
    with pytest.raises(TeachError, match="target 2: a non-finite"):
        LANGUAGES[language].render(targets, [None] * 3,
                                   ProgramOptions(name=NAMES[language], speed_m_s=0.1), [])


@pytest.mark.parametrize("language", list(LANGUAGES))
def test_header_text_is_escaped_into_one_comment_line(er20: Robot, language: str) -> None:
    files, configs, options = _render(er20, language, _targets(er20),
                                      header=(f"robot {INJECTION}",))
    text = "".join(files.values())
    assert "SetDO" in text and "\n    SetDO" not in text and "    MoveAbsJ [[" not in text
    assert check_program(language, files, er20, _targets(er20), configs, options) < 0.01


# ------------------------------------------------------------------------------ the checker
def _insert_after(files: dict[str, str], anchor: str, line: str) -> dict[str, str]:
    for suffix, text in files.items():
        if anchor in text.split("\n"):
            lines = text.split("\n")
            lines.insert(lines.index(anchor) + 1, line)
            return {**files, suffix: "\n".join(lines)}
    raise AssertionError(f"no line {anchor!r}")


def _remove(files: dict[str, str], *gone: str) -> dict[str, str]:
    out = {s: "\n".join(line for line in t.split("\n") if line not in gone)
           for s, t in files.items()}
    assert out != files
    return out


ANCHOR = {"rapid": "    ! P2", "tp": "  13:  ! P2 ;", "krl": "; P2", "urscript": "  # P2"}


@pytest.mark.parametrize("joint_space", [False, True], ids=["linear", "joint"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_checker_rejects_one_injected_digital_output(er20: Robot, language: str,
                                                     joint_space: bool) -> None:
    targets = _targets(er20)
    files, configs, options = _render(er20, language, targets, joint_space)
    assert check_program(language, files, er20, targets, configs, options) < 0.01
    bad = _insert_after(files, ANCHOR[language], DIGITAL_OUT[language])
    with pytest.raises(TeachError, match="a statement the program writer does not emit"):
        check_program(language, bad, er20, targets, configs, options)


LAST_MOVE = {  # the last move and everything that belongs to it only
    ("rapid", False): ["    MoveL p3,v_lt,fine,tool0\\WObj:=wobj0;"],
    ("rapid", True): ["    MoveAbsJ j3,v_lt,fine,tool0;"],
    ("krl", False): ["LIN XP3"], ("krl", True): ["PTP XP3"],
    ("tp", False): ["  14:L P[3] 100mm/sec FINE ;"], ("tp", True): ["  14:J P[3] 7% FINE ;"],
    ("urscript", False): None, ("urscript", True): None,
}


@pytest.mark.parametrize("joint_space", [False, True], ids=["linear", "joint"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_checker_rejects_a_removed_move(er20: Robot, language: str, joint_space: bool) -> None:
    targets = _targets(er20)
    files, configs, options = _render(er20, language, targets, joint_space)
    gone = LAST_MOVE[(language, joint_space)]
    if gone is None:  # URScript: the last line before "end"
        gone = [files[".script"].split("\n")[-3]]
    with pytest.raises(TeachError):
        check_program(language, _remove(files, *gone), er20, targets, configs, options)
    # a well-formed program of the first two moves only: the comparison counts every move
    short = _render(er20, language, targets[:2], joint_space)[0]
    with pytest.raises(TeachError, match="holds 2 moves, 3 were written"):
        check_program(language, short, er20, targets, configs, options)


@pytest.mark.parametrize("language", list(LANGUAGES))
def test_checker_rejects_a_well_formed_extra_move(er20: Robot, language: str) -> None:
    targets = _targets(er20)
    _, configs, options = _render(er20, language, targets)
    longer, _, _ = _render(er20, language, [*targets, targets[1]], header=("taught path",))
    with pytest.raises(TeachError, match="holds 4 moves, 3 were written"):
        check_program(language, longer, er20, targets, configs, options)


def test_checker_rejects_another_program_name(er20: Robot) -> None:
    targets = _targets(er20)
    files, configs, options = _render(er20, "rapid", targets)
    with pytest.raises(TeachError, match="names another program"):
        check_program("rapid", files, er20, targets, configs, replace(options, name="other"))


# ----------------------------------------------------------------------------- property test
_LABEL = st.from_regex(r"[A-Za-z0-9_.\-][A-Za-z0-9_.\- ]{0,30}[A-Za-z0-9_.\-]|[A-Za-z0-9_.\-]",
                       fullmatch=True)
_TARGET_LABEL = st.one_of(st.just(""), _LABEL, st.lists(_LABEL, min_size=2, max_size=3).map(
    "/".join))


def _valid_waypoint(robot: Robot, q: np.ndarray) -> bool:
    """Within the joint limits (J2, J3, J5 within ±179°, which FANUC and ABB can express) and
    away from the singularities (half the margins of ``sample_configurations``)."""
    lo, hi = robot.lower_limits.copy(), robot.upper_limits.copy()
    for j in (1, 2, 4):
        lo[j], hi[j] = max(lo[j], -math.radians(179.0)), min(hi[j], math.radians(179.0))
    b = branch_values(arm_structure(robot), robot, q)
    margin = math.radians(0.5 * SINGULARITY_MARGIN_DEG)
    return bool(np.all((lo <= q) & (q <= hi))) and abs(b.shoulder) >= 0.01 \
        and abs(b.elbow) >= 0.005 and margin <= abs(b.wrist) <= math.pi - margin


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(language=st.sampled_from(list(LANGUAGES)), joint_space=st.booleans(),
       seed=st.integers(0, 2**16), labels=st.lists(_TARGET_LABEL, min_size=2, max_size=4),
       data=st.data())
def test_property_generated_programs_pass_and_any_foreign_line_is_rejected(
        er20: Robot, language: str, joint_space: bool, seed: int, labels: list[str],
        data: st.DataObject) -> None:
    assert all(is_label(p) for lab in labels for p in lab.split("/") if lab)
    base = sample_configurations(er20, 1, seed)[0]
    step = np.random.default_rng(seed).uniform(-0.5, 0.5, (len(labels), 6))  # [deg]
    qs = base + np.radians(np.cumsum(step, axis=0))
    assume(all(_valid_waypoint(er20, q) for q in qs))
    targets = [ProgramTarget(lab, q, pose_of(er20, q), bool(lab) or i in (0, len(qs) - 1),
                             0.2, 0.05) for i, (lab, q) in enumerate(zip(labels, qs, strict=True))]
    files, configs, options = _render(er20, language, targets, joint_space,
                                      header=(f"robot {data.draw(st.text(max_size=40))}",))
    assert check_program(language, files, er20, targets, configs, options) <= 0.01
    suffix = data.draw(st.sampled_from(sorted(files)))
    lines = files[suffix].split("\n")[:-1]
    at = data.draw(st.integers(0, len(lines)))
    foreign = data.draw(st.sampled_from(FOREIGN[language]))
    bad = {**files, suffix: "\n".join([*lines[:at], foreign, *lines[at:]]) + "\n"}
    with pytest.raises(TeachError):
        check_program(language, bad, er20, targets, configs, options)
