"""Compiled inner loops of the guiding controller (Numba, ``nopython``, cached on disk).

The controller's cycle is small-vector work (6 joints, 6 axes): each NumPy call costs more in
dispatch than in arithmetic, and the cycle needs dozens. These kernels fuse each step into one
compiled call, with the same arithmetic as the NumPy reference they replace (the modules that
call them document the algorithms: :mod:`~leadthrough.control.safety`,
:mod:`~leadthrough.control.virtual_friction`, :mod:`~leadthrough.control.limits`,
:mod:`~leadthrough.control.ik`). ``benchmarks/guiding.py`` measures the cycle.

All kernels write into preallocated arrays and return a scalar or nothing; none allocates. J Jᵀ,
μ and the Cholesky solve come from the estimator's kernels
(:func:`leadthrough.estimation.kernels.gram_manipulability`), one formula for both.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.estimation.kernels import cholesky_factor, cholesky_solve

__all__ = [
    "FEEDBACK_COLLISION_FORCE",
    "FEEDBACK_COLLISION_TORQUE",
    "FEEDBACK_CURRENT",
    "FEEDBACK_FOLLOWING",
    "FEEDBACK_OK",
    "FEEDBACK_POSITION",
    "all_finite",
    "control_wrench",
    "decelerate_twist",
    "dls_step",
    "feedback_fault",
    "hermite_start",
    "hermite_step",
    "integrate_base",
    "is_zero",
    "joint_limit_index",
    "joint_stop_cycles",
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
def feedback_fault(q: Array, current: Array, wrench: Array, q_commanded: Array, mid: Array,
                   half_tolerance: Array, max_current: Array, following_limit: float,
                   max_force: float, max_torque: float, info: Array) -> int:
    """The range checks of the feedback, in order: position, current, following error,
    collision force, collision torque.

    Args:
        q: Measured joint positions [rad], shape (n,).
        current: Measured currents [A], shape (n,).
        wrench: Estimated wrench, force first [N, N·m], shape (6,).
        q_commanded: Commanded joint positions [rad], shape (n,).
        mid: Middle of each joint range [rad], shape (n,).
        half_tolerance: Half range + position tolerance [rad], shape (n,).
        max_current: Current bound [A], shape (n,).
        following_limit: Largest |q − q_cmd| [rad].
        max_force: Collision force [N].
        max_torque: Collision torque [N·m].
        info: Output (value, index) of the first failed check, shape (2,).

    Returns:
        ``FEEDBACK_OK`` or the code of the first failed check (value and index in ``info``:
        the joint with the largest excess, or the wrench norm and 0/1).
    """
    n = q.size
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
        min_cycles: Lower bound on n, e.g. the joints' own stop (:func:`joint_stop_cycles`).
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
def joint_stop_cycles(qd: Array, dv: Array) -> float:
    """Cycles the joints need to stop at their acceleration limits: max_j |q̇_j|/(a_j·dt).

    Args:
        qd: Joint velocity [rad/s], shape (n,).
        dv: Joint acceleration limit × dt [rad/s], shape (n,).
    """
    n = 0.0
    for j in range(qd.size):
        n = max(n, abs(qd[j]) / dv[j])
    return n


@njit(cache=True, nogil=True)
def _braking_speed(dist: float, dv: float, dt: float) -> float:
    """Largest speed from which the discrete stop ends within ``dist``.

    Lowering the speed v by dv = a·dt per cycle (position advanced with the new speed of each
    cycle) travels dt·Σ_i max(v − i·dv, 0). Writing v = dv·(m + f), m integer, f ∈ [0, 1], that
    is a·dt²·(m + 1)(m/2 + f); solved for the largest v with D = dist/(a·dt²). From there the
    next cycle's bound is exactly v − dv, so braking never exceeds a.
    """
    d = dist / (dv * dt)
    m = math.floor(0.5 * (math.sqrt(1.0 + 8.0 * d) - 1.0))
    f = min(max(d / (m + 1) - 0.5 * m, 0.0), 1.0)
    return dv * (m + f)


@njit(cache=True, nogil=True)
def _speed_bound(v: float, q: float, lower: float, upper: float, vmax: float, dv: float,
                 dt: float) -> float:
    """Largest |q̇| of a joint moving at sign(``v``): its speed limit, and the speed from which
    it can still stop before the bound it moves toward."""
    dist = max(upper - q if v > 0.0 else q - lower, 0.0)
    return min(vmax, _braking_speed(dist, dv, dt))


@njit(cache=True, nogil=True)
def dls_step(jacobian: Array, gram: Array, damping: float, err: Array, dt: float,
             q: Array, qd_previous: Array, lower: Array, upper: Array, vmax: Array,
             dv: Array, half_inv_a: Array, qd_dls: Array, qd: Array, q_next: Array,
             scratch: Array) -> float:
    """Damped least squares with the joint acceleration, speed and braking bounds (see
    :mod:`leadthrough.control.ik`).

    Args:
        jacobian: TCP Jacobian in tool axes, shape (6, n).
        gram: J Jᵀ, shape (6, 6) (not modified).
        damping: λ.
        err: log6 error to the target in tool axes, shape (6,).
        dt: Controller cycle [s].
        q: Joint position [rad], shape (n,).
        qd_previous: Joint velocity of the last cycle [rad/s], shape (n,).
        lower: Lower bounds [rad], shape (n,).
        upper: Upper bounds [rad], shape (n,).
        vmax: Joint speed limits [rad/s], shape (n,).
        dv: Joint acceleration limit × dt [rad/s], shape (n,).
        half_inv_a: 1/(2·a) per joint [s²/rad], shape (n,).
        qd_dls: Output joint velocity of the DLS step before the bounds [rad/s], shape (n,).
        qd: Output joint velocity [rad/s], shape (n,).
        q_next: Output q + q̇·dt [rad], shape (n,).
        scratch: Work space, shape (7, 6): the factor of J Jᵀ + λ²·1, then the solution.

    Returns:
        The fraction of the DLS step kept by the bounds (1: none active; 0: J Jᵀ + λ²·1 was
        singular, λ = 0 at a singularity, and every joint brakes at its limit instead).
    """
    n = q.size
    factor, y = scratch[:6], scratch[6]
    if not cholesky_factor(gram, 6, damping * damping, factor):
        # singular (λ = 0 exactly at a singularity): brake every joint at its limit
        for j in range(n):
            v = qd_previous[j]
            qd[j] = max(v - dv[j], 0.0) if v > 0.0 else min(v + dv[j], 0.0)
            qd_dls[j] = 0.0
            q_next[j] = q[j] + qd[j] * dt
        return 0.0
    inv_dt = 1.0 / dt
    for r in range(6):
        y[r] = err[r] * inv_dt
    cholesky_solve(factor, 6, y)
    ratio = 0.0
    for j in range(n):
        s = 0.0
        for r in range(6):
            s += jacobian[r, j] * y[r]
        qd[j] = s
        qd_dls[j] = s
        ratio = max(ratio, abs(s - qd_previous[j]) / dv[j])
    scale = 1.0
    if ratio > 1.0:
        k = 1.0 / ratio
        for j in range(n):
            qd[j] = qd_previous[j] + (qd[j] - qd_previous[j]) * k
        scale = k
    # speed and braking distance to the bounds: fast path, then exact per joint
    fast = True
    for j in range(n):
        v = abs(qd[j])
        dist = upper[j] - q[j] if qd[j] >= 0.0 else q[j] - lower[j]
        if v * (v * half_inv_a[j] + dt) > dist or v > vmax[j]:
            fast = False
            break
    if not fast:
        s_bound = 1.0
        for j in range(n):
            v = qd[j]
            if v == 0.0:
                continue
            bound = _speed_bound(v, q[j], lower[j], upper[j], vmax[j], dv[j], dt)
            if abs(v) > bound:
                s_bound = min(s_bound, bound / abs(v))
        if s_bound < 1.0:
            for j in range(n):
                qd[j] *= s_bound
            scale *= s_bound
            # the common factor may slow a fast joint by more than its own a·dt: such a joint
            # slows at its limit instead (the TCP leaves its line while a joint bound brakes);
            # the braking joint's own bound admits its previous speed less a·dt, so both hold
            for j in range(n):
                v = min(max(qd[j], qd_previous[j] - dv[j]), qd_previous[j] + dv[j])
                bound = _speed_bound(v, q[j], lower[j], upper[j], vmax[j], dv[j], dt)
                qd[j] = min(max(v, -bound), bound)
    for j in range(n):
        q_next[j] = qd[j] * dt + q[j]
    return scale


@njit(cache=True, nogil=True)
def integrate_base(rotation: Array, position: Array, twist: Array, dt: float,
                   rotation_out: Array, position_out: Array) -> None:
    """Pose after one cycle of a base-axes twist: p + v·dt, exp3(ω·dt)·R (Rodrigues)."""
    wx, wy, wz = twist[3] * dt, twist[4] * dt, twist[5] * dt
    th2 = wx * wx + wy * wy + wz * wz
    th = math.sqrt(th2)
    if th < 1e-8:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    e00 = 1.0 - b * (wy * wy + wz * wz)
    e11 = 1.0 - b * (wx * wx + wz * wz)
    e22 = 1.0 - b * (wx * wx + wy * wy)
    e01, e10 = b * wx * wy - a * wz, b * wx * wy + a * wz
    e02, e20 = b * wx * wz + a * wy, b * wx * wz - a * wy
    e12, e21 = b * wy * wz - a * wx, b * wy * wz + a * wx
    for c in range(3):
        r0, r1, r2 = rotation[0, c], rotation[1, c], rotation[2, c]
        rotation_out[0, c] = e00 * r0 + e01 * r1 + e02 * r2
        rotation_out[1, c] = e10 * r0 + e11 * r1 + e12 * r2
        rotation_out[2, c] = e20 * r0 + e21 * r1 + e22 * r2
    for r in range(3):
        position_out[r] = position[r] + twist[r] * dt


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


#: Rows of the Hermite interpolator's segment state (``hermite_start`` / ``hermite_step``):
#: start position and velocity, end position and velocity, end − start, last command.
HERMITE_P0, HERMITE_V0, HERMITE_P1, HERMITE_V1, HERMITE_DP, HERMITE_Q, HERMITE_QD = range(7)


@njit(cache=True, nogil=True)
def hermite_start(segment: Array, q: Array, qd: Array) -> None:
    """A new segment from the last command to the setpoint (q, q̇) (see
    :mod:`leadthrough.control.interpolation`).

    Args:
        segment: Segment state, shape (7, n), rows ``HERMITE_*`` (in place).
        q: Setpoint [rad], shape (n,).
        qd: Velocity at the setpoint [rad/s], shape (n,).
    """
    for j in range(q.size):
        segment[HERMITE_P0, j] = segment[HERMITE_Q, j]
        segment[HERMITE_V0, j] = segment[HERMITE_QD, j]
        segment[HERMITE_P1, j] = q[j]
        segment[HERMITE_V1, j] = qd[j]
        segment[HERMITE_DP, j] = q[j] - segment[HERMITE_Q, j]


@njit(cache=True, nogil=True)
def hermite_step(segment: Array, basis: Array, k: int, q_out: Array, qd_out: Array) -> int:
    """Command k of the segment (0-based): q = p0 + c01·Δp + c10·v0 + c11·v1,
    q̇ = d01·Δp + d10·v0 + d11·v1; the last one is the setpoint itself; past it, the end
    position is held at rest.

    Args:
        segment: Segment state, shape (7, n), rows ``HERMITE_*`` (last command updated).
        basis: Rows (c01, c10, c11, d01, d10, d11) per substep, shape (substeps, 6).
        k: Substep.
        q_out: Position command [rad], shape (n,).
        qd_out: Velocity command [rad/s], shape (n,).

    Returns:
        0 inside the segment, 1 at its end, -1 past it (the ``InterpolatorStatus`` codes).
    """
    substeps = basis.shape[0]
    status = 0
    for j in range(q_out.size):
        if k >= substeps:
            segment[HERMITE_QD, j] = 0.0
            status = -1
        elif k == substeps - 1:
            segment[HERMITE_Q, j] = segment[HERMITE_P1, j]
            segment[HERMITE_QD, j] = segment[HERMITE_V1, j]
            status = 1
        else:
            dp, v0, v1 = segment[HERMITE_DP, j], segment[HERMITE_V0, j], segment[HERMITE_V1, j]
            segment[HERMITE_Q, j] = (dp * basis[k, 0] + v0 * basis[k, 1] + v1 * basis[k, 2]
                                     + segment[HERMITE_P0, j])
            segment[HERMITE_QD, j] = dp * basis[k, 3] + v0 * basis[k, 4] + v1 * basis[k, 5]
        q_out[j] = segment[HERMITE_Q, j]
        qd_out[j] = segment[HERMITE_QD, j]
    return status


@njit(cache=True, nogil=True)
def joint_limit_index(q: Array, qd: Array, lower: Array, upper: Array) -> int:
    """First joint at or beyond a bound and moving toward it (−1: none)."""
    for j in range(q.size):
        if (qd[j] > 0.0 and q[j] >= upper[j]) or (qd[j] < 0.0 and q[j] <= lower[j]):
            return j
    return -1
