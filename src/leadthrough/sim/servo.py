"""Position-mode servo of an industrial controller: cascaded position / velocity loop at 1 kHz.

Per joint::

    v_ref = Kp·(q_cmd − q̂) + q̇_ff
    τ_cmd = Kv·(v_ref − v̂) + ∫ Ki·(v_ref − v̂) dt
    i_cmd = clip(τ_cmd / (R·Kt), ±i_max)

q̂ is the encoder reading and v̂ its backward difference. The current loop is taken as ideal
(its bandwidth is far above 1 kHz). The integrator has conditional anti-windup: it stops
integrating while the current is saturated in the same direction.

Gains are designed once from the nominal model: Kv = J·ω_v, Ki = Kv·ω_v/4, Kp = ω_v/4, with J
the nominal joint inertia (link inertia at a mid-range pose plus rotor inertia) and ω_v the
velocity-loop bandwidth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.robot.description import Robot

__all__ = ["CascadedServo", "ServoGains", "design_servo_gains", "mid_range_link_inertia"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ServoGains:
    """Servo gains per joint, each shape (n,).

    Attributes:
        kp: Position gain [1/s].
        kv: Velocity gain [N·m·s/rad].
        ki: Velocity integral gain [N·m/rad].
    """

    kp: Array
    kv: Array
    ki: Array


def mid_range_link_inertia(robot: Robot) -> Array:
    """Diagonal of the nominal links' mass matrix at the middle of the joint ranges, the
    inertia each joint sees without its rotor [kg·m²], shape (n,)."""
    q = 0.5 * (robot.lower_limits + robot.upper_limits)
    return np.diag(pin.crba(robot.model, robot.model.createData(), q)).copy()


def design_servo_gains(robot: Robot, bandwidth_hz: float = 20.0) -> ServoGains:
    """Gains from the nominal joint inertia and a velocity-loop bandwidth.

    Args:
        robot: The robot (nominal model and rotor inertias).
        bandwidth_hz: Velocity-loop bandwidth [Hz].

    Returns:
        The gains.
    """
    inertia = mid_range_link_inertia(robot) + robot.reflected_rotor_inertia
    w = 2.0 * np.pi * bandwidth_hz
    kv = inertia * w
    return ServoGains(kp=np.full(robot.n, w / 4.0), kv=kv, ki=kv * w / 4.0)


class CascadedServo:
    """Cascaded position/velocity servo with preallocated state.

    Args:
        gains: Servo gains.
        torque_per_amp: R·Kt per joint [N·m/A], shape (n,).
        max_current: Current limit per joint [A], shape (n,).
    """

    def __init__(self, gains: ServoGains, torque_per_amp: Array, max_current: Array) -> None:
        self.gains = gains
        self._inv_tpa = 1.0 / np.asarray(torque_per_amp, dtype=float)
        self._imax = np.asarray(max_current, dtype=float)
        self._neg_imax = -self._imax
        n = self._imax.size
        self.integral = np.zeros(n)   # [N·m]
        self.current = np.zeros(n)    # last current command [A]
        self._q_prev = np.zeros(n)
        self._ev = np.zeros(n)
        self._tmp = np.zeros(n)
        self._hold = np.zeros(n, dtype=bool)      # anti-windup masks (no allocation per step)
        self._other = np.zeros(n, dtype=bool)
        self._below = np.zeros(n, dtype=bool)

    def reset(self, q: Array, holding_torque: Array) -> None:
        """Start settled at ``q`` delivering ``holding_torque`` [N·m] (integrator preset)."""
        self._q_prev[:] = q
        self.integral[:] = holding_torque
        np.multiply(holding_torque, self._inv_tpa, out=self.current)

    def update(self, q_meas: Array, q_cmd: Array, qd_ff: Array, dt: float) -> Array:
        """One servo cycle.

        Args:
            q_meas: Encoder positions [rad], shape (n,).
            q_cmd: Commanded positions [rad], shape (n,).
            qd_ff: Velocity feed-forward [rad/s], shape (n,).
            dt: Cycle time [s].

        Returns:
            Current command [A], shape (n,) (an internal buffer; copy to keep).
        """
        g = self.gains
        ev, tmp = self._ev, self._tmp
        # v_ref - v_meas
        np.subtract(q_cmd, q_meas, out=ev)
        ev *= g.kp
        ev += qd_ff
        np.subtract(q_meas, self._q_prev, out=tmp)
        tmp *= 1.0 / dt
        ev -= tmp
        self._q_prev[:] = q_meas
        # PI with conditional anti-windup.
        np.multiply(ev, g.ki * dt, out=tmp)
        # no integration where saturated the same way: (sat_hi & tmp > 0) | (sat_lo & tmp < 0)
        hold, other = self._hold, self._other
        np.greater_equal(self.current, self._imax, out=hold)
        hold &= np.greater(tmp, 0.0, out=other)
        np.less_equal(self.current, self._neg_imax, out=other)
        other &= np.less(tmp, 0.0, out=self._below)
        hold |= other
        np.copyto(tmp, 0.0, where=hold)
        self.integral += tmp
        np.multiply(ev, g.kv, out=tmp)
        tmp += self.integral
        tmp *= self._inv_tpa
        # clip(tmp, -imax, imax), without np.clip's per-call overhead on 6 values
        np.maximum(tmp, self._neg_imax, out=tmp)
        np.minimum(tmp, self._imax, out=self.current)
        return self.current
