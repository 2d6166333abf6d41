"""Optional jerk-limited 10 ms → 1 ms interpolation with Ruckig (free version).

``pip install ruckig`` to use it; it is not a dependency of leadthrough, and this module imports
it only when a :class:`JerkLimitedInterpolator` is built (a clear :class:`ControlError` says so
if it is missing).

Every controller cycle the setpoint (q_k, q̇_k) becomes Ruckig's target state, with the change
of q̇ over the cycle as target acceleration (0 for a setpoint at rest), so that a steady
deceleration is not broken into stops at every setpoint. Ruckig then produces one state per servo
period within the joint velocity, acceleration and jerk limits, time-optimally toward the latest
target. Same interface as :class:`leadthrough.control.interpolation.HermiteInterpolator`: C²
instead of C¹, at a price: setpoints whose acceleration changes faster than the jerk limit allows
(the start and the end of every stop) are followed with a lag of a few milliradians, and the
catch-up can overshoot a setpoint slightly (tenths of a milliradian at the joint acceleration
limits, inside the IK's joint-limit margin). The Hermite interpolator is the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.interpolation import CommandBuffer, InterpolatedCommand, InterpolatorStatus
from leadthrough.errors import ControlError, check_fields
from leadthrough.robot.description import Robot

__all__ = ["JerkLimitConfig", "JerkLimitedInterpolator"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class JerkLimitConfig:
    """Settings of the jerk-limited interpolator, validated once.

    Attributes:
        period: Controller cycle [s] (the spacing of the setpoints).
        servo_period: Servo cycle [s] (the spacing of the commands).
        velocity_scale: Fraction of the robot's joint speed limits, in (0, 1].
        acceleration_scale: Fraction of the robot's joint acceleration limits, in (0, 1].
        jerk_per_acceleration: Jerk limit as a multiple of the acceleration limit [1/s]
            (20: full acceleration is built up in 50 ms).
    """

    period: float = 0.01
    servo_period: float = 0.001
    velocity_scale: float = 1.0
    acceleration_scale: float = 1.0
    jerk_per_acceleration: float = 20.0

    def __post_init__(self) -> None:
        check_fields("jerk_limit", self, [
            ("period", math.isfinite(self.period) and self.period > 0, "> 0 s"),
            ("servo_period", 0 < self.servo_period <= self.period, "0 < servo_period <= period"),
            ("velocity_scale", 0 < self.velocity_scale <= 1, "0 < scale <= 1"),
            ("acceleration_scale", 0 < self.acceleration_scale <= 1, "0 < scale <= 1"),
            ("jerk_per_acceleration",
             math.isfinite(self.jerk_per_acceleration) and self.jerk_per_acceleration > 0,
             "> 0 1/s"),
        ], ControlError)


def _import_ruckig() -> Any:
    try:
        import ruckig
    except ImportError as e:
        raise ControlError("the optional package 'ruckig' is not installed",
                           field="interpolator", value="jerk-limited",
                           expected="'pip install ruckig', or the Hermite interpolator") from e
    return ruckig


class JerkLimitedInterpolator:
    """Jerk-limited interpolation of controller setpoints with Ruckig (a
    :class:`~leadthrough.control.interpolation.JointInterpolator`).

    Args:
        robot: The robot (joint speed and acceleration limits).
        config: Settings.

    Raises:
        ControlError: ``ruckig`` is not installed.
    """

    def __init__(self, robot: Robot, config: JerkLimitConfig | None = None) -> None:
        self.config = cfg = config if config is not None else JerkLimitConfig()
        rk = _import_ruckig()
        self.n = n = robot.n
        self._ok = (rk.Result.Working, rk.Result.Finished)
        self._finished = rk.Result.Finished
        self._otg = rk.Ruckig(n, cfg.servo_period)
        self._inp = rk.InputParameter(n)
        self._out = rk.OutputParameter(n)
        amax = robot.acceleration_limit * cfg.acceleration_scale
        self._inp.max_velocity = (robot.velocity_limit * cfg.velocity_scale).tolist()
        self._inp.max_acceleration = amax.tolist()
        self._inp.max_jerk = (amax * cfg.jerk_per_acceleration).tolist()
        self._zero = [0.0] * n
        self._amax = amax
        self._neg_amax = -amax
        self._q = np.zeros(n)
        self._qd_prev = np.zeros(n)
        self._acc = np.zeros(n)
        self._rest = np.zeros(n, dtype=bool)

    def make_command(self) -> InterpolatedCommand:
        """A preallocated command."""
        return InterpolatedCommand(q=np.zeros(self.n), qd=np.zeros(self.n))

    def reset(self, q: Array) -> None:
        """Hold ``q`` at rest (shape (n,) [rad])."""
        qs = np.asarray(q, dtype=float).tolist()
        self._q[:] = q
        self._qd_prev[:] = 0.0
        self._inp.current_position = qs
        self._inp.current_velocity = self._zero
        self._inp.current_acceleration = self._zero
        self._inp.target_position = qs
        self._inp.target_velocity = self._zero
        self._inp.target_acceleration = self._zero

    def set_target(self, q: Array, qd: Array) -> None:
        """New target state (q, q̇) [rad, rad/s], shape (n,) each, due one cycle later.

        The target acceleration is the change of q̇ since the last setpoint over one cycle (0
        for joints whose setpoint is at rest).
        """
        np.subtract(qd, self._qd_prev, out=self._acc)
        self._acc *= 1.0 / self.config.period
        np.clip(self._acc, self._neg_amax, self._amax, out=self._acc)
        np.equal(qd, 0.0, out=self._rest)
        np.copyto(self._acc, 0.0, where=self._rest)
        self._qd_prev[:] = qd
        self._inp.target_position = q.tolist()
        self._inp.target_velocity = qd.tolist()
        self._inp.target_acceleration = self._acc.tolist()

    def warm_up(self) -> None:
        """Nothing to prepare (``ruckig`` is compiled ahead of time)."""

    def update(self, out: CommandBuffer) -> InterpolatorStatus:
        """Advance one servo period and write the command into ``out.q``, ``out.qd``."""
        result = self._otg.update(self._inp, self._out)
        if result not in self._ok:
            out.q[:] = self._q
            out.qd[:] = 0.0
            return InterpolatorStatus.ERROR
        self._out.pass_to_input(self._inp)
        out.q[:] = self._out.new_position
        out.qd[:] = self._out.new_velocity
        self._q[:] = out.q
        if result == self._finished:
            return InterpolatorStatus.FINISHED
        return InterpolatorStatus.WORKING
