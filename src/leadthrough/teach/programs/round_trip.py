"""The round trip of a program language on random poses: joints → program text → parsed → joints.

For each sampled joint configuration ``q`` (random within the joint limits, every shoulder,
elbow and wrist branch the limits allow), a program moving there is rendered, read back with the
language's parser and solved back with :func:`~leadthrough.teach.programs.parsed.solve_back`;
the figure is the largest joint difference [deg]. URScript has no configuration data: its
``movel`` is solved from the previous move's joints, so each pose gets a program that first moves
(``movej``) to a configuration a few degrees away on the same branch, as a taught path's previous
waypoint is.

Used by ``tests/test_programs_round_trip.py`` (asserting ≤ 0.01°) and
``benchmarks/program_round_trip.py`` (printing the figures).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.description import Robot
from leadthrough.robot.inverse_kinematics import pose_of
from leadthrough.teach.programs import LANGUAGES, target_configurations
from leadthrough.teach.programs.parsed import solve_back
from leadthrough.teach.programs.targets import ProgramOptions, ProgramTarget

__all__ = ["SINGULARITY_MARGIN_DEG", "round_trip_errors", "sample_configurations"]

Array = NDArray[np.float64]

SINGULARITY_MARGIN_DEG = 10.0  # wrist: |A5 − q5⁰| and |180° − |A5 − q5⁰|| at least this
_SHOULDER_MARGIN_M = 0.02  # wrist point at least this far from the A1 plane
_ELBOW_MARGIN_M2 = 0.01  # |elbow indicator| at least this (a few degrees off the stretched arm)
_PRINCIPAL = math.radians(179.0)  # J2, J3, J5: FANUC and ABB carry no turn for them


def sample_configurations(robot: Robot, count: int, seed: int) -> Array:
    """Random joint configurations within the limits, away from the singularities.

    Joints 2, 3 and 5 stay within ±179° (FANUC and ABB give them no turn number); the
    branch indicators keep the margins of this module (a program's decimals cannot pin a
    pose down at a singularity).

    Args:
        robot: A 6-axis robot.
        count: Number of configurations.
        seed: Random seed.

    Returns:
        Joint positions [rad], shape (count, 6).
    """
    structure = arm_structure(robot)
    data = robot.model.createData()
    rng = np.random.default_rng(seed)
    lo, hi = robot.lower_limits.copy(), robot.upper_limits.copy()
    for j in (1, 2, 4):
        lo[j], hi[j] = max(lo[j], -_PRINCIPAL), min(hi[j], _PRINCIPAL)
    out: list[Array] = []
    margin = math.radians(SINGULARITY_MARGIN_DEG)
    while len(out) < count:
        q = rng.uniform(lo, hi)
        b = branch_values(structure, robot, q, data)
        if (abs(b.shoulder) >= _SHOULDER_MARGIN_M and abs(b.elbow) >= _ELBOW_MARGIN_M2
                and margin <= abs(b.wrist) <= math.pi - margin):
            out.append(q)
    return np.array(out)


def _target(robot: Robot, q: Array) -> ProgramTarget:
    return ProgramTarget("", q, pose_of(robot, q), True, 0.5, 0.1)


def _render_parse_solve(robot: Robot, language: str, qs: Array, options: ProgramOptions) -> Array:
    lang = LANGUAGES[language]
    targets = [_target(robot, q) for q in qs]
    configs = target_configurations(language, robot, targets, options.joint_space)
    files = lang.render(targets, configs, options, [])
    return solve_back(lang.parse(files), robot)


def round_trip_errors(robot: Robot, language: str, qs: Array, *, joint_space: bool = False,
                      seed: int = 0) -> Array:
    """Largest joint difference [deg] per configuration after the program round trip.

    Args:
        robot: The robot.
        language: ``urscript``, ``krl``, ``tp`` or ``rapid``.
        qs: Joint configurations [rad], shape (K, n).
        joint_space: Joint moves instead of poses with configuration data.
        seed: Random seed of URScript's previous-waypoint offsets.

    Returns:
        Errors [deg], shape (K,).
    """
    options = ProgramOptions(name="round_trip", speed_m_s=0.1, zone_mm=0.0,
                             joint_space=joint_space)
    if language != "urscript" or joint_space:
        start = robot.neutral()[None, :]
        q = _render_parse_solve(robot, language, np.vstack([start, qs]), options)[1:]
        return np.asarray(np.degrees(np.abs(q - qs)).max(axis=1))
    rng = np.random.default_rng(seed)
    errs = []
    for q in qs:
        prev = np.clip(q + rng.normal(0.0, math.radians(2.0), q.size), robot.lower_limits,
                       robot.upper_limits)
        back = _render_parse_solve(robot, language, np.vstack([prev, q]), options)[1]
        errs.append(float(np.degrees(np.abs(back - q)).max()))
    return np.array(errs)
