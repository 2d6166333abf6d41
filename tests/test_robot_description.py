"""Robot files: built-ins load; bad files give a LeadthroughError naming file, field and value."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from leadthrough.cli import main
from leadthrough.errors import LeadthroughError, RobotFileError, UnknownRobotError
from leadthrough.robot import BUILTIN_ROBOTS, builtin_robot_path, load_robot

EXPECTED_DOF = {"er20": 6, "ur5": 6, "ur10": 6, "panda": 7}


@pytest.mark.parametrize("name", BUILTIN_ROBOTS)
def test_builtin_robots_load(name: str) -> None:
    robot = load_robot(name)
    assert robot.n == EXPECTED_DOF[name]
    assert robot.model.nq == robot.n
    assert np.all(robot.lower_limits < robot.upper_limits)
    assert np.all(robot.torque_per_amp > 0)
    # max current is consistent with the max joint torque through R·Kt
    np.testing.assert_allclose(robot.max_current * robot.torque_per_amp, robot.max_torque,
                               rtol=2e-3)


def test_er20_matches_paper_table_i(er20) -> None:
    np.testing.assert_array_equal(er20.gear_ratio, [147, 178, 164, 77, 80, 50])
    np.testing.assert_array_equal(er20.max_torque, [1764, 2138, 418, 105, 109, 35])
    np.testing.assert_allclose(np.rad2deg(er20.lower_limits), [-175, -142, -73, -178, -132, -360])
    np.testing.assert_allclose(np.rad2deg(er20.upper_limits), [175, 65, 163, 178, 132, 360])
    total = sum(er20.model.inertias[j].mass for j in range(1, 7))
    assert 150.0 < total < 200.0  # moving links; plus the 60 kg base ≈ 220 kg robot


def test_er20_reach_is_about_1_7_m(er20) -> None:
    """Max horizontal distance of the wrist centre from axis 1 over the q2/q3 ranges ≈ 1.7 m."""
    import pinocchio as pin

    data = er20.model.createData()
    wrist = er20.model.getJointId("joint_5")
    reach = 0.0
    for q2 in np.linspace(er20.lower_limits[1], er20.upper_limits[1], 60):
        for q3 in np.linspace(er20.lower_limits[2], er20.upper_limits[2], 60):
            pin.forwardKinematics(er20.model, data, np.array([0, q2, q3, 0, 0, 0.0]))
            p = data.oMi[wrist].translation
            reach = max(reach, float(np.hypot(p[0], p[1])))
    assert 1.65 < reach < 1.75


def _copy_er20(tmp_path: Path) -> Path:
    src = builtin_robot_path("er20")
    shutil.copy(src, tmp_path / "er20.toml")
    shutil.copy(src.parent / "er20.urdf", tmp_path / "er20.urdf")
    return tmp_path / "er20.toml"


def test_user_robot_by_path(tmp_path: Path) -> None:
    robot = load_robot(_copy_er20(tmp_path))
    assert robot.name == "er20" and robot.n == 6


def test_unknown_robot_name() -> None:
    with pytest.raises(UnknownRobotError) as e:
        load_robot("kr1000")
    assert e.value.value == "kr1000" and "er20" in str(e.value)


def test_missing_urdf(tmp_path: Path) -> None:
    toml = _copy_er20(tmp_path)
    (tmp_path / "er20.urdf").unlink()
    with pytest.raises(RobotFileError) as e:
        load_robot(toml)
    assert e.value.field == "robot.urdf" and str(toml) in str(e.value)


def test_drive_file_missing_a_joint(tmp_path: Path) -> None:
    toml = _copy_er20(tmp_path)
    text = toml.read_text()
    start = text.index("[joints.joint_4]")
    end = text.index("[joints.joint_5]")
    toml.write_text(text[:start] + text[end:])
    with pytest.raises(RobotFileError) as e:
        load_robot(toml)
    assert e.value.field == "joints.joint_4" and "missing" in str(e.value)


@pytest.mark.parametrize("bad", ["0.0", "-3.0", "\"x\"", "nan"])
def test_bad_gear_ratio(tmp_path: Path, bad: str) -> None:
    toml = _copy_er20(tmp_path)
    toml.write_text(toml.read_text().replace("gear_ratio = 77.0", f"gear_ratio = {bad}"))
    with pytest.raises(RobotFileError) as e:
        load_robot(toml)
    assert e.value.field == "joints.joint_4.gear_ratio"
    assert str(toml) in str(e.value) and "> 0" in str(e.value)


def test_limits_outside_urdf(tmp_path: Path) -> None:
    toml = _copy_er20(tmp_path)
    toml.write_text(toml.read_text().replace(
        "position_limits = [-2.303834612632515, 2.303834612632515]",
        "position_limits = [-2.5, 2.303834612632515]"))
    with pytest.raises(RobotFileError) as e:
        load_robot(toml)
    assert e.value.field == "joints.joint_5.position_limits"


def test_unknown_field_and_bad_tcp(tmp_path: Path) -> None:
    toml = _copy_er20(tmp_path)
    toml.write_text(toml.read_text().replace("gear_ratio = 50.0", "gear_ratio = 50.0\ngear = 2"))
    with pytest.raises(RobotFileError, match="unknown field"):
        load_robot(toml)
    toml = _copy_er20(tmp_path)
    toml.write_text(toml.read_text().replace('tcp_frame = "flange"', 'tcp_frame = "nose"'))
    with pytest.raises(RobotFileError) as e:
        load_robot(toml)
    assert e.value.field == "robot.tcp_frame" and e.value.value == "nose"


def test_not_toml(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\nname=")
    with pytest.raises(RobotFileError, match="not valid TOML"):
        load_robot(bad)


def test_errors_share_the_root() -> None:
    assert issubclass(UnknownRobotError, LeadthroughError)
    assert issubclass(RobotFileError, LeadthroughError)


@pytest.mark.parametrize("spec", ["nosuch", "missing/robot.toml"])
def test_cli_exits_2_on_bad_robot(spec: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["robots", "--robot", spec]) == 2
    err = capsys.readouterr().err
    assert err.startswith("leadthrough: error:") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_cli_exits_2_on_bad_ratio(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = _copy_er20(tmp_path)
    toml.write_text(toml.read_text().replace("gear_ratio = 77.0", "gear_ratio = 0"))
    assert main(["robots", "--robot", str(toml)]) == 2
    err = capsys.readouterr().err
    assert "joints.joint_4.gear_ratio" in err and "= 0" in err and str(toml) in err
