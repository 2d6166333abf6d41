"""Compiled inner loops of the real-time estimator (Numba, ``nopython``, cached on disk).

With six joints, each NumPy call costs more in dispatch (~0.5–1 µs) than in arithmetic, and one
estimator sample needs dozens of them. These kernels fuse the element-wise work of one sample
into a single compiled call each, so an update costs a few Pinocchio calls plus two kernel
calls. The real-time filter and model classes call them too. The friction here is eq. 15 with
the smoothed sign (with memory: :mod:`leadthrough.estimation.presliding_kernels`); the offline model
(:mod:`leadthrough.dynamics.friction`, exact sign) is the reference, and
``tests/test_estimation.py`` checks that both agree away from standstill.

All kernels write into preallocated arrays and return nothing (or a float); none allocates
(the small symmetric systems are solved by :func:`cholesky_factor` / :func:`cholesky_solve`).

Friction parameter rows (``fp``, shape (8, n)), see :mod:`leadthrough.dynamics.friction`:
``0`` 1/v_ε (smoothed sign), ``1`` Coulomb f1, ``2`` viscous f4, ``3`` R/q̇_sm, ``4`` f2,
``5`` 1/q̇_sg, ``6`` f3, ``7`` cube-root coefficient (OLS-cbrt model only).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "FRICTION_ROWS",
    "cholesky_factor",
    "cholesky_solve",
    "damping_of",
    "direct_residual",
    "friction_torque",
    "friction_weights",
    "gram_manipulability",
    "low_pass_step",
    "momentum_step",
    "smallest_eigenvalue_3",
    "smooth_sign",
    "svf_step",
    "wrench_from_torque",
]

Array = NDArray[np.float64]
FRICTION_ROWS = 8


@njit(cache=True, nogil=True)
def svf_step(coef: Array, q: Array, position: Array, velocity: Array,
             acceleration: Array) -> None:
    """One exact-discretised step of the state-variable differentiator (in place).

    Args:
        coef: [a11, a12, a21, a22, b1, b2, 1/dt], shape (7,).
        q: Measured positions, shape (n,).
        position: Filtered positions (state), shape (n,).
        velocity: Filtered velocities (state), shape (n,).
        acceleration: Output: backward difference of the filtered velocity, shape (n,).
    """
    for j in range(q.size):
        v_new = coef[2] * position[j] + coef[3] * velocity[j] + coef[5] * q[j]
        position[j] = coef[0] * position[j] + coef[1] * velocity[j] + coef[4] * q[j]
        acceleration[j] = (v_new - velocity[j]) * coef[6]
        velocity[j] = v_new


@njit(cache=True, nogil=True)
def low_pass_step(alpha: float, x: Array, value: Array) -> None:
    """First-order low-pass y ← y + α·(x − y) (in place on ``value``)."""
    for j in range(x.size):
        value[j] += alpha * (x[j] - value[j])


@njit(cache=True, nogil=True)
def smooth_sign(qd: Array, fp: Array, sign: Array) -> None:
    """The smoothed friction sign sat(q̇/v_ε) (in place on ``sign``).

    Args:
        qd: Joint velocities [rad/s], shape (n,).
        fp: Friction parameter rows, shape (8, n) (row 0 is 1/v_ε).
        sign: Output in [−1, 1], shape (n,).
    """
    for j in range(qd.size):
        sign[j] = min(1.0, max(-1.0, qd[j] * fp[0, j]))


@njit(cache=True, nogil=True)
def friction_weights(level: Array, state: Array, decay: float, kappa: float, std: Array,
                     envelope: Array, weight: Array) -> None:
    """Per-joint weights of the force fit from the friction's uncertainty, one step.

    u_j = |g_j(q̇) − |F_j||, the gap between the friction state of
    :func:`presliding_friction_step` and the eq. 15 level at the current speed: zero in steady
    sliding, up to g while the friction turns over after a reversal (|F| passes through zero,
    and where the gear is then depends on its presliding, of which the model's z₀ is only a
    guess), and at standstill the gap to the static level (a stopped gear's friction can be
    anything up to it). Its envelope (peak hold decaying by ``decay`` per step, so that it
    covers the low-passed τ_ext) enters the weight w_j = 1/√(σ_j² + (κ·u_j)²).

    Args:
        level: g(q̇) [N·m], shape (n,).
        state: F [N·m], shape (n,).
        decay: Envelope factor per step, in [0, 1).
        kappa: κ [-], ≥ 0.
        std: σ_j of the calibration residual [N·m], shape (n,), > 0.
        envelope: Envelope of u [N·m] (in place), shape (n,).
        weight: Weights [1/(N·m)], shape (n,) (written).
    """
    for j in range(level.size):
        u = abs(level[j] - abs(state[j]))
        held = envelope[j] * decay
        envelope[j] = u if u > held else held
        s = kappa * envelope[j]
        weight[j] = 1.0 / np.sqrt(std[j] * std[j] + s * s)


@njit(cache=True, nogil=True)
def friction_torque(qd: Array, sign: Array, fp: Array, stribeck: bool, out: Array) -> None:
    """Joint friction for a given friction direction (eq. 15, or the OLS models) [N·m].

    Args:
        qd: Joint velocities [rad/s], shape (n,).
        sign: Friction direction in [−1, 1] (:func:`smooth_sign`), shape (n,).
        fp: Friction parameter rows, shape (8, n) (module docstring).
        stribeck: Use the Stribeck rows (eq. 15) instead of the cube-root row.
        out: Output [N·m], shape (n,).
    """
    for j in range(qd.size):
        v = qd[j]
        s = sign[j]
        f = s * fp[1, j] + v * fp[2, j]
        if stribeck:
            a = v * fp[3, j]
            b = v * fp[5, j]
            f += s * (fp[4, j] * np.exp(-a * a) + fp[6, j] * np.exp(-b * b))
        else:
            f += fp[7, j] * np.cbrt(v)
        out[j] = f


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
def damping_of(mu: float, mu0: float, max_damping: float) -> float:
    """Damping λ = λ_max·√(1 − (μ/μ₀)²) below the manipulability threshold μ₀, else 0."""
    if mu >= mu0:
        return 0.0
    return max_damping * np.sqrt(1.0 - (mu / mu0) ** 2)


@njit(cache=True, nogil=True)
def cholesky_factor(a: Array, m: int, shift: float, factor: Array) -> bool:
    """Lower Cholesky factor L (L Lᵀ = A + shift·1) of the leading m×m block of a symmetric
    matrix (``a`` is not modified).

    Args:
        a: Symmetric matrix; its lower triangle of the leading m×m block is read.
        m: Block size.
        shift: Added to the diagonal (a damping λ²), ≥ 0.
        factor: Output: L in the lower triangle of its leading m×m block (the rest untouched);
            may not alias ``a``.

    Returns:
        False if the block is not (numerically) positive definite (``factor`` then partial).
    """
    for j in range(m):
        s = a[j, j] + shift
        for k in range(j):
            s -= factor[j, k] * factor[j, k]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        factor[j, j] = d
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= factor[i, k] * factor[j, k]
            factor[i, j] = s / d
    return True


@njit(cache=True, nogil=True)
def cholesky_solve(factor: Array, m: int, x: Array) -> None:
    """Solve L Lᵀ·x = b in place (``x`` holds b on entry), L from :func:`cholesky_factor`."""
    for i in range(m):
        s = x[i]
        for k in range(i):
            s -= factor[i, k] * x[k]
        x[i] = s / factor[i, i]
    for i in range(m - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, m):
            s -= factor[k, i] * x[k]
        x[i] = s / factor[i, i]


@njit(cache=True, nogil=True)
def gram_manipulability(jacobian: Array, gram: Array, factor: Array) -> float:
    """J Jᵀ (into ``gram``, shape (6, 6)) and the manipulability μ = √det(J Jᵀ) = ∏ L_ii of
    its Cholesky factor (into ``factor``, shape (6, 6); μ = 0 if J Jᵀ is not positive
    definite), for the estimator's Jᵀ inverse and the controller's IK alike. No allocation."""
    n = jacobian.shape[1]
    for r in range(6):
        for c in range(r, 6):
            s = 0.0
            for k in range(n):
                s += jacobian[r, k] * jacobian[c, k]
            gram[r, c] = s
            gram[c, r] = s
    if not cholesky_factor(gram, 6, 0.0, factor):
        return 0.0
    mu = 1.0
    for r in range(6):
        mu *= factor[r, r]
    return mu


@njit(cache=True, nogil=True)
def smallest_eigenvalue_3(a: Array) -> float:
    """Smallest eigenvalue of the leading 3×3 block of a symmetric matrix, in closed form
    (trigonometric solution of the characteristic cubic; no allocation). Near a repeated
    eigenvalue the arccos limits the absolute accuracy to ~1e-8 of the matrix's scale, ample
    for a damping threshold.

    Args:
        a: Symmetric matrix; the upper triangle of its leading 3×3 block is read.

    Returns:
        The smallest eigenvalue.
    """
    p1 = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
    q = (a[0, 0] + a[1, 1] + a[2, 2]) / 3.0
    d0, d1, d2 = a[0, 0] - q, a[1, 1] - q, a[2, 2] - q
    p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1
    if p2 <= 0.0:
        return q                                     # a multiple of the identity
    p = np.sqrt(p2 / 6.0)
    # B = (A − q·1)/p (scaled first: no under- or overflow), r = det(B)/2, in [−1, 1] up to
    # rounding
    b0, b1, b2 = d0 / p, d1 / p, d2 / p
    b01, b02, b12 = a[0, 1] / p, a[0, 2] / p, a[1, 2] / p
    r = 0.5 * (b0 * (b1 * b2 - b12 * b12) - b01 * (b01 * b2 - b12 * b02)
               + b02 * (b01 * b12 - b1 * b02))
    r = min(1.0, max(-1.0, r))
    return q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)


@njit(cache=True, nogil=True)
def wrench_from_torque(jacobian: Array, tau: Array, weight: Array, force_only: bool,
                       mu0: float, max_damping: float, min_lever: float, wrench: Array,
                       scratch: Array, info: Array) -> None:
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

    Solved by Cholesky in ``scratch``, no allocation; a system that is still singular
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
        scratch: Work space, shape (2, 6, 6).
        info: Output: μ and the damping λ used, shape (2,).
    """
    n = tau.size
    a, factor = scratch[0], scratch[1]
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
    info[0] = mu
    info[1] = lam
