"""Configuration data against hand-worked examples and the vendors' documented tables.

Sources: KUKA Turn: bit i−1 = 1 for Ai < 0; the worked example TU = 'B010011' = 19 (A1 < 0,
A2 < 0, A5 < 0) of the Siemens SINUMERIK programming manual 6FC5398-2EP40-0BA0 §3.9 (KUKA's
Status/Turn convention). ABB confdata: quadrant = floor(angle / 90°), e.g. the RAPID manual's
``[1, -1, 0, 0]`` for axis 1 in 90…180°, axis 4 in −90…0°, axis 6 in 0…90°; cfx table (wrist
centre relative to axis 1 / lower arm, axis 5 sign). FANUC turn numbers as RoboDK's FANUC
post-processor: 0 for (−180°, 180°), ±1 beyond.

Hand-worked ER20 geometry (tests/test_programs_golden.py): upper arm 0.78 m from A2 at
(0.17, 0, 0.504) m, turned about −y by A2; forearm offset 0.14 m up and 0.76 m forward from A3,
turned about +y by A3 − A2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from leadthrough.errors import TeachError
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.arm_configuration import arm_structure, branch_values, wrap_angle
from leadthrough.teach.programs.configuration import (
    AbbConfig,
    FanucConfig,
    KukaConfig,
    abb_config,
    fanuc_config,
    fanuc_turn,
    kuka_config,
)


def _all(robot: Robot, q_deg: list[float]) -> tuple[KukaConfig, FanucConfig, AbbConfig]:
    s = arm_structure(robot)
    q = np.radians(q_deg)
    b = branch_values(s, robot, q)
    return kuka_config(s, robot, q, b), fanuc_config(s, robot, q, b), abb_config(s, robot, q, b)


def test_front_elbow_up_wrist_down(er20: Robot) -> None:
    # wrist centre (0.93, 0, 1.424) m: in front of A1; upper arm vertical, forearm forward:
    # elbow up; A5 = 90° > 0
    kuka, fanuc, abb = _all(er20, [0.0, 0.0, 0.0, 0.0, 90.0, 0.0])
    assert (kuka.status, kuka.turn) == (0b010, 0)
    assert fanuc.text() == "F U T, 0, 0, 0"
    assert abb == AbbConfig(0, 0, 0, 0)


def test_overhead_folded_elbow_wrist_negative(er20: Robot) -> None:
    # A2 = 60° tilts the upper arm back: elbow at (0.17 − 0.78 sin 60°, 0, 0.504 + 0.78 cos 60°)
    # = (−0.5055, 0, 0.894); A3 − A2 = 90° turns the forearm down: wrist centre at
    # (−0.5055 + 0.14, 0, 0.894 − 0.76) = (−0.3655, 0, 0.134): behind A1 (overhead);
    # (P3 − P2) × (W − P3) · y = 0.39·0.14 − 0.6755·0.76 < 0: elbow down; A5 = −30° < 0
    s = arm_structure(er20)
    q = np.radians([0.0, 60.0, 150.0, 0.0, -30.0, 0.0])
    b = branch_values(s, er20, q)
    assert b.shoulder == pytest.approx(-0.3655, abs=1e-4)
    assert b.elbow == pytest.approx(0.39 * 0.14 - 0.78 * math.sin(math.pi / 3) * 0.76, abs=1e-9)
    assert b.wrist == pytest.approx(math.radians(-30.0))
    kuka, fanuc, abb = _all(er20, [0.0, 60.0, 150.0, 0.0, -30.0, 0.0])
    assert (kuka.status, kuka.turn) == (0b101, 0b010000)
    assert fanuc.text() == "N D B, 0, 0, 0"
    assert abb == AbbConfig(0, 0, 0, 7)


def test_turns_and_quadrants(er20: Robot) -> None:
    kuka, fanuc, abb = _all(er20, [-100.0, -20.0, 30.0, 100.0, 45.0, -200.0])
    assert kuka.turn == 0b100011  # A1, A2, A6 < 0
    assert fanuc.turns == (0, 0, -1)  # J6 = −200° is turn −1
    assert (abb.cf1, abb.cf4, abb.cf6) == (-2, 1, -3)
    kuka, fanuc, abb = _all(er20, [100.0, -20.0, 30.0, -45.0, 45.0, 45.0])
    assert (abb.cf1, abb.cf4, abb.cf6) == (1, -1, 0)  # the RAPID manual's [1, -1, 0, …]
    assert _all(er20, [0.0, -20.0, 30.0, 0.0, 45.0, 200.0])[1].turns == (0, 0, 1)


def test_kuka_turn_documented_example(er20: Robot) -> None:
    # TU = 'B010011' = 19: A1 < 0, A2 < 0, A3 ≥ 0, A4 ≥ 0, A5 < 0, A6 ≥ 0
    assert _all(er20, [-10.0, -20.0, 30.0, 10.0, -40.0, 0.0])[0].turn == 19


def test_fanuc_turn_numbers() -> None:
    cases = {0.0: 0, 179.9: 0, -179.9: 0, 180.0: 1, -180.0: -1, 539.0: 1, 540.0: 2, -541.0: -2}
    for deg, turn in cases.items():
        assert fanuc_turn(math.radians(deg)) == turn, deg


def test_wrist_zero_and_forward_axis_of_builtins() -> None:
    for name in ("er20", "ur5", "ur10"):
        s = arm_structure(load_robot(name))
        assert s.wrist_zero == pytest.approx(0.0, abs=1e-12)
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


def test_windows_decode_what_was_encoded(er20: Robot) -> None:
    s = arm_structure(er20)
    q = np.radians([-100.0, -20.0, 30.0, 100.0, -45.0, -200.0])
    b = branch_values(s, er20, q)
    for cfg in (kuka_config(s, er20, q, b), fanuc_config(s, er20, q, b),
                abb_config(s, er20, q, b)):
        w = cfg.window(er20, s)
        assert w.accepts(b)
        assert np.all(w.lower <= q) and np.all(q <= w.upper)
        flipped = b._replace(wrist=-b.wrist)
        assert not w.accepts(flipped)


def test_refusals_name_the_robot_and_why() -> None:
    with pytest.raises(TeachError, match=r"panda.*7-axis arm|7-axis arm.*panda"):
        arm_structure(load_robot("panda"))
    ur5 = load_robot("ur5")
    s = arm_structure(ur5)
    q = np.radians([10.0, -200.0, 30.0, 10.0, 40.0, 10.0])  # J2 beyond ±180°: no turn number
    with pytest.raises(TeachError, match=r"joint 2 at -200\.000° lies outside what FANUC"):
        fanuc_config(s, ur5, q, branch_values(s, ur5, q))
    with pytest.raises(TeachError, match=r"joint 2 .* ABB.s confdata"):
        abb_config(s, ur5, q, branch_values(s, ur5, q))
    assert kuka_config(s, ur5, q, branch_values(s, ur5, q)).turn & 0b10  # KUKA: sign suffices
