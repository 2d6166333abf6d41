"""Compiled joint-space inner loops of the guiding controller (Numba, ``nopython``, cached on
disk): the damped-least-squares IK step with the joint bounds (:mod:`~leadthrough.control.ik`),
the joints' stopping time, and the cubic Hermite interpolation from controller setpoints to 1 ms
commands (:mod:`~leadthrough.control.interpolation`). The Cartesian-space kernels are in
:mod:`leadthrough.control.kernels`.

All kernels write into preallocated arrays and return a scalar or nothing; none allocates. J Jᵀ,
μ and the Cholesky solve come from the estimator's kernels
(:func:`leadthrough.estimation.kernels.gram_manipulability`), one formula for both.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control.se3_kernels import log6_between
from leadthrough.estimation.kernels import cholesky_factor, cholesky_solve

__all__ = [
    "HERMITE_DP",
    "HERMITE_FINISHED",
    "HERMITE_P0",
    "HERMITE_P1",
    "HERMITE_Q",
    "HERMITE_QD",
    "HERMITE_STARVED",
    "HERMITE_V0",
    "HERMITE_V1",
    "HERMITE_WORKING",
    "IK_ROWS",
    "dls_step",
    "hermite_start",
    "hermite_step",
    "ik_size",
    "ik_step",
    "ik_views",
    "joint_stop_cycles",
]

Array = NDArray[np.float64]


# The IK's buffer (``DifferentialIK.buffer``, one array so that a compiled call takes it as one
# argument): J Jᵀ and its factor (2, 6, 6), the least squares' work space (7, 6), the log6 error
# (6,), the Jacobian (6, n), then the joint table (IK_ROWS, n), whose rows are the IK's bounds,
# speed limits, a·dt, 1/(2a) and the planned stop's a·dt (the fraction a stop may take)
IK_LOWER, IK_UPPER, IK_VMAX, IK_DV, IK_HALF_INV_A, IK_DV_STOP = range(6)
IK_ROWS = 6

_SCRATCH_AT = 72
_ERROR_AT = _SCRATCH_AT + 42
_JACOBIAN_AT = _ERROR_AT + 6


def ik_size(n: int) -> int:
    """Length of the IK's buffer for ``n`` joints."""
    return _JACOBIAN_AT + (6 + IK_ROWS) * n


@njit(cache=True, nogil=True)
def ik_views(buffer: Array, n: int) -> tuple[Array, Array, Array, Array, Array]:
    """``gram`` (2, 6, 6), ``scratch`` (7, 6), ``error`` (6,), ``jacobian`` (6, n) and
    ``table`` (``IK_ROWS``, n) of the IK's buffer."""
    table_at = _JACOBIAN_AT + 6 * n
    return (buffer[:_SCRATCH_AT].reshape((2, 6, 6)),
            buffer[_SCRATCH_AT:_ERROR_AT].reshape((7, 6)), buffer[_ERROR_AT:_JACOBIAN_AT],
            buffer[_JACOBIAN_AT:table_at].reshape((6, n)),
            buffer[table_at:table_at + IK_ROWS * n].reshape((IK_ROWS, n)))


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
def ik_step(jacobian: Array, gram: Array, table: Array, scratch: Array, err: Array,
            damping: float, dt: float, fk_rotation: Array, fk_position: Array,
            target_rotation: Array, target_position: Array, q: Array, qd_previous: Array,
            qd_dls: Array, qd: Array, q_next: Array) -> tuple[float, float]:
    """One step of the differential IK (:meth:`DifferentialIK.solve
    <leadthrough.control.ik.DifferentialIK.solve>`): the log6 error from the TCP pose at ``q``
    to the target, then :func:`dls_step` with the IK's joint table.

    Args:
        jacobian: TCP Jacobian in tool axes at ``q``, shape (6, n).
        gram: J Jᵀ at ``q`` (and its factor), shape (2, 6, 6).
        table: The IK's joint table, shape (``IK_ROWS``, n).
        scratch: Work space, shape (7, 6).
        err: Output log6 error [m, rad], shape (6,).
        damping: λ at ``q``.
        dt: Controller cycle [s].
        fk_rotation: R of the TCP at ``q``, shape (3, 3).
        fk_position: p of the TCP at ``q`` [m], shape (3,).
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
    residual = log6_between(fk_rotation, fk_position, target_rotation, target_position, err)
    scale = dls_step(jacobian, gram[0], damping, err, dt, q, qd_previous, table[IK_LOWER],
                     table[IK_UPPER], table[IK_VMAX], table[IK_DV], table[IK_HALF_INV_A],
                     qd_dls, qd, q_next, scratch)
    return scale, residual


#: Rows of the Hermite interpolator's segment state (``hermite_start`` / ``hermite_step``):
#: start position and velocity, end position and velocity, end − start, last command.
HERMITE_P0, HERMITE_V0, HERMITE_P1, HERMITE_V1, HERMITE_DP, HERMITE_Q, HERMITE_QD = range(7)
#: Codes of ``hermite_step``: inside the segment, at its end, past it (no new setpoint).
HERMITE_WORKING, HERMITE_FINISHED, HERMITE_STARVED = 0, 1, -1


@njit(cache=True, nogil=True)
def hermite_start(segment: Array, q: Array, qd: Array) -> bool:
    """A new segment from the last command to the setpoint (q, q̇) (see
    :mod:`leadthrough.control.interpolation`).

    Args:
        segment: Segment state, shape (7, n), rows ``HERMITE_*`` (in place).
        q: Setpoint [rad], shape (n,).
        qd: Velocity at the setpoint [rad/s], shape (n,).

    Returns:
        False, with nothing changed, for a setpoint of the wrong size or not finite.
    """
    n = segment.shape[1]
    if q.size != n or qd.size != n:
        return False
    for j in range(n):
        if not (np.isfinite(q[j]) and np.isfinite(qd[j])):
            return False
    for j in range(n):
        segment[HERMITE_P0, j] = segment[HERMITE_Q, j]
        segment[HERMITE_V0, j] = segment[HERMITE_QD, j]
        segment[HERMITE_P1, j] = q[j]
        segment[HERMITE_V1, j] = qd[j]
        segment[HERMITE_DP, j] = q[j] - segment[HERMITE_Q, j]
    return True


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
        ``HERMITE_WORKING`` inside the segment, ``HERMITE_FINISHED`` at its end,
        ``HERMITE_STARVED`` past it.
    """
    substeps = basis.shape[0]
    status = HERMITE_WORKING
    for j in range(q_out.size):
        if k >= substeps:
            segment[HERMITE_QD, j] = 0.0
            status = HERMITE_STARVED
        elif k == substeps - 1:
            segment[HERMITE_Q, j] = segment[HERMITE_P1, j]
            segment[HERMITE_QD, j] = segment[HERMITE_V1, j]
            status = HERMITE_FINISHED
        else:
            dp, v0, v1 = segment[HERMITE_DP, j], segment[HERMITE_V0, j], segment[HERMITE_V1, j]
            segment[HERMITE_Q, j] = (dp * basis[k, 0] + v0 * basis[k, 1] + v1 * basis[k, 2]
                                     + segment[HERMITE_P0, j])
            segment[HERMITE_QD, j] = dp * basis[k, 3] + v0 * basis[k, 4] + v1 * basis[k, 5]
        q_out[j] = segment[HERMITE_Q, j]
        qd_out[j] = segment[HERMITE_QD, j]
    return status
