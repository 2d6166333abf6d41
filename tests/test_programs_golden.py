"""Golden files of each program language for a fixed small taught path on the ER20.

The files in ``tests/data/programs/<language>_<linear|joint>/`` were written by hand from the
languages' specifications (see each module's docstring) for this path, not produced by the
exporter: three targets with A1 = 0°, 15°, 30°, A5 = 90°, all other joints 0. By hand: the
wrist centre is at (0.93, 0, 1.424) m rotated by A1, the flange 0.125 m below it, so the flange
is at (930 cos A1, 930 sin A1, 1299) mm with orientation Rz(A1)·Ry(180°) = Rz(A1 + 180°)·Rx(180°):
KUKA A, B, C = A1 + 180°, 0, 180° (wrapped to (−180°, 180°]), FANUC W, P, R = 180°, 0, A1 + 180°,
quaternion (w, x, y, z) = (0, −sin(A1/2), cos(A1/2), 0) (written with its first non-zero entry
positive), rotation vector π·(−sin(A1/2), cos(A1/2), 0) (likewise). Configuration: wrist centre
in front of A1, elbow up (upper arm vertical, forearm forward), A5 = 90° > 0: KUKA S 2
('B010'), T 0; FANUC 'F U T, 0, 0, 0' (F: J5 ≥ 0); ABB [0, 0, 0, 0].
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from leadthrough.robot import Robot
from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.inverse_kinematics import pose_of
from leadthrough.teach.programs import LANGUAGES
from leadthrough.teach.programs.parsed import solve_back
from leadthrough.teach.programs.targets import ProgramOptions, ProgramTarget

DATA = Path(__file__).parent / "data" / "programs"
NAMES = {"urscript": "seam", "krl": "seam", "tp": "SEAM", "rapid": "seam"}


def _targets(robot: Robot) -> list[ProgramTarget]:
    out = []
    for a1, label, exact in ((0.0, "P1", True), (15.0, "", False), (30.0, "P2", True)):
        q = np.radians([a1, 0.0, 0.0, 0.0, 90.0, 0.0])
        out.append(ProgramTarget(label, q, pose_of(robot, q), exact, 0.2, 0.0674))
    return out


def _render(robot: Robot, language: str, joint_space: bool) -> dict[str, str]:
    lang = LANGUAGES[language]
    targets = _targets(robot)
    configs: list[object] = [None] * len(targets)
    if not joint_space and lang.configure is not None:
        s = arm_structure(robot)
        configs[1:] = [lang.configure(s, robot, t.q, branch_values(s, robot, t.q))
                       for t in targets[1:]]
    options = ProgramOptions(name=NAMES[language], speed_m_s=0.1, orientation_speed_rad_s=0.5,
                             zone_mm=1.0, joint_space=joint_space, fanuc_cnt=50)
    return lang.render(targets, configs, options, ["golden path"])


def _golden(language: str, joint_space: bool) -> dict[str, str]:
    folder = DATA / f"{language}_{'joint' if joint_space else 'linear'}"
    return {p.suffix.lower(): p.read_text(encoding="utf-8") for p in sorted(folder.iterdir())}


def test_flange_pose_is_the_hand_worked_one(er20: Robot) -> None:
    for a1 in (0.0, 15.0, 30.0):
        p = pose_of(er20, np.radians([a1, 0.0, 0.0, 0.0, 90.0, 0.0]))
        c, s = math.cos(math.radians(a1)), math.sin(math.radians(a1))
        np.testing.assert_allclose(p.translation, [0.93 * c, 0.93 * s, 1.299], atol=1e-12)
        expected = np.array([[-c, -s, 0.0], [-s, c, 0.0], [0.0, 0.0, -1.0]])  # Rz(a1)·Ry(180°)
        # the URDF's flange rpy 1.57079632679 is π/2 − 4.9e-12
        np.testing.assert_allclose(p.rotation, expected, atol=1e-11)


@pytest.mark.parametrize("joint_space", [False, True], ids=["linear", "joint"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_program_text_equals_golden_file(er20: Robot, language: str, joint_space: bool) -> None:
    rendered = _render(er20, language, joint_space)
    golden = _golden(language, joint_space)
    assert sorted(rendered) == sorted(golden)
    for suffix, text in golden.items():
        assert rendered[suffix].splitlines() == text.splitlines(), f"{language}{suffix}"


@pytest.mark.parametrize("joint_space", [False, True], ids=["linear", "joint"])
@pytest.mark.parametrize("language", list(LANGUAGES))
def test_golden_file_solves_back_to_the_path(er20: Robot, language: str,
                                             joint_space: bool) -> None:
    parsed = LANGUAGES[language].parse(_golden(language, joint_space))
    q = solve_back(parsed, er20)
    taught = np.array([t.q for t in _targets(er20)])
    assert np.degrees(np.abs(q - taught)).max() < 1e-3
