"""Vendor configuration data of a joint configuration, and back: KUKA Status/Turn, FANUC
configuration string with turn numbers, ABB ``confdata``.

Each is computed from the branch indicators of :mod:`leadthrough.robot.arm_configuration`
(shoulder ``s``, elbow ``e``, wrist ``w``) and the joint angles, and each decodes into what it
says about the joints: the branch, and a window per joint (turn) that inverse kinematics must
respect.

KUKA (KUKA System Software 8.3, Operating and Programming Instructions for System Integrators,
"Status" and "Turn"): ``S = bit0 + 2·bit1 + 4·bit2`` with bit 0 = 1 in the overhead area
(wrist point x < 0 in the A1 frame, ``s < 0``), bit 1 = 1 for ``A3 ≥ φ`` (the elbow bent up,
``e ≥ 0``), bit 2 = 1 for ``A5 ≤ 0`` (``w ≤ 0``); ``T`` has bit i−1 = 1 for ``Ai < 0``. A joint
window is then [0, upper] or [lower, 0): a joint whose range exceeds 360° on one side of zero
cannot be told from its next turn, and is refused.

FANUC (configuration ``'F U T, t1, t4, t6'``: wrist Flip/No-flip, arm Up/Down, arm front (Top)
or Back, turn numbers of J1, J4, J6; the turn number of an angle θ is ``floor((θ + 180°)/360°)``
for θ ≥ 0 and ``−floor((180° − θ)/360°)`` for θ < 0, so 0 covers (−180°, 180°), as in RoboDK's
public FANUC post-processor ``Fanuc_R30iA.py``, which also states "F means axis 5 >= 0, N means
axis 5 < 0"; examples ``NUT 000`` / ``FUT 000`` in onerobotics.com, "The perils of six-axis
robots"): F for ``w ≥ 0``, U for ``e ≥ 0``, T for ``s ≥ 0``. J2, J3, J5 carry no turn number:
their taught angle must lie in (−180°, 180°) or export is refused.

ABB (RAPID reference manual, data type ``confdata``): ``cf1``, ``cf4``, ``cf6`` are the quadrant
numbers ``floor(θ / 90°)`` of axes 1, 4, 6 (0 for 0…90°, −1 for −90…0°); ``cfx = 4·[wrist
centre behind axis 1] + 2·[wrist centre behind the lower arm] + [axis 5 negative]``, i.e.
``4·[s < 0] + 2·[e < 0] + [w < 0]``. Axes 2, 3, 5 as for FANUC.

The indicators are the vendors' definitions applied to the robot file's joints (whose angles the
joint-space programs carry): on a vendor arm with the vendor's zero and directions they are the
vendor's own bits; on another arm they keep their geometric meaning.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.robot.arm_configuration import ArmStructure, BranchValues
from leadthrough.robot.description import Robot

__all__ = ["AbbConfig", "ConfigWindow", "FanucConfig", "KukaConfig", "abb_config",
           "fanuc_config", "fanuc_turn", "kuka_config"]

Array = NDArray[np.float64]

_PRINCIPAL = (-math.pi, math.pi)


@dataclass(frozen=True)
class ConfigWindow:
    """What a configuration says about the joints.

    Attributes:
        back: Wrist point behind A1 (``s < 0``).
        elbow_up: Elbow bent up (``e ≥ 0``).
        wrist: Predicate on the wrist indicator ``w`` [rad].
        lower: Lowest joint angles allowed [rad], shape (n,) (joint limits included).
        upper: Highest joint angles allowed [rad], shape (n,).
    """

    back: bool
    elbow_up: bool
    wrist: Callable[[float], bool]
    lower: Array
    upper: Array

    def accepts(self, b: BranchValues) -> bool:
        """True if indicators ``b`` match the configuration."""
        return (b.shoulder < 0.0) == self.back and (b.elbow >= 0.0) == self.elbow_up \
            and self.wrist(b.wrist)


def _window(robot: Robot, windows: dict[int, tuple[float, float]], what: str,
            q: Array | None = None) -> tuple[Array, Array]:
    """Joint limits intersected with ``windows``; unnamed joints keep (−π, π) for FANUC/ABB."""
    lo, hi = robot.lower_limits.copy(), robot.upper_limits.copy()
    for j, (a, b) in windows.items():
        lo[j], hi[j] = max(lo[j], a), min(hi[j], b)
        if hi[j] - lo[j] > 2.0 * math.pi + 1e-9:
            raise TeachError(f"joint {j + 1} turns more than 360° on one side of zero: {what} "
                             "cannot tell its angle from the next turn", field="robot",
                             value=robot.name, expected="export joint positions instead "
                                                        "(--joint-space)")
    if q is not None:
        for j in range(robot.n):
            if not lo[j] - 1e-9 <= q[j] <= hi[j] + 1e-9:
                raise TeachError(f"joint {j + 1} at {math.degrees(q[j]):.3f}° lies outside "
                                 f"what {what} can express", field=f"q{j + 1}",
                                 value=round(math.degrees(q[j]), 3),
                                 expected=f"[{math.degrees(lo[j]):.1f}°, "
                                          f"{math.degrees(hi[j]):.1f}°]; export joint "
                                          "positions instead (--joint-space)")
    return lo, hi


# -------------------------------------------------------------------------------------- KUKA
@dataclass(frozen=True)
class KukaConfig:
    """KUKA Status and Turn of an ``E6POS``.

    Attributes:
        status: S, bits 0–2 (0 … 7).
        turn: T, bit i−1 set for ``Ai < 0`` (0 … 63).
    """

    status: int
    turn: int

    def window(self, robot: Robot, structure: ArmStructure) -> ConfigWindow:
        """The branch and sign windows this Status/Turn allows."""
        w = {j: ((-math.inf, -1e-12) if self.turn >> i & 1 else (0.0, math.inf))
             for i, j in enumerate(structure.axes)}
        lo, hi = _window(robot, w, "KUKA's Turn")
        wrist_neg = bool(self.status & 4)
        return ConfigWindow(bool(self.status & 1), bool(self.status & 2),
                            lambda v: (v <= 0.0) == wrist_neg, lo, hi)


def kuka_config(structure: ArmStructure, robot: Robot, q: Array, b: BranchValues) -> KukaConfig:
    """Status and Turn of joint positions ``q`` [rad] with indicators ``b``."""
    status = int(b.shoulder < 0.0) | int(b.elbow >= 0.0) << 1 | int(b.wrist <= 0.0) << 2
    turn = sum(1 << i for i, j in enumerate(structure.axes) if q[j] < 0.0)
    cfg = KukaConfig(status, turn)
    cfg.window(robot, structure)  # refuses joints whose sign does not name the turn
    return cfg


# ------------------------------------------------------------------------------------- FANUC
def fanuc_turn(angle: float) -> int:
    """FANUC turn number of a joint angle [rad]: 0 for (−180°, 180°), 1 for [180°, 540°) …"""
    deg = math.degrees(angle)
    return math.floor((deg + 180.0) / 360.0) if deg >= 0.0 else -math.floor((180.0 - deg) / 360.0)


def _turn_window(t: int) -> tuple[float, float]:
    """Angles [rad] of turn number ``t`` (0: (−180°, 180°))."""
    a, b = math.radians(360.0 * t - 180.0), math.radians(360.0 * t + 180.0)
    return (a + (1e-12 if t <= 0 else 0.0), b - (1e-12 if t >= 0 else 0.0))


@dataclass(frozen=True)
class FanucConfig:
    """FANUC configuration string.

    Attributes:
        flip: ``F`` (True) or ``N``.
        up: ``U`` (True) or ``D``.
        front: ``T`` (True) or ``B``.
        turns: Turn numbers of J1, J4, J6.
    """

    flip: bool
    up: bool
    front: bool
    turns: tuple[int, int, int]

    def text(self) -> str:
        """The string as in ``CONFIG : 'N U T, 0, 0, 0'``."""
        letters = f"{'F' if self.flip else 'N'} {'U' if self.up else 'D'} " \
                  f"{'T' if self.front else 'B'}"
        return f"{letters}, {self.turns[0]}, {self.turns[1]}, {self.turns[2]}"

    def window(self, robot: Robot, structure: ArmStructure,
               q: Array | None = None) -> ConfigWindow:
        """The branch and joint windows this configuration allows."""
        a = structure.axes
        w = {j: _PRINCIPAL for j in a}
        for t, j in zip(self.turns, (a[0], a[3], a[5]), strict=True):
            w[j] = _turn_window(t)
        lo, hi = _window(robot, w, "FANUC's configuration (turns of J1, J4, J6 only)", q)
        flip = self.flip
        return ConfigWindow(not self.front, self.up, lambda v: (v >= 0.0) == flip, lo, hi)


def fanuc_config(structure: ArmStructure, robot: Robot, q: Array,
                 b: BranchValues) -> FanucConfig:
    """FANUC configuration of joint positions ``q`` [rad] with indicators ``b``.

    Raises:
        TeachError: J2, J3 or J5 outside (−180°, 180°) (no turn number carries them).
    """
    a = structure.axes
    cfg = FanucConfig(b.wrist >= 0.0, b.elbow >= 0.0, b.shoulder >= 0.0,
                      (fanuc_turn(q[a[0]]), fanuc_turn(q[a[3]]), fanuc_turn(q[a[5]])))
    cfg.window(robot, structure, q)
    return cfg


# --------------------------------------------------------------------------------------- ABB
@dataclass(frozen=True)
class AbbConfig:
    """ABB ``confdata`` [cf1, cf4, cf6, cfx]."""

    cf1: int
    cf4: int
    cf6: int
    cfx: int

    def window(self, robot: Robot, structure: ArmStructure,
               q: Array | None = None) -> ConfigWindow:
        """The branch and quadrant windows this confdata allows."""
        a = structure.axes
        w = {j: _PRINCIPAL for j in a}
        for cf, j in zip((self.cf1, self.cf4, self.cf6), (a[0], a[3], a[5]), strict=True):
            w[j] = (math.radians(90.0 * cf), math.radians(90.0 * (cf + 1)) - 1e-12)
        lo, hi = _window(robot, w, "ABB's confdata (quadrants of axes 1, 4, 6 only)", q)
        negative = bool(self.cfx & 1)
        return ConfigWindow(bool(self.cfx & 4), not self.cfx & 2,
                            lambda v: (v < 0.0) == negative, lo, hi)


def _quadrant(angle: float) -> int:
    return math.floor(math.degrees(angle) / 90.0)


def abb_config(structure: ArmStructure, robot: Robot, q: Array, b: BranchValues) -> AbbConfig:
    """ABB confdata of joint positions ``q`` [rad] with indicators ``b``.

    Raises:
        TeachError: Axis 2, 3 or 5 outside (−180°, 180°) (no quadrant number carries them).
    """
    a = structure.axes
    cfx = 4 * int(b.shoulder < 0.0) + 2 * int(b.elbow < 0.0) + int(b.wrist < 0.0)
    cfg = AbbConfig(_quadrant(q[a[0]]), _quadrant(q[a[3]]), _quadrant(q[a[5]]), cfx)
    cfg.window(robot, structure, q)
    return cfg
