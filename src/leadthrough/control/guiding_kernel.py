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

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control.kernels import is_zero, limit_twist, release_step, virtual_friction_step
from leadthrough.control.se3_kernels import integrate_base

__all__ = [
    "AXES_ROWS",
    "DESIRED",
    "FRICTION",
    "LAW",
    "LAW_VELOCITY",
    "LAW_VIRTUAL_FRICTION",
    "MASK",
    "NEW",
    "PEAK",
    "SMOOTH",
    "STOP_FRICTION",
    "TWIST",
    "WRENCH",
    "guiding_step",
    "velocity_baseline_step",
]

Array = NDArray[np.float64]

#: Rows of the controller's per-axis state: the twist of the last cycle, the law's desired twist,
#: the limited new twist, the wrench in the controller's frame, δ, δ_s, the smoothed wrench and
#: its peak (release detection), the law's per-axis coefficients, the axes' enable mask (1.0 or
#: 0.0).
TWIST, DESIRED, NEW, WRENCH, FRICTION, STOP_FRICTION, SMOOTH, PEAK, LAW, MASK = range(10)
AXES_ROWS = 10

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
