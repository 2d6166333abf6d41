"""Cartesian speed and acceleration limits of the commanded TCP twist (paper Table IV).

Twists are 6-vectors in Pinocchio's order, linear first: ``(vx, vy, vz, ωx, ωy, ωz)`` [m/s,
rad/s]. The limits apply to the Euclidean norm of the linear part and of the angular part
separately (a per-axis clamp would allow √3 × the speed along a diagonal):

* speed: ‖v‖ ≤ v_max·s and ‖ω‖ ≤ ω_max·s, s ∈ [0, 1] a speed scale (singularity slow-down);
* acceleration: ‖Δv‖ ≤ a_max·dt and ‖Δω‖ ≤ α_max·dt per cycle.

The limiter first clips the desired twist to the speed ball, then moves from the previous twist
toward it by at most the acceleration step. Both balls are convex, so the result is inside the
speed ball whenever the previous twist was (a lowered speed scale is reached by decelerating at
a_max, never by a jump). :meth:`TwistLimiter.decelerate` is the step toward zero: a stop along a
straight line in velocity space at the acceleration limit, or slower when the joints need longer
to stop, which is how every stop (fault, deadman release) is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import kernels
from leadthrough.errors import ControlError, check_fields, check_period

__all__ = ["CartesianLimits", "TwistLimiter"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CartesianLimits:
    """Speed and acceleration limits of the TCP, validated once (defaults: paper Table IV).

    Attributes:
        max_linear_speed: v_max [m/s].
        max_angular_speed: ω_max [rad/s].
        max_linear_acceleration: a_max [m/s²].
        max_angular_acceleration: α_max [rad/s²].
    """

    max_linear_speed: float = 0.2
    max_angular_speed: float = 0.2
    max_linear_acceleration: float = 0.4
    max_angular_acceleration: float = 0.4

    def __post_init__(self) -> None:
        check_fields("limits", self, [
            (name, math.isfinite(getattr(self, name)) and getattr(self, name) > 0,
             "finite and > 0")
            for name in ("max_linear_speed", "max_angular_speed", "max_linear_acceleration",
                         "max_angular_acceleration")
        ], ControlError)

    def braking_distance(self, linear_speed: float, stop_time: float = 0.0) -> float:
        """Distance the TCP travels while stopping from ``linear_speed`` [m].

        The discrete stop of :meth:`TwistLimiter.decelerate` lowers the speed linearly to zero
        over T = max(‖v‖/a_max, ``stop_time``) (position advanced with the new speed of each
        cycle) and so travels at most ‖v‖·T/2, which is v²/(2·a_max) when the Cartesian limit
        sets the pace.

        Args:
            linear_speed: ‖v‖ [m/s].
            stop_time: Lower bound on T [s], e.g. the time the joints need to stop at their
                acceleration limits.
        """
        return 0.5 * linear_speed * max(linear_speed / self.max_linear_acceleration, stop_time)


class TwistLimiter:
    """Applies :class:`CartesianLimits` to a commanded twist, one controller cycle at a time.

    Args:
        limits: The limits.
        dt: Controller cycle [s].

    Raises:
        ControlError: ``dt`` not finite and positive.
    """

    def __init__(self, limits: CartesianLimits, dt: float) -> None:
        check_period("dt", dt, ControlError)
        self.limits = limits
        self.dt = dt
        #: (v_max, ω_max) [m/s, rad/s].
        self.max_speed = np.array([limits.max_linear_speed, limits.max_angular_speed])
        #: Largest change of the speed per cycle, (a_max·dt, α_max·dt) [m/s, rad/s].
        self.max_step = np.array([limits.max_linear_acceleration * dt,
                                  limits.max_angular_acceleration * dt])

    def limit(self, previous: Array, desired: Array, speed_scale: float, out: Array) -> bool:
        """Limit speed and acceleration.

        Args:
            previous: Twist of the last cycle, shape (6,) [m/s, rad/s].
            desired: Twist asked for, shape (6,) (not modified).
            speed_scale: s ∈ [0, 1] multiplying both speed limits.
            out: Result, shape (6,); may be ``desired`` but not ``previous``.

        Returns:
            Whether a limit was active.
        """
        return bool(kernels.limit_twist(previous, desired, self.max_speed, self.max_step,
                                        speed_scale, out))

    def stop_cycles(self, twist: Array) -> float:
        """Cycles a stop at the acceleration limits takes: max(‖v‖/(a_max·dt), ‖ω‖/(α_max·dt)).

        Args:
            twist: Twist, shape (6,) [m/s, rad/s].
        """
        return float(kernels.twist_stop_cycles(twist, self.max_step))

    def decelerate(self, previous: Array, out: Array, min_cycles: float = 0.0) -> None:
        """One cycle of a stop at the acceleration limit (exactly zero once reached).

        The whole twist is scaled down by the same factor each cycle (a straight line in
        velocity space, linear and angular parts ending together), so that the stop takes
        max(‖v‖/(a_max·dt), ‖ω‖/(α_max·dt), ``min_cycles``) cycles.

        Args:
            previous: Twist of the last cycle, shape (6,).
            out: Result, shape (6,); may be ``previous``.
            min_cycles: Fewest cycles the stop may take, e.g. those the joints need to stop
                at their own acceleration limits (slower than the Cartesian limit near a
                singularity), so that the joints can follow the decelerating twist.
        """
        kernels.decelerate_twist(previous, self.max_step, min_cycles, out)
