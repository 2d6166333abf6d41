"""CLI: bad input found by a new user's audit (2026-11-29), each refused with exit code 2, a
message naming the option or field and the value, and nothing written or overwritten."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import numpy as np
import pinocchio as pin
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from leadthrough.cli import main
from leadthrough.cli.arg_checks import check_payload_torques
from leadthrough.dynamics.model import FrictionModel, nominal_drive_parameters
from leadthrough.errors import DataError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.fileio import require_text
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import save_params
from leadthrough.robot import load_robot
from leadthrough.session.realtime import RealtimeRequest, setup_realtime
from leadthrough.session_format import FORMAT_VERSION, session_metadata
from leadthrough.sim.guiding_params import shipped_params_path

COLUMN_MAP = """delimiter = ","
skip_rows = 0
[time]
column = 0
unit = "s"
[q]
columns = [1, 2, 3, 4, 5, 6]
unit = "rad"
[current]
columns = [7, 8, 9, 10, 11, 12]
unit = "A"
"""


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def _closed_port() -> int:
    """A loopback port nobody listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize("option, value", [("--host", "127.0.0.1"), ("--port", "30004"),
                                           ("--approach", "0.2")])
def test_record_refuses_a_robot_setting_without_a_driver(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str) -> None:
    """``record --host H`` without ``--driver`` used to record on the simulator, exit 0: the
    user believed they had recorded their robot."""
    traj, out = tmp_path / "traj.csv", tmp_path / "rec.parquet"
    traj.write_text("not read: refused before\n")
    assert main(["record", "--robot", "er20", "--trajectory", str(traj), option, value,
                 "-o", str(out)]) == 2
    err = _error(capsys)
    assert f"'{option}'" in err and "without a driver" in err
    assert not out.exists()


def test_outputs_never_overwrite_the_commands_inputs(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]
                                                     ) -> None:
    """Each output option that names one of the command's inputs (by another spelling of the
    same path too) is refused before anything is read, and the input is left as it was."""
    traj, cmap, rec = tmp_path / "traj.csv", tmp_path / "map.toml", tmp_path / "log.csv"
    for f in (traj, cmap, rec):
        f.write_text("original\n")
    params = tmp_path / "params.toml"
    params.write_bytes(shipped_params_path("er20").read_bytes())
    other = tmp_path / "sub" / ".." / "traj.csv"
    link = tmp_path / "links.urdf"      # a link to the recording, under a URDF's name
    link.symlink_to(rec)
    (tmp_path / "sub").mkdir()
    cases = [
        (["record", "--robot", "er20", "--trajectory", str(traj), "-o", str(other)],
         "'-o'", "--trajectory", traj),
        (["identify", str(rec), "--columns", str(cmap), "--robot", "er20", "-o", str(cmap)],
         "'-o'", "--columns", cmap),
        (["identify", str(rec), "--robot", "er20", "--columns", str(cmap), "-o",
          str(tmp_path / "p.toml"), "--urdf-out", str(link)], "'--urdf-out'", "the recording",
         rec),
        (["refresh-friction", str(params), str(rec), "--robot", "er20", "-o", str(params)],
         "'-o'", "the params", params),
        (["guide", "--robot", "er20", "--params", str(params), "--operator", "rest", "-o",
          str(params)], "'-o'", "--params", params),
    ]
    for argv, option, name, victim in cases:
        before = victim.read_bytes()
        assert main(argv) == 2, argv
        err = _error(capsys)
        if Path(argv[argv.index(option.strip("'")) + 1]).is_symlink():
            assert "symbolic link" in err, (argv, err)   # no output goes through a link
        else:
            assert option in err and f"overwrite the input {name}" in err, (argv, err)
        assert victim.read_bytes() == before


def test_refresh_friction_names_the_params_file_for_its_friction_model(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Parameters without eq. 15 friction: the error names the params file and its field (it
    named the check recording, which has no such field)."""
    robot = load_robot("er20")
    params = tmp_path / "cv.toml"
    n = robot.n
    stats = ResidualStats(mean=np.zeros(n), std=np.ones(n), std_pct_max=np.ones(n),
                          rms=np.ones(n), rel_error_pct=1.0, J=1.0, k_omega=1.0,
                          samples=np.ones(n, dtype=np.int64))
    save_params(params, robot, "ols-cv", nominal_drive_parameters(robot), stats)
    assert nominal_drive_parameters(robot).friction_model is not FrictionModel.STRIBECK
    check = tmp_path / "check.parquet"
    assert main(["refresh-friction", str(params), str(check), "--robot", "er20", "-o",
                 str(tmp_path / "new.toml")]) == 2
    err = _error(capsys)
    assert f"{params}: field 'meta.friction_model'" in err and "check.parquet" not in err
    assert not (tmp_path / "new.toml").exists()


@pytest.mark.parametrize("option, value", [("--rt-priority", "200"), ("--rt-priority", "0"),
                                           ("--cpus", "-1")])
def test_guide_on_a_robot_refuses_real_time_settings_out_of_range(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str) -> None:
    """Before connecting or starting anything: ``--rt-priority 200`` only warned and ran at
    normal priority, ``--cpus -1`` ended in a ValueError traceback."""
    out = tmp_path / "s.parquet"
    assert main(["guide", "--driver", "ur-rtde", "--host", "127.0.0.1", "--port",
                 str(_closed_port()), "--robot", "er20", "--params",
                 str(shipped_params_path("er20")), "--enable-input", "0", option, value,
                 "-o", str(out)]) == 2
    err = _error(capsys)
    assert f"field '{option}' = {value}" in err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_an_affinity_the_os_refuses_is_reported_not_raised() -> None:
    """The library's real-time set-up reports a CPU number the OS rejects (a negative one
    raised ValueError from ``os.sched_setaffinity``)."""
    lines = setup_realtime(RealtimeRequest(cpus=(-1,)))
    assert len(lines) == 1 and lines[0].startswith("CPU affinity not set")


def test_a_binary_or_non_utf8_log_is_refused_with_its_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A Parquet file given with a column map, and a log with one row of bytes that are not
    UTF-8: Arrow's CSV reader printed an ignored exception's traceback and a message full of
    raw bytes. Now the file is checked first: Parquet is named as such, and the first bad
    bytes are given with their line."""
    cmap = tmp_path / "map.toml"
    cmap.write_text(COLUMN_MAP)
    parquet = tmp_path / "rec.parquet"
    pq.write_table(pa.table({"t": [0.0, 1.0]}), parquet)
    assert main(["identify", str(parquet), "--columns", str(cmap), "--robot", "er20", "-o",
                 str(tmp_path / "p.toml")]) == 2
    err = _error(capsys)
    assert "field 'format' = 'Parquet'" in err and "without a column map" in err
    log = tmp_path / "log.csv"
    good = ",".join(["0.0"] * 13) + "\n"
    log.write_bytes(good.encode() * 2 + b"0.5,\xe9\xff,1\n" + good.encode())
    for command in ("identify", "payload"):
        extra = ["--params", str(shipped_params_path("er20"))] if command == "payload" else \
            ["-o", str(tmp_path / "p.toml")]
        assert main([command, str(log), "--columns", str(cmap), "--robot", "er20",
                     *extra]) == 2
        err = _error(capsys)
        assert "field 'line 3' = 'e9 ff 2c 31'" in err and "not UTF-8" in err
    assert not (tmp_path / "p.toml").exists()
    with pytest.raises(DataError) as e:
        require_text(log, "log")
    assert e.value.field == "line 3"
    require_text(cmap, "column map")     # text passes


def _trajectory_csv(path: Path, rows: list[list[float]]) -> None:
    header = "time," + ",".join(f"{k}{j}" for k in ("q", "qd", "qdd") for j in range(1, 7))
    path.write_text("# leadthrough trajectory\n# robot: er20\n" + header + "\n"
                    + "".join(",".join(repr(v) for v in r) + "\n" for r in rows))


def test_a_bad_trajectory_row_is_named_with_its_column(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """A NaN, a time that goes back, no rows: the message named only 'time' (a NaN in q3
    included), with no row; an empty file also printed two numpy warnings."""
    rows = [[0.01 * i] + [0.0] * 18 for i in range(6)]
    out = tmp_path / "rec.parquet"
    cases = []
    nan = [r.copy() for r in rows]
    nan[4][3] = float("nan")
    cases.append((nan, "not finite in row 5", "field 'q3' = nan"))
    back = [r.copy() for r in rows]
    back[3][0] = 0.0
    cases.append((back, "time does not increase in row 4", "field 'time' = 0.0"))
    cases.append(([], "too few samples", "field 'rows' = 0"))
    for data, what, field in cases:
        traj = tmp_path / "t.csv"
        _trajectory_csv(traj, data)
        assert main(["record", "--robot", "er20", "--trajectory", str(traj), "-o",
                     str(out)]) == 2
        err = _error(capsys)
        assert what in err and field in err and "Warning" not in err, err
        assert not out.exists()


def test_a_column_map_scale_of_zero_is_refused(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """``scale = 0`` made every current zero, and identify wrote parameters fitted to them."""
    cmap = tmp_path / "map.toml"
    cmap.write_text(COLUMN_MAP.replace('unit = "A"', 'unit = "A"\nscale = 0'))
    log = tmp_path / "log.csv"
    log.write_text("".join(f"{0.001 * i}" + ",0.0" * 12 + "\n" for i in range(10)))
    assert main(["identify", str(log), "--columns", str(cmap), "--robot", "er20", "-o",
                 str(tmp_path / "p.toml")]) == 2
    err = _error(capsys)
    assert "field 'current.scale' = 0" in err and "non-zero" in err
    assert not (tmp_path / "p.toml").exists()


@pytest.mark.parametrize("option, value", [("--harmonics", "100000"),
                                           ("--starts", "1000000000")])
def test_excite_bounds_the_search(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  option: str, value: str) -> None:
    """Both had no upper bound: the search just ran (killed after 40 s in the audit)."""
    out = tmp_path / "t.csv"
    assert main(["excite", "--robot", "er20", option, value, "-o", str(out)]) == 2
    err = _error(capsys)
    assert option.lstrip("-") in err and value in err
    assert not out.exists()


@pytest.mark.parametrize("option, value, words", [
    ("--duration", "inf", "finite seconds > 0 on the simulator"),
    ("--duration", "nan", "finite seconds > 0 on the simulator"),
    ("--duration", "-1", "finite seconds > 0 on the simulator"),
    ("--seed", "-1", "out of range")])
def test_guide_on_the_simulator_names_a_bad_duration_or_seed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str,
        words: str) -> None:
    """``--duration inf`` was refused as the loop's internal ``duration_s`` ('no way to stop'),
    ``--seed -1`` as 'identified on another simulated robot'."""
    out = tmp_path / "s.parquet"
    assert main(["guide", "--robot", "er20", "--params", str(shipped_params_path("er20")),
                 "--operator", "rest", option, value, "-o", str(out)]) == 2
    err = _error(capsys)
    assert f"field '{option}'" in err and words in err and "another" not in err
    assert not out.exists()


def test_a_port_that_never_answers_rtde_is_named(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A listener that accepts the connection and says nothing (not a UR controller): the
    message named only the request, not where it went. The link, not the input: exit 1."""
    traj = tmp_path / "traj.csv"
    _trajectory_csv(traj, [[0.01 * i] + [0.0] * 18 for i in range(3)])
    out = tmp_path / "rec.parquet"
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(1)        # the kernel completes the connection; nobody answers
        port = silent.getsockname()[1]
        assert main(["record", "--driver", "ur-rtde", "--host", "127.0.0.1", "--port",
                     str(port), "--robot", "er20", "--trajectory", str(traj), "-o",
                     str(out)]) == 1
    err = _error(capsys)
    assert f"no answer from 127.0.0.1:{port}" in err and "REQUEST_PROTOCOL_VERSION" in err
    assert not out.exists()


def test_excite_names_the_experiments_that_clash(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """``--sweep --friction-check`` was reported as ``--presliding``."""
    out = tmp_path / "t.csv"
    assert main(["excite", "--robot", "er20", "--sweep", "--friction-check", "-o",
                 str(out)]) == 2
    err = _error(capsys)
    assert "field '--sweep and --friction-check'" in err and not out.exists()
    assert main(["excite", "--robot", "er20", "--start", *["0"] * 6, "-o", str(out)]) == 2
    assert "--start with --sweep, --presliding or --friction-check" in _error(capsys)


@pytest.mark.parametrize("extra, field", [
    (["--method", "ols-cv", "--bound", "0.5"], "'--bound' = 0.5"),
    (["--method", "ols-cv", "--seed", "5"], "'--seed' = 5"),
    (["--method", "consistent", "--seed", "5"], "'--seed' = 5"),
    (["--urdf-out", "links.toml"], "'--urdf-out' = '.toml'")])
def test_identify_refuses_options_it_would_ignore(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str],
        field: str) -> None:
    """``--bound``/``--seed`` for a method that does not use them were ignored, and
    ``--urdf-out`` wrote a URDF under any suffix."""
    extra = [str(tmp_path / x) if x.endswith(".toml") else x for x in extra]
    out = tmp_path / "p.toml"
    assert main(["identify", str(tmp_path / "rec.parquet"), "--robot", "er20", *extra,
                 "-o", str(out)]) == 2
    err = _error(capsys)
    assert field in err
    assert not out.exists()


def test_teach_refuses_a_session_format_it_does_not_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A session's metadata with another format number was read as if it were this one."""
    meta = session_metadata("er20", 6, [], {})
    ((key, raw),) = meta.items()
    doc = json.loads(raw)
    assert doc["format"] == FORMAT_VERSION
    doc["format"] = 99
    session = tmp_path / "s.parquet"
    pq.write_table(pa.table({"t": [0.0]}).replace_schema_metadata({key: json.dumps(doc)}),
                   session)
    out = tmp_path / "p.json"
    assert main(["teach", str(session), "-o", str(out)]) == 2
    err = _error(capsys)
    assert "field 'format' = 99" in err and f"expected {FORMAT_VERSION}" in err
    assert not out.exists()


@pytest.mark.parametrize("out, extra, option", [
    ("seam.script", ["--fanuc-cnt", "30"], "--fanuc-cnt"),
    ("seam.json", ["--fanuc-cnt", "30"], "--fanuc-cnt"),
    ("seam.json", ["--tool", "0,0,300,0,0,0"], "--tool"),
    ("seam.json", ["--joint-space"], "--joint-space")])
def test_teach_refuses_a_setting_its_output_format_has_not(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], out: str, extra: list[str],
        option: str) -> None:
    """FANUC's CNT for a URScript or a JSON path, a tool or joint moves for a JSON path: each
    was ignored, exit 0."""
    path = tmp_path / out
    assert main(["teach", str(tmp_path / "s.parquet"), "-o", str(path), *extra]) == 2
    err = _error(capsys)
    assert f"field '{option}'" in err
    assert not path.exists()


@pytest.mark.parametrize("extra", [["--watchdog", "0.2"], ["--rt-priority", "50"],
                                   ["--cpus", "0"], ["--lock-memory"]])
def test_guide_on_the_simulator_refuses_a_robot_links_settings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str]) -> None:
    """The driver link's watchdog and the loop's real-time set-up do nothing on the
    in-process simulator: each was ignored, exit 0."""
    out = tmp_path / "s.parquet"
    assert main(["guide", "--robot", "er20", "--params", str(shipped_params_path("er20")),
                 "--operator", "rest", *extra, "-o", str(out)]) == 2
    err = _error(capsys)
    assert f"field '{extra[0]}'" in err and "given for the simulator" in err
    assert not out.exists()


def test_a_payload_is_checked_against_the_joints_max_torque(tmp_path: Path) -> None:
    """At rest the check is statics: the heaviest payload a pose holds is where the gravity
    torque of the payload (m·g times its lever, here from Pinocchio's RNEA of a unit mass)
    plus the arm's own reaches a joint's max torque; a payload 1 % under it passes, 1 % over
    it is refused naming the option, the value and that joint."""
    robot = load_robot("er20")
    q = np.tile(np.array([0.0, -0.4, 0.6, 0.0, 0.5, 0.0]), (3, 1))
    traj = TrajectorySamples(time=np.array([0.0, 0.5, 1.0]), q=q, qd=np.zeros_like(q),
                             qdd=np.zeros_like(q))
    zero = np.zeros(robot.n)
    arm = pin.rnea(robot.model, robot.model.createData(), q[0], zero, zero)
    model = pin.Model(robot.model)
    frame = model.frames[robot.tcp_frame_id]
    model.inertias[frame.parentJoint] += frame.placement.act(
        pin.Inertia(1.0, np.zeros(3), np.zeros((3, 3))))
    unit = pin.rnea(model, model.createData(), q[0], zero, zero) - arm     # per kg [N·m]
    # |arm_j + m·unit_j| <= max_j for m > 0: m <= (max_j − sgn(unit_j)·arm_j) / |unit_j|
    limit = ((robot.max_torque - np.sign(unit) * arm)
             / np.abs(np.where(unit == 0.0, np.nan, unit)))
    j = int(np.nanargmin(limit))
    heaviest = float(limit[j])
    assert 5.0 < heaviest < 200.0

    def check(mass: float) -> None:
        check_payload_torques(tmp_path / "t.csv", traj, robot,
                              pin.Inertia(mass, np.zeros(3), np.zeros((3, 3))),
                              "--payload-mass", mass)

    check(0.99 * heaviest)
    with pytest.raises(DataError, match=rf"'--payload-mass' = .*joint {j + 1} needs"):
        check(1.01 * heaviest)
