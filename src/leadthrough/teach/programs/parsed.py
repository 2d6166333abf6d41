"""What a program file says, read back: its moves (joints, or a pose with configuration data) and
its tool; and the joints a controller reaches for them, solved with our inverse kinematics.

Used after every export (the written text is parsed and solved back, and must give the taught
joints to :data:`ROUND_TRIP_TOLERANCE_DEG`) and by the tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.description import Robot
from leadthrough.robot.inverse_kinematics import solve_near, solve_pose
from leadthrough.teach.programs.configuration import AbbConfig, FanucConfig, KukaConfig

__all__ = ["ROUND_TRIP_TOLERANCE_DEG", "ParsedMove", "ParsedProgram", "check_round_trip",
           "solve_back"]

Array = NDArray[np.float64]

ROUND_TRIP_TOLERANCE_DEG = 0.01


@dataclass(frozen=True)
class ParsedMove:
    """One move of a program file.

    Attributes:
        q_deg: Joint angles [deg] of a joint move, or None.
        pose: Programmed TCP (tool included) in the base frame of a Cartesian move, or None.
        config: Configuration data of the Cartesian move (None in URScript).
    """

    q_deg: tuple[float, ...] | None = None
    pose: pin.SE3 | None = None
    config: KukaConfig | FanucConfig | AbbConfig | None = None


@dataclass(frozen=True)
class ParsedProgram:
    """The moves of a program file, its tool (TCP relative to the robot's TCP frame) and its
    program name (as the file declares it)."""

    moves: tuple[ParsedMove, ...]
    tool: pin.SE3 = field(default_factory=pin.SE3.Identity)
    name: str = ""


def _solve_configured(robot: Robot, flange: pin.SE3,
                      config: KukaConfig | FanucConfig | AbbConfig, index: int) -> Array:
    structure = arm_structure(robot)
    window = config.window(robot, structure)
    data = robot.model.createData()
    sols = solve_pose(robot, flange, (window.lower, window.upper),
                      lambda q: window.accepts(branch_values(structure, robot, q, data)))
    if not sols:
        raise TeachError(f"move {index}: no joint solution of the pose in its configuration",
                         field=f"moves[{index}]", value=str(config),
                         expected="a pose reachable in the stated configuration")
    if len(sols) > 1:
        raise TeachError(f"move {index}: the configuration does not single out one joint "
                         "solution (" + "; ".join(
                             ", ".join(f"{math.degrees(v):.3f}" for v in q) for q in sols)
                         + " deg)", field=f"moves[{index}]", value=str(config),
                         expected="one solution per configuration")
    return sols[0]


def solve_back(parsed: ParsedProgram, robot: Robot) -> Array:
    """The joints [rad] a controller reaches for each move, shape (K, n).

    Joint moves give their angles. A pose with configuration data is solved with
    :func:`~leadthrough.robot.inverse_kinematics.solve_pose` inside the configuration (the only
    solution there, else an error). A pose without (URScript ``movel``) is solved nearest the
    previous move's joints, as UR's controller does.

    Raises:
        TeachError: A pose without a solution in its configuration, with several, or a URScript
            pose before any joint move.
    """
    out: list[Array] = []
    inv_tool = parsed.tool.inverse()
    for i, move in enumerate(parsed.moves):
        if move.q_deg is not None:
            out.append(np.radians(np.asarray(move.q_deg, dtype=float)))
            continue
        assert move.pose is not None
        flange = move.pose * inv_tool
        if move.config is not None:
            out.append(_solve_configured(robot, flange, move.config, i))
        elif out:
            res = solve_near(robot, flange, out[-1])
            if not res.converged:
                raise TeachError(f"move {i}: no joint solution near the previous move",
                                 field=f"moves[{i}]", value=round(res.error, 9),
                                 expected="a reachable pose")
            out.append(res.q)
        else:
            raise TeachError("a linear move before any joint move", field="moves[0]",
                             expected="a joint move first (movej)")
    return np.array(out)


def check_round_trip(parsed: ParsedProgram, robot: Robot, q_taught: Array,
                     language: str, joint_moves: Sequence[bool] | None = None) -> float:
    """Compare every move read back with the move written: count, kind and joints, in order.

    Args:
        parsed: The program as written, read back.
        robot: The robot.
        q_taught: Joints of each move written [rad], shape (K, n).
        language: For messages.
        joint_moves: Whether each move written is a joint move (else a pose), K values, or
            None not to compare the kinds.

    Returns:
        The largest joint difference [deg].

    Raises:
        TeachError: Another number of moves than written (a move added or missing), a move of
            another kind, or a joint difference above :data:`ROUND_TRIP_TOLERANCE_DEG`, naming
            the move and joint.
    """
    q_taught = np.atleast_2d(np.asarray(q_taught, dtype=float))
    if len(parsed.moves) != q_taught.shape[0]:
        raise TeachError(f"the {language} program holds {len(parsed.moves)} moves, "
                         f"{q_taught.shape[0]} were written", field="moves",
                         value=len(parsed.moves),
                         expected=f"exactly the {q_taught.shape[0]} moves written, in order")
    if joint_moves is not None:
        for i, (move, joint) in enumerate(zip(parsed.moves, joint_moves, strict=True)):
            if (move.q_deg is not None) != joint:
                raise TeachError(f"the {language} program's move {i} is a "
                                 f"{'joint' if move.q_deg is not None else 'linear'} move, "
                                 f"a {'joint' if joint else 'linear'} move was written",
                                 field=f"moves[{i}]", expected="the moves written, in order")
    q = solve_back(parsed, robot)
    if q.shape != q_taught.shape:
        raise TeachError(f"the {language} program's moves have {q.shape[-1]} joints",
                         field="moves", value=q.shape[-1],
                         expected=f"{q_taught.shape[1]} joints per move")
    err = np.degrees(np.abs(q - q_taught))
    worst = float(err.max()) if err.size else 0.0
    if not worst <= ROUND_TRIP_TOLERANCE_DEG:
        i, j = (int(v) for v in np.unravel_index(int(np.argmax(np.nan_to_num(err, nan=np.inf))),
                                                 err.shape))
        raise TeachError(f"the {language} program does not give back the taught joints: move "
                         f"{i}, joint {j + 1} differs by {worst:.4f}°", field=f"moves[{i}]",
                         value=round(worst, 4),
                         expected=f"≤ {ROUND_TRIP_TOLERANCE_DEG}° (a pose too close to a "
                                  "singularity for the file's decimals; export joint "
                                  "positions instead: --joint-space)")
    return worst
