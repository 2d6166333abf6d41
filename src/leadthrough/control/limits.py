"""Cartesian speed and acceleration limits of the commanded TCP twist (paper Table IV).

Twists are 6-vectors in Pinocchio's order, linear first: ``(vx, vy, vz, ωx, ωy, ωz)`` [m/s,
rad/s]. The limits apply to the Euclidean norm of the linear part and of the angular part
separately (a per-axis clamp would allow √3 × the speed along a diagonal):

* speed: ‖v‖ ≤ v_max·s and ‖ω‖ ≤ ω_max·s, s ∈ [0, 1] a speed scale (singularity slow-down);
* acceleration: ‖Δv‖ ≤ a_max·dt and ‖Δω‖ ≤ α_max·dt per cycle.

The limiter first clips the desired twist to the speed ball, then moves from the previous twist
toward it by at most the acceleration step. Both balls are convex, so the result is inside the
speed ball whenever the previous twist was (a lowered speed scale is reached by decelerating at
a_max, never by a jump). :func:`decelerate_twist` is the step toward zero: a stop along a
straight line in velocity space at the acceleration limit, or slower when the joints need longer
to stop, which is how every stop (fault, deadman release) is made.

The limits are compiled (Numba, ``nopython``, cached on disk) and run inside the guiding cycle
(:mod:`leadthrough.control.guiding_cycle`): :func:`limit_twist`, :func:`decelerate_twist`,
:func:`twist_stop_cycles` and :func:`braking_distance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import ControlError, check_fields

__all__ = [
    "CartesianLimits",
    "braking_distance",
    "decelerate_twist",
    "limit_twist",
    "twist_stop_cycles",
]

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

    @property
    def max_speed(self) -> Array:
        """(v_max, ω_max) [m/s, rad/s], shape (2,)."""
        return np.array([self.max_linear_speed, self.max_angular_speed])

    def max_step(self, dt: float) -> Array:
        """Largest change of the speed per cycle of ``dt`` [s], (a_max·dt, α_max·dt) [m/s,
        rad/s], shape (2,)."""
        return np.array([self.max_linear_acceleration * dt, self.max_angular_acceleration * dt])


@njit(cache=True, nogil=True)
def braking_distance(linear_speed: float, max_acceleration: float, stop_time: float) -> float:
    """Distance the TCP travels while stopping from ``linear_speed`` [m].

    The discrete stop of :func:`decelerate_twist` lowers the speed linearly to zero over
    T = max(‖v‖/a_max, ``stop_time``) (position advanced with the new speed of each cycle) and
    so travels at most ‖v‖·T/2, which is v²/(2·a_max) when the Cartesian limit sets the pace.

    Args:
        linear_speed: ‖v‖ [m/s].
        max_acceleration: a_max [m/s²].
        stop_time: Lower bound on T [s], e.g. the time the joints need to stop at their
            acceleration limits.
    """
    return 0.5 * linear_speed * max(linear_speed / max_acceleration, stop_time)


@njit(cache=True, nogil=True)
def limit_twist(previous: Array, desired: Array, max_speed: Array, max_step: Array,
                speed_scale: float, out: Array) -> bool:
    """Speed ball then acceleration step, per linear / angular part (see
    :mod:`leadthrough.control.limits`).

    Args:
        previous: Twist of the last cycle, shape (6,).
        desired: Twist asked for, shape (6,) (may be ``out``).
        max_speed: (v_max, ω_max).
        max_step: (a_max·dt, α_max·dt).
        speed_scale: Factor of the speed limits.
        out: Result, shape (6,); must not be ``previous``.

    Returns:
        Whether a limit was active.
    """
    active = False
    for part in range(2):
        i = 3 * part
        a, b, c = desired[i], desired[i + 1], desired[i + 2]
        cap = max_speed[part] * speed_scale
        norm = math.sqrt(a * a + b * b + c * c)
        k = 1.0
        if norm > cap:
            k = cap / norm
            active = True
        da = a * k - previous[i]
        db = b * k - previous[i + 1]
        dc = c * k - previous[i + 2]
        step = max_step[part]
        dnorm = math.sqrt(da * da + db * db + dc * dc)
        if dnorm > step:
            s = step / dnorm
            da, db, dc = da * s, db * s, dc * s
            active = True
        out[i] = previous[i] + da
        out[i + 1] = previous[i + 1] + db
        out[i + 2] = previous[i + 2] + dc
    return active


@njit(cache=True, nogil=True)
def twist_stop_cycles(twist: Array, max_step: Array) -> float:
    """Cycles a stop at the acceleration limits takes: max(‖v‖/(a_max·dt), ‖ω‖/(α_max·dt)).

    Args:
        twist: Twist, shape (6,) [m/s, rad/s].
        max_step: (a_max·dt, α_max·dt).
    """
    n = 0.0
    for part in range(2):
        i = 3 * part
        a, b, c = twist[i], twist[i + 1], twist[i + 2]
        n = max(n, math.sqrt(a * a + b * b + c * c) / max_step[part])
    return n


@njit(cache=True, nogil=True)
def decelerate_twist(previous: Array, max_step: Array, min_cycles: float, out: Array) -> None:
    """One cycle of a proportional stop, exactly zero once reached (may alias).

    The stop takes n = max(‖v‖/(a_max·dt), ‖ω‖/(α_max·dt), ``min_cycles``) cycles and scales
    the whole twist by 1 − 1/n: a straight line in velocity space (the linear and angular
    parts end together), the dominant part at its acceleration limit.

    Args:
        previous: Twist of the last cycle, shape (6,).
        max_step: (a_max·dt, α_max·dt).
        min_cycles: Lower bound on n, e.g. the joints' own stop
            (:func:`leadthrough.control.joint_kernels.joint_stop_cycles`).
        out: Result, shape (6,).
    """
    n = max(min_cycles, twist_stop_cycles(previous, max_step))
    if n <= 1.0:
        for i in range(6):
            out[i] = 0.0
    else:
        k = 1.0 - 1.0 / n
        for i in range(6):
            out[i] = previous[i] * k
