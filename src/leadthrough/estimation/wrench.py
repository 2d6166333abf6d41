"""The operator's wrench at the TCP from the external joint torque (paper eq. 28–30), and the
joint weights of the force-only fit, per sample.

:func:`wrench_from_torque` maps τ_ext through a damped pseudo-inverse of Jᵀ
(:mod:`leadthrough.damped_least_squares`): the full wrench, or a pure force fitted to all joint
torques by weighted least squares; :func:`friction_weights` weighs the joints by their
friction's uncertainty. Compiled (Numba, ``nopython``, cached on disk), allocation-free.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.damped_least_squares import (
    cholesky_factor,
    cholesky_solve,
    damping_of,
    gram_manipulability,
    smallest_eigenvalue_3,
)

__all__ = ["friction_weights", "wrench_from_torque"]

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def friction_weights(level: Array, state: Array, encoder_state: Array, decay: float,
                     kappa: float, std: Array, envelope: Array, weight: Array) -> None:
    """Per-joint weights of the force fit from the friction's uncertainty, one step.

    u_j is the larger of two gaps:

    * |g_j(q̇) − |F_j||, between the friction state of
      :func:`~leadthrough.dynamics.presliding.presliding_friction_step` and the eq. 15 level at
      the current speed: zero in steady sliding, up to g while the friction turns over after a
      reversal (|F| passes through zero, and where the gear is then depends on its
      presliding, of which the model's z₀ is only a guess), and at standstill the gap to the
      static level (a stopped gear's friction can be anything up to it);
    * |F_j − F_enc,j|, between that state (turned over by the command while the joint moves)
      and the state the encoder alone turns over
      (:func:`~leadthrough.estimation.friction_torque.encoder_friction_step`): up to 2g after a
      reversal the command has made and the joint has not yet followed (a slowly reversing
      joint sticks until its servo has built up the breakaway torque). The command's friction
      stays the estimate (driven by the encoder, a start from rest would read the servo's
      rising torque as a push against the motion); the encoder's only says how far to trust
      it. On the simulated er20's seam a wrist joint's command friction was 10–15 N·m off
      for 0.2 s where its σ is 1 N·m: 90 N of phantom force before this term.

    Its envelope (peak hold decaying by ``decay`` per step, so that it
    covers the low-passed τ_ext) enters the weight w_j = 1/√(σ_j² + (κ·u_j)²).

    Args:
        level: g(q̇) [N·m], shape (n,).
        state: F [N·m], shape (n,).
        encoder_state: F_enc, as the encoder alone turns it over [N·m], shape (n,).
        decay: Envelope factor per step, in [0, 1).
        kappa: κ [-], ≥ 0.
        std: σ_j of the calibration residual [N·m], shape (n,), > 0.
        envelope: Envelope of u [N·m] (in place), shape (n,).
        weight: Weights [1/(N·m)], shape (n,) (written).
    """
    for j in range(level.size):
        u = max(abs(level[j] - abs(state[j])), abs(state[j] - encoder_state[j]))
        held = envelope[j] * decay
        envelope[j] = u if u > held else held
        s = kappa * envelope[j]
        weight[j] = 1.0 / np.sqrt(std[j] * std[j] + s * s)


@njit(cache=True, nogil=True)
def wrench_from_torque(jacobian: Array, tau: Array, weight: Array, force_only: bool,
                       mu0: float, max_damping: float, min_lever: float, wrench: Array,
                       gram: Array, factor: Array) -> tuple[float, float]:
    """Joint torque → TCP wrench through a damped pseudo-inverse of Jᵀ (eq. 28–30, in place).

    Full wrench: (J Jᵀ + λ²·1)⁻¹·J·τ, with λ = λ_max·√(1 − (μ/μ₀)²) when the manipulability
    μ = √det(J Jᵀ) < μ₀, else 0.

    ``force_only``: the three force components are the weighted least-squares fit of Jᵥᵀf to τ
    (weights ``weight`` per joint), (Jᵥ W² Jᵥᵀ + s·λ²·1)⁻¹·Jᵥ W² τ, and the torque components
    are zero. A pure force needs only Jᵥ to have full rank, so the damping follows the
    shortest lever arm ℓ = σ_min(Jᵥ) [m] (a force along the weakest direction makes joint
    torques of norm only ℓ per newton), not μ, which also vanishes at the wrist singularity
    where the force stays well observed: λ = λ_max·√(1 − (ℓ/ℓ₀)²) when ℓ < ℓ₀ = ``min_lever``.
    The scale s = tr(Jᵥ W² Jᵥᵀ)/tr(Jᵥ Jᵥᵀ) carries λ [m] into the units of the weighted system
    (with equal weights w, s = w² and the solution is the unweighted damped one).

    Solved by Cholesky in the work space, no allocation; a system that is still singular
    (λ_max = 0 at a singularity) gives a zero wrench.

    Args:
        jacobian: TCP Jacobian in the output frame, shape (6, n).
        tau: Joint torque [N·m], shape (n,).
        weight: Per-joint weights (``force_only``), shape (n,).
        force_only: See above.
        mu0: Manipulability threshold μ₀ (full wrench).
        max_damping: λ_max [m].
        min_lever: ℓ₀ [m] (``force_only``).
        wrench: Output [N, N·m], shape (6,).
        gram: Work space, shape (6, 6).
        factor: Work space, shape (6, 6).

    Returns:
        μ and the damping λ used.
    """
    n = tau.size
    a = gram
    mu = gram_manipulability(jacobian, a, factor)
    m = 3 if force_only else 6
    if force_only:
        lever2 = smallest_eigenvalue_3(a)
        lam = damping_of(np.sqrt(max(lever2, 0.0)), min_lever, max_damping)
        trace = a[0, 0] + a[1, 1] + a[2, 2]
        for r in range(3):
            for c in range(r + 1):
                s = 0.0
                for k in range(n):
                    s += jacobian[r, k] * jacobian[c, k] * weight[k] * weight[k]
                a[r, c] = s
            s = 0.0
            for k in range(n):
                s += jacobian[r, k] * weight[k] * weight[k] * tau[k]
            wrench[r] = s
            wrench[r + 3] = 0.0
        lam2 = lam * lam * (a[0, 0] + a[1, 1] + a[2, 2]) / trace if trace > 0.0 else 0.0
    else:
        lam = damping_of(mu, mu0, max_damping)
        lam2 = lam * lam
        for r in range(6):
            s = 0.0
            for k in range(n):
                s += jacobian[r, k] * tau[k]
            wrench[r] = s
    if cholesky_factor(a, m, lam2, factor):
        cholesky_solve(factor, m, wrench)
    else:
        wrench[:] = 0.0
    return mu, lam
