"""External joint torque, the residual of the identified model (paper eq. 27 and 30), per sample.

* The direct estimate (the paper's): τ_ext = LPF(τ̂_d − τ̂_j) + τ̄_ω, τ̂_d = RNEA + τ_f(q̇) +
  M_j·q̈ + τ_0 (eq. 21's right side, eq. 27), a first-order low-pass, and the identified mean
  noise τ̄_ω added back (eq. 30: τ_ω = τ_j − τ_d) (:func:`direct_residual`).
* De Luca's generalized-momentum observer, no q̈ needed (:func:`momentum_step`).
* Averaging windows (a tare, a zero-velocity update) subtracted from then on
  (:func:`average_into_tare`).

Compiled (Numba, ``nopython``, cached on disk), allocation-free; the estimator
(:mod:`leadthrough.estimation.estimator_step`) runs them every sample.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["average_into_tare", "direct_residual", "momentum_step"]

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def direct_residual(rnea: Array, friction: Array, qdd: Array, tau_j: Array, rotor: Array,
                    offset: Array, alpha: float, filtered: Array, noise_mean: Array,
                    tau_ext: Array) -> None:
    """Eq. 27 and 30 for one sample: τ_ext = LPF(τ̂_d − τ̂_j) + τ̄_ω (in place).

    τ̂_d = RNEA + τ_f(q̇) + M_j·q̈ + τ_0 (eq. 21 right side).

    Args:
        rnea: Rigid-body torque of the identified links [N·m], shape (n,).
        friction: Friction torque τ_f [N·m], shape (n,) (:func:`friction_torque` or
            :func:`presliding_friction_step`).
        qdd: Joint accelerations [rad/s²], shape (n,).
        tau_j: Torque from current [N·m], shape (n,).
        rotor: Rotor inertias M_j [kg·m²], shape (n,).
        offset: Torque offsets τ_0 [N·m], shape (n,).
        alpha: Low-pass coefficient.
        filtered: Low-pass state (in place), shape (n,).
        noise_mean: τ̄_ω added back (zeros to skip) [N·m], shape (n,).
        tau_ext: Output [N·m], shape (n,).
    """
    for j in range(qdd.size):
        raw = rnea[j] + friction[j] + rotor[j] * qdd[j] + offset[j] - tau_j[j]
        filtered[j] += alpha * (raw - filtered[j])
        tau_ext[j] = filtered[j] + noise_mean[j]


@njit(cache=True, nogil=True)
def momentum_step(mass_upper: Array, rotor: Array, coriolis: Array, gravity: Array,
                  qd: Array, friction: Array, tau_j: Array, offset: Array, dt: float,
                  gain: float, first: bool, p0: Array, integral: Array, r: Array, work: Array,
                  noise_mean: Array, tau_ext: Array) -> None:
    """One step of De Luca's generalized-momentum observer (in place).

    r = K_O·(p − p₀ − ∫(τ_j + Cᵀq̇ − g − τ_f − τ_0 + r) dt), p = (M + M_j)·q̇; r → τ_ext with
    bandwidth K_O. Then τ_ext = r + τ̄_ω.

    Args:
        mass_upper: M(q) of the links, upper triangle used (as ``pin.crba`` fills it),
            shape (n, n).
        rotor: Rotor inertias M_j [kg·m²], shape (n,).
        coriolis: C(q, q̇), shape (n, n).
        gravity: g(q) [N·m], shape (n,).
        qd: Joint velocities [rad/s], shape (n,).
        friction: Friction torque τ_f [N·m], shape (n,).
        tau_j: Torque from current [N·m], shape (n,).
        offset: τ_0 [N·m], shape (n,).
        dt: Sample period [s].
        gain: Observer gain K_O [1/s].
        first: First sample after reset (sets p₀).
        p0: Initial momentum (state), shape (n,).
        integral: Integral (state), shape (n,).
        r: Residual (state) [N·m], shape (n,).
        work: Scratch, shape (n,).
        noise_mean: τ̄_ω [N·m], shape (n,).
        tau_ext: Output [N·m], shape (n,).
    """
    n = qd.size
    for i in range(n):
        p = rotor[i] * qd[i]
        ctq = 0.0
        for k in range(n):
            p += (mass_upper[i, k] if i <= k else mass_upper[k, i]) * qd[k]
            ctq += coriolis[k, i] * qd[k]
        if first:
            p0[i] = p
        beta = tau_j[i] + ctq - gravity[i] - friction[i] - offset[i]
        integral[i] += (beta + r[i]) * dt
        work[i] = p
    for i in range(n):
        r[i] = gain * (work[i] - p0[i] - integral[i])
        tau_ext[i] = r[i] + noise_mean[i]


@njit(cache=True, nogil=True)
def average_into_tare(window_sum: Array, tare: Array, left: int, taken: int,
                      tau_ext: Array) -> int:
    """One sample of an averaging window (tare or re-zero): add ``tau_ext`` to ``window_sum``;
    on the window's last sample add the window's mean to ``tare``. Returns the samples left.

    Args:
        window_sum: Sum over the window so far [N·m] (in place), shape (n,).
        tare: The torque subtracted from τ_ext [N·m] (in place), shape (n,).
        left: Samples left in the window, ≥ 1.
        taken: Samples of the whole window.
        tau_ext: This sample's τ_ext [N·m], shape (n,).
    """
    n = tau_ext.size
    for j in range(n):
        window_sum[j] += tau_ext[j]
    left -= 1
    if left == 0:
        for j in range(n):
            window_sum[j] *= 1.0 / taken
            tare[j] += window_sum[j]
    return left
