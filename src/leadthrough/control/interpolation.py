"""From 10 ms joint setpoints to 1 ms position-mode commands (position and velocity, no steps).

The guiding controller produces, every controller cycle T (10 ms), the joint position q_k it
wants at the end of the cycle and the joint velocity q̇_k it moves with. The servo wants a command
every 1 ms. :class:`HermiteInterpolator` joins consecutive setpoints by cubic Hermite segments:

    q(s) = p₀ + h₀₁(s)·(p₁ − p₀) + T·(h₁₀(s)·v₀ + h₁₁(s)·v₁),  s = (t − t_k)/T ∈ [0, 1]
    h₀₁ = 3s² − 2s³,  h₁₀ = s³ − 2s² + s,  h₁₁ = s³ − s²

from the last command (p₀, v₀) to the new setpoint (p₁, v₁): position and velocity are continuous
at every 1 ms sample (C¹), and a held setpoint (p₁ = p₀, v = 0) gives exactly constant commands and
exactly zero velocity. With v₁ the segment's own mean velocity (the IK's q̇, which moves p₀ to p₁)
the path departs from the straight segment by at most 4/27·T·|v₀ − v₁|, a fraction of a
milliradian at the joint acceleration limits, well inside the IK's joint-limit margin.

:class:`leadthrough.control.jerk_limit.JerkLimitedInterpolator` has the same interface and adds
jerk limits (``ruckig``, optional). Both take the setpoint once per cycle (``set_target``) and
produce one command per ``update``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import joint_kernels
from leadthrough.errors import ControlError, check_period

__all__ = [
    "CommandBuffer",
    "HermiteInterpolator",
    "InterpolatorStatus",
    "JointCommand",
    "JointInterpolator",
]

Array = NDArray[np.float64]


class InterpolatorStatus(IntEnum):
    """Result of one interpolator update."""

    #: A command inside the current segment.
    WORKING = 0
    #: The command is the segment's end point (the next setpoint is due).
    FINISHED = 1
    #: Called again after the end without a new setpoint: holds the end position, q̇ = 0.
    STARVED = -1
    #: The interpolator failed (jerk-limited version only): holds the last command, q̇ = 0.
    ERROR = -2


@dataclass
class JointCommand:
    """One servo command, filled in place by an interpolator.

    Attributes:
        q: Joint position command [rad], shape (n,).
        qd: Joint velocity feed-forward [rad/s], shape (n,).
    """

    q: Array
    qd: Array


class CommandBuffer(Protocol):
    """What ``update`` writes into: anything with preallocated ``q`` and ``qd`` arrays of shape
    (n,) (a :class:`JointCommand`, or a driver's own command object)."""

    q: Array
    qd: Array


class JointInterpolator(Protocol):
    """Interface of the 10 ms → 1 ms interpolators."""

    def make_command(self) -> JointCommand:
        """A preallocated command."""
        ...

    def reset(self, q: Array) -> None:
        """Hold ``q`` at rest (shape (n,) [rad])."""
        ...

    def set_target(self, q: Array, qd: Array) -> None:
        """Start a new segment toward setpoint (q, q̇), reached one controller cycle later."""
        ...

    def update(self, out: CommandBuffer) -> InterpolatorStatus:
        """Advance by one servo period and write the command into ``out.q``, ``out.qd``."""
        ...


class HermiteInterpolator:
    """Cubic Hermite interpolation of controller setpoints (C¹, no steps).

    Args:
        n: Number of joints.
        period: Controller cycle T [s].
        substeps: Servo commands per controller cycle (10 for 10 ms → 1 ms).

    Raises:
        ControlError: ``period`` not positive or ``substeps`` < 1.
    """

    def __init__(self, n: int, period: float = 0.01, substeps: int = 10) -> None:
        check_period("period", period, ControlError)
        if substeps < 1:
            raise ControlError("out of range", field="substeps", value=substeps,
                               expected=">= 1")
        self.n = n
        self.period = period
        self.substeps = substeps
        s = np.arange(1, substeps + 1) / substeps
        # per substep: position basis (h01 and T·h10, T·h11) and velocity basis (h'/T)
        self._basis = np.column_stack([3 * s**2 - 2 * s**3, period * (s**3 - 2 * s**2 + s),
                                       period * (s**3 - s**2), (6 * s - 6 * s**2) / period,
                                       3 * s**2 - 4 * s + 1, 3 * s**2 - 2 * s])
        self._segment = np.zeros((7, n))  # rows joint_kernels.HERMITE_*
        self._k = substeps

    def make_command(self) -> JointCommand:
        """A preallocated command."""
        return JointCommand(q=np.zeros(self.n), qd=np.zeros(self.n))

    def reset(self, q: Array) -> None:
        """Hold ``q`` at rest (shape (n,) [rad])."""
        seg = self._segment
        seg[:] = 0.0
        seg[joint_kernels.HERMITE_Q] = q
        seg[joint_kernels.HERMITE_P1] = q
        self._k = self.substeps

    def set_target(self, q: Array, qd: Array) -> None:
        """New segment from the last command to (q, q̇) [rad, rad/s], shape (n,) each.

        A setpoint of the wrong size or not finite is ignored, like a missed one: the current
        segment runs to its end, then the end is held (``STARVED``); no command is ever NaN.
        """
        if joint_kernels.hermite_start(self._segment, q, qd):
            self._k = 0

    def update(self, out: CommandBuffer) -> InterpolatorStatus:
        """Advance one servo period and write the command into ``out.q``, ``out.qd``."""
        k = self._k
        if k < self.substeps:
            self._k = k + 1
        code = joint_kernels.hermite_step(self._segment, self._basis, k, out.q, out.qd)
        return _STATUS[code]


#: InterpolatorStatus by the code of ``joint_kernels.hermite_step``.
_STATUS = {joint_kernels.HERMITE_WORKING: InterpolatorStatus.WORKING,
           joint_kernels.HERMITE_FINISHED: InterpolatorStatus.FINISHED,
           joint_kernels.HERMITE_STARVED: InterpolatorStatus.STARVED}
