"""Damped least squares: the small linear algebra shared by the force estimate and the IK.

Both map through a damped pseudo-inverse of a 6×n TCP Jacobian J: the estimator maps joint
torques to a wrench, w = (J Jᵀ + λ²·1)⁻¹·J·τ (paper eq. 28–30), the differential IK a twist to
joint velocities, q̇ = Jᵀ(J Jᵀ + λ²·1)⁻¹·ν. The damping grows as the manipulability
μ = √det(J Jᵀ) falls below a threshold μ₀ (Nakamura and Hanafusa, 1986):
λ = λ_max·√(1 − (μ/μ₀)²), so both stay bounded near a singularity.

Compiled (Numba, ``nopython``, cached on disk), allocation-free: the 6×6 systems are solved by
Cholesky in preallocated arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "cholesky_factor",
    "cholesky_solve",
    "damping_of",
    "gram_manipulability",
    "smallest_eigenvalue_3",
]

Array = NDArray[np.float64]


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
