"""The interface shared by the force-following laws (virtual friction, velocity baseline).

A law maps the operator's wrench to the next commanded TCP twist, one controller cycle at a time,
per Cartesian axis. Axes are in Pinocchio's order, linear first (the paper lists them angular
first): index 0–2 are x, y, z (force [N], velocity [m/s], mass [kg]), index 3–5 are ωx, ωy, ωz
(torque [N·m], angular velocity [rad/s], inertia [kg·m²]). Wrench, twist and friction are all
expressed in the same frame, the controller's (base axes at the TCP, or tool axes).

The law is stateless: the twist of the last cycle is passed in, so that the guiding controller
can apply speed and acceleration limits afterwards and feed the limited twist back (no wind-up),
and can swap laws without moving state around.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["AXIS_NAMES", "AdmittanceLaw"]

Array = NDArray[np.float64]

#: Cartesian axis names in twist / wrench order.
AXIS_NAMES: tuple[str, ...] = ("x", "y", "z", "rx", "ry", "rz")


class AdmittanceLaw(Protocol):
    """One cycle of a force-following law (before speed and acceleration limits).

    The guiding controller runs the law compiled, inside
    :func:`~leadthrough.control.guiding_kernel.guiding_step`: ``law_id`` names the kernel and
    ``coefficients`` / ``alpha`` are its parameters; ``step`` runs the same kernel alone.
    """

    #: The compiled law (``guiding_kernel.LAW_*``).
    law_id: int
    #: Its per-axis coefficients, shape (6,).
    coefficients: Array
    #: Its scalar coefficient (0.0 if it has none).
    alpha: float

    def step(self, twist: Array, wrench: Array, friction: Array, stopping_friction: Array,
             out: Array) -> None:
        """Desired twist after one cycle.

        Args:
            twist: Commanded twist of the last cycle, shape (6,) [m/s, rad/s].
            wrench: Operator wrench, shape (6,) [N, N·m] (force first).
            friction: Virtual friction δ per axis, shape (6,) [N, N·m] (laws without friction
                ignore it).
            stopping_friction: Friction once the force is removed, shape (6,) [N, N·m].
            out: Desired twist, shape (6,), written in place; must not alias an input.
        """
        ...
