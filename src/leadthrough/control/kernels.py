"""Compiled inner loops of the guiding controller (Numba, ``nopython``, cached on disk).

The controller's cycle is small-vector work (6 joints, 6 axes): each NumPy call costs more in
dispatch than in arithmetic, and the cycle needs dozens. These kernels fuse each step into one
compiled call, with the same arithmetic as the NumPy reference they replace (the modules that
call them document the algorithms: :mod:`~leadthrough.control.safety`,
:mod:`~leadthrough.control.virtual_friction`, :mod:`~leadthrough.control.limits`,
:mod:`~leadthrough.control.guiding`). ``benchmarks/guiding.py`` measures the cycle.

All kernels write into preallocated arrays and return a scalar or nothing; none allocates. These
are the Cartesian-space ones (safety checks, law, limits, frames, output); the joint-space ones
(the IK step, joint stops, the 1 ms interpolation) are in :mod:`leadthrough.control.joint_kernels`,
and the GUIDING state's step, which chains these, in :mod:`leadthrough.control.guiding_kernel`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "FEEDBACK_COLLISION_FORCE",
    "FEEDBACK_COLLISION_TORQUE",
    "FEEDBACK_CURRENT",
    "FEEDBACK_FOLLOWING",
    "FEEDBACK_NONFINITE",
    "FEEDBACK_OK",
    "FEEDBACK_POSITION",
    "all_finite",
    "control_wrench",
    "decelerate_twist",
    "feedback_fault",
    "is_zero",
    "joint_limit_index",
    "limit_twist",
    "norm",
    "release_step",
    "rotate_to_base",
    "rotate_to_tool",
    "twist_stop_cycles",
    "virtual_friction_step",
    "write_output",
]

Array = NDArray[np.float64]

FEEDBACK_OK = 0
FEEDBACK_POSITION = 1
FEEDBACK_CURRENT = 2
FEEDBACK_FOLLOWING = 3
FEEDBACK_COLLISION_FORCE = 4
FEEDBACK_COLLISION_TORQUE = 5
FEEDBACK_NONFINITE = 6


@njit(cache=True, nogil=True)
def all_finite(q: Array, current: Array, wrench: Array) -> bool:
    """Whether every entry of the three arrays is finite (``q`` and ``current`` of one size)."""
    acc = 0.0    # any NaN or inf makes the sum of x·0 NaN
    for j in range(q.size):
        acc += q[j] * 0.0 + current[j] * 0.0
    for j in range(wrench.size):
        acc += wrench[j] * 0.0
    return acc == 0.0


@njit(cache=True, nogil=True)
def feedback_fault(q: Array, current: Array, wrench: Array, q_commanded: Array,
                   joint_bounds: Array, limits: Array, info: Array) -> int:
    """The checks of the feedback, in order: finite (q, current, wrench), position, current,
    following error, collision force, collision torque.

    Args:
        q: Measured joint positions [rad], shape (n,).
        current: Measured currents [A], shape (n,).
        wrench: Estimated wrench, force first [N, N·m], shape (6,).
        q_commanded: Commanded joint positions [rad], shape (n,).
        joint_bounds: Per joint, shape (3, n): the middle of its range [rad], half its range
            + the position tolerance [rad], its current bound [A].
        limits: Largest |q − q_cmd| [rad], collision force [N], collision torque [N·m],
            shape (3,).
        info: Output (value, index) of the first failed check, shape (2,).

    Returns:
        ``FEEDBACK_OK`` or the code of the first failed check (value and index in ``info``:
        the joint with the largest excess, or the wrench norm and 0/1; not set for
        ``FEEDBACK_NONFINITE``, which also stands for arrays of the wrong size).
    """
    n = q_commanded.size
    if q.size != n or current.size != n or wrench.size != 6:
        return FEEDBACK_NONFINITE
    if not all_finite(q, current, wrench):
        return FEEDBACK_NONFINITE
    mid, half_tolerance, max_current = joint_bounds[0], joint_bounds[1], joint_bounds[2]
    following_limit, max_force, max_torque = limits[0], limits[1], limits[2]
    for code in range(FEEDBACK_POSITION, FEEDBACK_FOLLOWING + 1):
        worst, jw = -math.inf, 0
        for j in range(n):
            if code == FEEDBACK_POSITION:
                x = abs(q[j] - mid[j]) - half_tolerance[j]
            elif code == FEEDBACK_CURRENT:
                x = abs(current[j]) - max_current[j]
            else:
                x = abs(q[j] - q_commanded[j])
            if x > worst:
                worst, jw = x, j
        if code == FEEDBACK_FOLLOWING:
            if worst > following_limit:
                info[0], info[1] = worst, jw
                return code
        elif worst > 0.0:
            info[0] = q[jw] if code == FEEDBACK_POSITION else current[jw]
            info[1] = jw
            return code
    force = math.sqrt(wrench[0] ** 2 + wrench[1] ** 2 + wrench[2] ** 2)
    torque = math.sqrt(wrench[3] ** 2 + wrench[4] ** 2 + wrench[5] ** 2)
    if force > max_force:
        info[0], info[1] = force, 0.0
        return FEEDBACK_COLLISION_FORCE
    if torque > max_torque:
        info[0], info[1] = torque, 1.0
        return FEEDBACK_COLLISION_TORQUE
    return FEEDBACK_OK


@njit(cache=True, nogil=True)
def virtual_friction_step(twist: Array, wrench: Array, friction: Array,
                          stopping_friction: Array, dt_over_mass: Array, out: Array) -> None:
    """Eq. 31–33 with the stopping friction, one Euler step per axis (see
    :mod:`leadthrough.control.virtual_friction`).

    Args:
        twist: Twist of the last cycle, shape (6,).
        wrench: Estimated wrench, shape (6,).
        friction: δ, shape (6,).
        stopping_friction: δ_s, shape (6,).
        dt_over_mass: dt/M per axis, shape (6,).
        out: Desired twist, shape (6,).
    """
    for i in range(6):
        v, w, d = twist[i], wrench[i], friction[i]
        if v == 0.0:
            f = min(max(w, -d), d)            # eq. 33: static friction up to δ
        else:
            mag = stopping_friction[i] if abs(w) < d else d
            f = mag if v > 0.0 else -mag      # eq. 32
        new = (w - f) * dt_over_mass[i] + v   # eq. 31
        out[i] = 0.0 if new * v < 0.0 else new


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
def release_step(wrench: Array, friction: Array, drop: float, alpha: float, forget: float,
                 smooth: Array, peak: Array, moving: bool) -> bool:
    """A release at rest: on some axis the smoothed w_i held a peak of at least ``drop``·δ_i
    and fell back from it, toward zero or beyond, by ``drop``·δ_i or more (a smaller hold
    needs no settling: the estimate's swing after letting go stays below δ). Letting go is
    quick; the peak forgets slow changes (it relaxes toward w_i by the factor ``forget`` per
    cycle), so that the estimate's slow drift at rest under a steady hand is not a release.

    Args:
        wrench: Estimated wrench in the controller's frame, shape (6,).
        friction: δ per axis, shape (6,).
        drop: Fraction of δ that counts as a release.
        alpha: Weight of the new sample in the first-order smoothing, in (0, 1].
        forget: Per-cycle factor of the peak's relaxation, in [0, 1] (1: never forgets).
        smooth: Smoothed wrench, shape (6,); updated in place.
        peak: Signed smoothed w_i of largest magnitude since the tool came to rest or since
            the last release, relaxed by ``forget``, shape (6,); updated in place.
        moving: The tool moves: the peak follows the smoothed wrench (a release counts only
            from rest).

    Returns:
        Whether some axis was released this cycle.
    """
    released = False
    for i in range(wrench.size):
        smooth[i] += alpha * (wrench[i] - smooth[i])
        w = smooth[i]
        p = w + (peak[i] - w) * forget
        back = p - w if p >= 0.0 else w - p      # how far w fell back from the peak
        level = drop * friction[i]
        if back >= level and abs(p) >= level:
            released = True
            peak[i] = w
        elif abs(w) > abs(p):
            peak[i] = w
        else:
            peak[i] = p
        if moving:
            peak[i] = w
    return released


@njit(cache=True, nogil=True)
def is_zero(x: Array) -> bool:
    """Whether every entry is exactly 0.0 (``not x.any()`` for a float vector, compiled)."""
    for i in range(x.size):  # noqa: SIM110 (a plain loop compiles to the fastest code)
        if x[i] != 0.0:
            return False
    return True


@njit(cache=True, nogil=True)
def norm(x: Array) -> float:
    """Euclidean norm √(Σ x_i²) of a vector."""
    s = 0.0
    for i in range(x.size):
        s += x[i] * x[i]
    return math.sqrt(s)


@njit(cache=True, nogil=True)
def control_wrench(wrench_base: Array, rotation: Array, tool: bool, finite: bool, mask: Array,
                   out: Array) -> None:
    """The wrench the law sees: the estimate in the controller's frame, disabled axes zeroed;
    all NaN if the inputs are not finite (the law is then not run).

    Args:
        wrench_base: Estimated wrench in base axes at the TCP, shape (6,).
        rotation: R, tool axes in the base frame, shape (3, 3).
        tool: The controller's frame is the tool's (else the base's).
        finite: The loop's inputs are finite.
        mask: 1.0 for an enabled axis, 0.0 for a disabled one, shape (6,).
        out: Result, shape (6,).
    """
    if not finite:
        out[:] = math.nan
        return
    if tool:
        rotate_to_tool(rotation, wrench_base, out)
    else:
        out[:] = wrench_base
    for i in range(6):
        out[i] *= mask[i]


@njit(cache=True, nogil=True)
def write_output(q_cmd: Array, qd_cmd: Array, rotation: Array, position: Array, twist: Array,
                 tool: bool, wrench: Array, friction: Array, stopping_friction: Array,
                 q_out: Array, qd_out: Array, transform_out: Array, twist_base_out: Array,
                 twist_tool_out: Array, wrench_out: Array, friction_out: Array,
                 stopping_friction_out: Array) -> None:
    """Copy a cycle's arrays into the controller's output (``GuidingOutput``): the setpoint,
    the commanded pose as a 4×4 transform, the twist in both frames (``twist`` is in the
    tool's if ``tool``, else in the base's), the wrench and both frictions."""
    for j in range(q_cmd.size):
        q_out[j] = q_cmd[j]
        qd_out[j] = qd_cmd[j]
    for r in range(3):
        for c in range(3):
            transform_out[r, c] = rotation[r, c]
        transform_out[r, 3] = position[r]
    if tool:
        twist_tool_out[:] = twist
        rotate_to_base(rotation, twist, twist_base_out)
    else:
        twist_base_out[:] = twist
        rotate_to_tool(rotation, twist, twist_tool_out)
    for i in range(6):
        wrench_out[i] = wrench[i]
        friction_out[i] = friction[i]
        stopping_friction_out[i] = stopping_friction[i]


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


@njit(cache=True, nogil=True)
def rotate_to_tool(rotation: Array, base: Array, tool: Array) -> None:
    """A twist or wrench from base axes to tool axes: Rᵀ applied to each half (may not alias).

    Args:
        rotation: R, tool axes in the base frame, shape (3, 3).
        base: 6-vector in base axes.
        tool: Output 6-vector in tool axes.
    """
    for i in (0, 3):
        for r in range(3):
            tool[i + r] = (rotation[0, r] * base[i] + rotation[1, r] * base[i + 1]
                           + rotation[2, r] * base[i + 2])


@njit(cache=True, nogil=True)
def rotate_to_base(rotation: Array, tool: Array, base: Array) -> None:
    """A twist or wrench from tool axes to base axes: R applied to each half (may not alias)."""
    for i in (0, 3):
        for r in range(3):
            base[i + r] = (rotation[r, 0] * tool[i] + rotation[r, 1] * tool[i + 1]
                           + rotation[r, 2] * tool[i + 2])


@njit(cache=True, nogil=True)
def joint_limit_index(q: Array, qd: Array, lower: Array, upper: Array) -> int:
    """First joint at or beyond a bound and moving toward it (−1: none)."""
    for j in range(q.size):
        if (qd[j] > 0.0 and q[j] >= upper[j]) or (qd[j] < 0.0 and q[j] <= lower[j]):
            return j
    return -1
