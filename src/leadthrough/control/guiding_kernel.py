"""The GUIDING state's step of the guiding cycle, as one compiled call (Numba, cached on disk).

In the GUIDING state every cycle runs the same chain on 6-vectors: the release detection at rest,
the choice of the friction (stopping friction while settling), the admittance law, the speed and
acceleration limits and, in the base frame, the integration of the twist into the next TCP
pose. Each link is a kernel of :mod:`leadthrough.control.kernels` (or of this module); chained in
Python they cost a dispatch each, more than their arithmetic. :func:`guiding_step` runs the chain
with the same kernels in one call. What each link does is documented where it is used:
:mod:`~leadthrough.control.guiding` (release, settling, integration),
:mod:`~leadthrough.control.virtual_friction` (eq. 31–33),
:mod:`~leadthrough.control.velocity_baseline` ([14]), :mod:`~leadthrough.control.limits`.

The controller keeps its per-axis state in one array of shape (``AXES_ROWS``, 6), row by row
(``TWIST`` … ``LAW``); its named vectors are views of those rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control.kernels import is_zero, limit_twist, release_step, virtual_friction_step

__all__ = [
    "AXES_ROWS",
    "DESIRED",
    "FRICTION",
    "LAW",
    "LAW_VELOCITY",
    "LAW_VIRTUAL_FRICTION",
    "NEW",
    "PEAK",
    "SMOOTH",
    "STOP_FRICTION",
    "TWIST",
    "WRENCH",
    "copy_pose",
    "guiding_step",
    "integrate_base",
    "velocity_baseline_step",
]

Array = NDArray[np.float64]

#: Rows of the controller's per-axis state: the twist of the last cycle, the law's desired twist,
#: the limited new twist, the wrench in the controller's frame, δ, δ_s, the smoothed wrench and
#: its peak (release detection), the law's per-axis coefficients.
TWIST, DESIRED, NEW, WRENCH, FRICTION, STOP_FRICTION, SMOOTH, PEAK, LAW = range(9)
AXES_ROWS = 9

#: The admittance laws :func:`guiding_step` can run (``AdmittanceLaw.law_id``).
LAW_VIRTUAL_FRICTION = 0
LAW_VELOCITY = 1


@njit(cache=True, nogil=True)
def velocity_baseline_step(twist: Array, wrench: Array, gain: Array, alpha: float,
                           out: Array) -> None:
    """The velocity baseline's first-order lag, v⁺ = v + α·(K·F̂ − v) per axis (see
    :mod:`leadthrough.control.velocity_baseline`).

    Args:
        twist: Twist of the last cycle, shape (6,).
        wrench: Estimated wrench, shape (6,).
        gain: K per axis, shape (6,).
        alpha: 1 − e^(−dt/T).
        out: Desired twist, shape (6,); must not alias an input.
    """
    for i in range(6):
        out[i] = (gain[i] * wrench[i] - twist[i]) * alpha + twist[i]


@njit(cache=True, nogil=True)
def guiding_step(axes: Array, law_id: int, law_alpha: float, settings: Array, max_speed: Array,
                 max_step: Array, speed_scale: float, rest_s: float, release_s: float,
                 integrate: bool, rotation: Array, position: Array, rotation_out: Array,
                 position_out: Array) -> float:
    """One GUIDING cycle from the wrench to the next twist (and pose).

    1. At rest (a twist of exactly zero), a release restarts the release clock
       (:func:`~leadthrough.control.kernels.release_step`; moving, the peak follows).
    2. Settling (at rest, within ``hold`` of the last stop or release): the law's friction is
       the stopping friction.
    3. The law (``law_id``) gives the desired twist, the limits the new one.
    4. With ``integrate`` (base frame), the pose after one cycle of the new twist.

    Args:
        axes: Per-axis state, shape (``AXES_ROWS``, 6): reads ``TWIST``, ``WRENCH``,
            ``FRICTION``, ``STOP_FRICTION``, ``LAW``; writes ``DESIRED``, ``NEW``; updates
            ``SMOOTH`` and ``PEAK``.
        law_id: ``LAW_VIRTUAL_FRICTION`` (``LAW`` row: dt/M) or ``LAW_VELOCITY`` (``LAW`` row:
            K).
        law_alpha: The velocity law's 1 − e^(−dt/T) (unused by the other).
        settings: hold [s], dt [s], release drop [-], release smoothing weight [-], release
            forgetting factor [-], shape (5,).
        max_speed: (v_max, ω_max) of the limits.
        max_step: (a_max·dt, α_max·dt) of the limits.
        speed_scale: Factor of the speed limits (singularity).
        rest_s: Time the commanded motion has been at rest [s].
        release_s: Time since the last release at rest [s].
        integrate: Integrate the new twist as base-axes twist (else the caller integrates).
        rotation: R of the commanded pose, shape (3, 3).
        position: p of the commanded pose [m], shape (3,).
        rotation_out: R of the next pose, shape (3, 3) (with ``integrate``).
        position_out: p of the next pose [m], shape (3,) (with ``integrate``).

    Returns:
        The release clock after this cycle [s].
    """
    twist, wrench = axes[TWIST], axes[WRENCH]
    friction, stop_friction = axes[FRICTION], axes[STOP_FRICTION]
    hold, dt = settings[0], settings[1]
    at_rest = is_zero(twist)
    if release_step(wrench, friction, settings[2], settings[3], settings[4], axes[SMOOTH],
                    axes[PEAK], not at_rest) and at_rest:
        release_s = 0.0
    settling = at_rest and (rest_s < hold or release_s < hold)
    release_s += dt
    if law_id == LAW_VIRTUAL_FRICTION:
        virtual_friction_step(twist, wrench, stop_friction if settling else friction,
                              stop_friction, axes[LAW], axes[DESIRED])
    else:
        velocity_baseline_step(twist, wrench, axes[LAW], law_alpha, axes[DESIRED])
    limit_twist(twist, axes[DESIRED], max_speed, max_step, speed_scale, axes[NEW])
    if integrate:
        integrate_base(rotation, position, axes[NEW], dt, rotation_out, position_out)
    return release_s


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
def copy_pose(rotation: Array, position: Array, rotation_out: Array, position_out: Array) -> None:
    """Copy a pose given as rotation, shape (3, 3), and position, shape (3,)."""
    for r in range(3):
        for c in range(3):
            rotation_out[r, c] = rotation[r, c]
        position_out[r] = position[r]
