"""One step of the differential IK, compiled (Numba, ``nopython``, cached on disk): damped least
squares with the joint acceleration, speed and braking bounds (:mod:`leadthrough.control.ik`
documents the algorithm), and the joints' stopping time.

Every function reads the IK's record (:func:`leadthrough.control.ik.ik_dtype`: its settings, the
kinematics at the setpoint, its work space) by field, writes into preallocated arrays and
allocates nothing; the guiding cycle (:mod:`leadthrough.control.guiding_cycle`) and
:meth:`DifferentialIK.solve <leadthrough.control.ik.DifferentialIK.solve>` run the same
:func:`ik_step`. J Jᵀ, μ, λ and the Cholesky solve come from
:mod:`leadthrough.damped_least_squares` (one formula with the force estimate's Jᵀ inverse).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control.se3 import log6_between
from leadthrough.damped_least_squares import (
    cholesky_factor,
    cholesky_solve,
    damping_of,
    gram_manipulability,
)

__all__ = ["dls_step", "ik_step", "joint_stop_cycles", "update_manipulability",
           "update_manipulability_of"]

Array = NDArray[np.float64]
Record = Any   # a record of ik_dtype(n)


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
def _position_bounds(ik: Record, q: Array, qd_previous: Array, qd: Array) -> float:
    """The speed limits and the braking distance to the position bounds, applied to ``qd`` in
    place: a fast path when no bound is near, else each joint's exact bound and one common
    factor (a fast joint it would slow by more than its own a·dt slows at its limit instead).
    Returns the common factor (1: none)."""
    n, dt = q.size, ik.dt
    lower, upper, vmax = ik.lower, ik.upper, ik.max_velocity
    dv, half_inv_a = ik.velocity_step, ik.half_inverse_acceleration
    fast = True
    for j in range(n):
        v = abs(qd[j])
        dist = upper[j] - q[j] if qd[j] >= 0.0 else q[j] - lower[j]
        if v * (v * half_inv_a[j] + dt) > dist or v > vmax[j]:
            fast = False
            break
    s_bound = 1.0
    if not fast:
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
            # the common factor may slow a fast joint by more than its own a·dt: such a joint
            # slows at its limit instead (the TCP leaves its line while a joint bound brakes);
            # the braking joint's own bound admits its previous speed less a·dt, so both hold
            for j in range(n):
                v = min(max(qd[j], qd_previous[j] - dv[j]), qd_previous[j] + dv[j])
                bound = _speed_bound(v, q[j], lower[j], upper[j], vmax[j], dv[j], dt)
                qd[j] = min(max(v, -bound), bound)
    return s_bound


@njit(cache=True, nogil=True)
def dls_step(ik: Record, q: Array, qd_previous: Array, qd_dls: Array, qd: Array,
             q_next: Array) -> float:
    """Damped least squares with the joint acceleration, speed and braking bounds (see
    :mod:`leadthrough.control.ik`).

    Args:
        ik: The IK's record: reads the kinematics at ``q`` (``jacobian``, ``gram``,
            ``damping``), the log6 ``error`` to the target in tool axes, and the joint bounds;
            ``solve_factor`` and ``solve_rhs`` are its work space.
        q: Joint position [rad], shape (n,).
        qd_previous: Joint velocity of the last cycle [rad/s], shape (n,).
        qd_dls: Output joint velocity of the DLS step before the bounds [rad/s], shape (n,).
        qd: Output joint velocity [rad/s], shape (n,).
        q_next: Output q + q̇·dt [rad], shape (n,).

    Returns:
        The fraction of the DLS step kept by the bounds (1: none active; 0: J Jᵀ + λ²·1 was
        singular, λ = 0 at a singularity, and every joint brakes at its limit instead).
    """
    n = q.size
    jacobian, err, dt, dv = ik.jacobian, ik.error, ik.dt, ik.velocity_step
    factor, y = ik.solve_factor, ik.solve_rhs
    if not cholesky_factor(ik.gram, 6, ik.damping * ik.damping, factor):
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
    scale *= _position_bounds(ik, q, qd_previous, qd)
    for j in range(n):
        q_next[j] = qd[j] * dt + q[j]
    return scale


@njit(cache=True, nogil=True)
def ik_step(ik: Record, target_rotation: Array, target_position: Array, q: Array,
            qd_previous: Array, qd_dls: Array, qd: Array, q_next: Array) -> tuple[float, float]:
    """One step of the differential IK: the log6 error from the TCP pose at ``q`` to the target
    (into ``ik.error``), then :func:`dls_step`.

    Args:
        ik: The IK's record, with the kinematics at ``q`` (TCP pose, Jacobian, J Jᵀ, damping).
        target_rotation: R of the target, shape (3, 3).
        target_position: p of the target [m], shape (3,).
        q: Joint position [rad], shape (n,).
        qd_previous: Joint velocity of the last cycle [rad/s], shape (n,).
        qd_dls: Output DLS joint velocity before the bounds [rad/s], shape (n,).
        qd: Output joint velocity [rad/s], shape (n,).
        q_next: Output q + q̇·dt [rad], shape (n,).

    Returns:
        The fraction of the step kept by the bounds (:func:`dls_step`) and the residual
        ‖log6‖ before the step [m and rad, mixed].
    """
    residual = log6_between(ik.tcp_rotation, ik.tcp_position, target_rotation, target_position,
                            ik.error)
    scale = dls_step(ik, q, qd_previous, qd_dls, qd, q_next)
    return scale, residual


@njit(cache=True, nogil=True)
def update_manipulability(ik: Record) -> None:
    """J Jᵀ, its factor, μ and the damping λ of the least squares at the kinematics' q."""
    ik.manipulability = gram_manipulability(ik.jacobian, ik.gram, ik.gram_factor)
    ik.damping = damping_of(ik.manipulability, ik.manipulability_threshold, ik.max_damping)


@njit(cache=True, nogil=True)
def update_manipulability_of(ik_record: NDArray[np.void]) -> None:
    """:func:`update_manipulability` of the IK's record as Python passes it (one element)."""
    update_manipulability(ik_record[0])
