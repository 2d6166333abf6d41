"""Round trip of every program language: taught joints → program text → parsed → our inverse
kinematics → joints, on 50 random reachable poses per built-in robot.

The poses are drawn uniformly within the joint limits (deterministic seeds), so they cover the
wrist-flipped, elbow-down and overhead branches the limits allow (asserted below), kept 10° from
the wrist singularity, 20 mm from the shoulder singularity plane and off the stretched elbow (a
file's decimals cannot pin joints down at a singularity). Configured languages (KRL, FANUC TP,
RAPID) must give the taught joints back from pose + configuration alone; URScript's ``movel`` is
solved nearest the previous waypoint's joints (a configuration 2° away on the same path), as UR's
controller does. The Panda (7 axes) gets joint programs only.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from leadthrough.errors import TeachError
from leadthrough.robot import Robot, builtin_robot_path, load_robot
from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.inverse_kinematics import pose_of, solve_pose
from leadthrough.teach.programs import LANGUAGES
from leadthrough.teach.programs.configuration import abb_config
from leadthrough.teach.programs.parsed import ROUND_TRIP_TOLERANCE_DEG
from leadthrough.teach.programs.round_trip import round_trip_errors, sample_configurations

SIX_AXIS = ("er20", "ur5", "ur10")
SEEDS = {"er20": 11, "ur5": 12, "ur10": 13}


@pytest.fixture(scope="module")
def samples() -> dict[str, tuple[Robot, np.ndarray]]:
    out = {}
    for name in SIX_AXIS:
        robot = load_robot(name)
        out[name] = (robot, sample_configurations(robot, 50, SEEDS[name]))
    return out


def test_samples_cover_the_branches(samples: dict[str, tuple[Robot, np.ndarray]]) -> None:
    for name, (robot, qs) in samples.items():
        s = arm_structure(robot)
        b = np.array([branch_values(s, robot, q) for q in qs])
        wrist_flipped, elbow_down, overhead = (b[:, 2] < 0).sum(), (b[:, 1] < 0).sum(), \
            (b[:, 0] < 0).sum()
        print(f"{name}: wrist flipped {wrist_flipped}, elbow down {elbow_down}, "
              f"overhead {overhead} of {len(qs)}")
        assert wrist_flipped >= 10 and len(qs) - wrist_flipped >= 10
        assert elbow_down >= 5 and len(qs) - elbow_down >= 5
        assert overhead >= 5


@pytest.mark.parametrize("joint_space", [False, True], ids=["poses", "joints"])
@pytest.mark.parametrize("language", list(LANGUAGES))
@pytest.mark.parametrize("name", SIX_AXIS)
def test_round_trip_50_random_poses(samples: dict[str, tuple[Robot, np.ndarray]], name: str,
                                    language: str, joint_space: bool) -> None:
    robot, qs = samples[name]
    err = round_trip_errors(robot, language, qs, joint_space=joint_space)
    print(f"{name} {language} {'joints' if joint_space else 'poses'}: max joint error "
          f"{err.max():.2e} deg over {len(qs)} poses")
    assert err.shape == (50,)
    assert err.max() <= ROUND_TRIP_TOLERANCE_DEG


@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), name=st.sampled_from(SIX_AXIS),
       language=st.sampled_from(["krl", "tp", "rapid", "urscript"]))
def test_round_trip_any_seed(seed: int, name: str, language: str) -> None:
    robot = load_robot(name)
    qs = sample_configurations(robot, 3, seed)
    assert round_trip_errors(robot, language, qs, seed=seed).max() <= ROUND_TRIP_TOLERANCE_DEG


def test_panda_joint_programs_round_trip_and_poses_are_refused() -> None:
    panda = load_robot("panda")
    rng = np.random.default_rng(5)
    qs = rng.uniform(panda.lower_limits, panda.upper_limits, size=(50, 7))
    for language in ("krl", "tp", "rapid"):
        err = round_trip_errors(panda, language, qs, joint_space=True)
        assert err.max() <= ROUND_TRIP_TOLERANCE_DEG
        with pytest.raises(TeachError, match=r"7-axis arm .*panda|panda.*7"):
            round_trip_errors(panda, language, qs[:2])
    with pytest.raises(TeachError, match="six joints"):
        round_trip_errors(panda, "urscript", qs[:2], joint_space=True)


def test_wrist_flip_is_the_other_solution_of_the_same_pose(er20: Robot) -> None:
    """On a spherical wrist (A4 + 180°, −A5, A6 + 180°) reaches the same pose: each of the two
    configurations solves back to its own joints."""
    s = arm_structure(er20)
    q = np.radians([20.0, -30.0, 40.0, 30.0, 50.0, -60.0])
    flipped = q + np.radians([0.0, 0.0, 0.0, -180.0, 0.0, 180.0])
    flipped[4] = -q[4]
    assert pose_of(er20, q).isApprox(pose_of(er20, flipped), 1e-12)
    for qq, cfx in ((q, 0), (flipped, 1)):
        cfg = abb_config(s, er20, qq, branch_values(s, er20, qq))
        assert cfg.cfx == cfx
        win = cfg.window(er20, s)
        sols = solve_pose(er20, pose_of(er20, q), (win.lower, win.upper),
                          lambda x, w=win: w.accepts(branch_values(s, er20, x)))
        assert len(sols) == 1
        np.testing.assert_allclose(sols[0], qq, atol=1e-9)


def test_unreachable_pose_is_a_clear_error(er20: Robot) -> None:
    s = arm_structure(er20)
    q = np.radians([0.0, 0.0, 0.0, 0.0, 90.0, 0.0])
    cfg = abb_config(s, er20, q, branch_values(s, er20, q))
    win = cfg.window(er20, s)
    far = pin.SE3(pose_of(er20, q).rotation, np.array([3.0, 0.0, 1.0]))
    assert solve_pose(er20, far, (win.lower, win.upper),
                      lambda x: win.accepts(branch_values(s, er20, x))) == []
    assert math.isfinite(float(np.linalg.norm(far.translation)))


def _robot_file(tmp_path: Path, joint5: str, joint6: str) -> Robot:
    """An ER20 variant: its own name, a longer forearm and the given joint 5 and 6 origins."""
    data = builtin_robot_path("er20").parent
    toml = (data / "er20.toml").read_text().replace('name = "er20"', 'name = "my_arm"')
    toml = toml.replace('urdf = "er20.urdf"', 'urdf = "my_arm.urdf"')
    (tmp_path / "my_arm.toml").write_text(toml)
    urdf = (data / "er20.urdf").read_text()
    urdf = urdf.replace('<origin xyz="0.760 0 0" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>', joint5)
    urdf = urdf.replace('<origin xyz="0.125 0 0" rpy="0 0 0"/>\n    <axis xyz="1 0 0"/>', joint6)
    (tmp_path / "my_arm.urdf").write_text(urdf)
    return load_robot(tmp_path / "my_arm.toml")


def test_any_robot_file_round_trips_and_an_offset_wrist_is_refused(tmp_path: Path) -> None:
    # A5 reversed, its zero turned by 0.3 rad (the wrist singularity moves to A5 = 0.3 rad),
    # forearm 0.9 m: still a vendor-like arm
    j5 = '<origin xyz="0.900 0 0" rpy="0 0.3 0"/>\n    <axis xyz="0 -1 0"/>'
    j6 = '<origin xyz="0.125 0 0" rpy="0 0 0"/>\n    <axis xyz="1 0 0"/>'
    robot = _robot_file(tmp_path, j5, j6)
    assert arm_structure(robot).wrist_zero == pytest.approx(0.3, abs=1e-9)
    qs = sample_configurations(robot, 20, 4)
    for language in LANGUAGES:
        assert round_trip_errors(robot, language, qs).max() <= ROUND_TRIP_TOLERANCE_DEG
    # A6 offset 60 mm sideways from A5: no longer a spherical or UR-type wrist; the vendor
    # indicators leave two solutions for some poses, which is reported, not written
    robot = _robot_file(tmp_path, j5, '<origin xyz="0.125 0.06 0" rpy="0 0 0"/>\n'
                                      '    <axis xyz="1 0 0"/>')
    qs = sample_configurations(robot, 30, 3)
    with pytest.raises(TeachError, match="does not single out one joint solution"):
        round_trip_errors(robot, "krl", qs)
    assert round_trip_errors(robot, "urscript", qs).max() <= ROUND_TRIP_TOLERANCE_DEG
