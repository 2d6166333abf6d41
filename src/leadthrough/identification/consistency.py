"""Physical consistency of link parameters: pseudo-inertia matrices and convex bounds.

For a link with standard parameters φ = (m, h = m·c, I_o) (inertia about the link frame origin),
the 4×4 pseudo-inertia matrix is (Wensing, Kim, Slotine 2017)::

    J(φ) = [[Σ_o, h], [hᵀ, m]],   Σ_o = ½·tr(I_o)·1 − I_o

It is linear in φ, and J ⪰ 0 exactly when some mass distribution has these parameters: it implies
m > 0, a positive-definite I_c and the triangle inequalities, so it is stronger than the paper's
positive-definite 3×3 inertia (Step 5).

The paper's bounds (eq. 37) are a box on (m, c, I_c). Mass and CoM bounds are convex in φ:
m_lo ≤ m ≤ m_hi and m·c_lo ≤ h ≤ m·c_hi (m > 0). The box on I_c is not (I_c = I_o − S(h)/m);
:func:`link_bounds` replaces it by the smallest box on I_o that contains every (m, c, I_c) of the
paper's box (interval arithmetic on the parallel-axis term), an outer relaxation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LinkBounds", "link_bounds", "min_pseudo_inertia_eigenvalues", "pseudo_inertia"]

Array = NDArray[np.float64]


def pseudo_inertia(phi_link: Array) -> Array:
    """Pseudo-inertia J of one link from its 10 standard parameters, shape (4, 4)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.asarray(phi_link, dtype=float)
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    out = np.zeros((4, 4))
    out[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    out[:3, 3] = out[3, :3] = (hx, hy, hz)
    out[3, 3] = m
    return out


def min_pseudo_inertia_eigenvalues(phi: Array) -> Array:
    """Smallest eigenvalue of each link's pseudo-inertia [kg·m²], shape (n,).

    Negative values mean the parameters cannot belong to any real body.
    """
    phi = np.asarray(phi, dtype=float)
    return np.array([np.linalg.eigvalsh(pseudo_inertia(phi[10 * k:10 * k + 10]))[0]
                     for k in range(phi.size // 10)])


@dataclass(frozen=True)
class LinkBounds:
    """Convex bounds of one link (eq. 37, relaxed as described in the module docstring).

    Attributes:
        mass: (lower, upper) [kg].
        com_lower: Lower CoM bound per axis [m], shape (3,).
        com_upper: Upper CoM bound per axis [m], shape (3,).
        inertia_lower: Lower bound of (Ixx, Ixy, Iyy, Ixz, Iyz, Izz) about the link origin.
        inertia_upper: Upper bound of the same entries [kg·m²].
    """

    mass: tuple[float, float]
    com_lower: Array
    com_upper: Array
    inertia_lower: Array
    inertia_upper: Array


def _product_range(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    p = [a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]]
    return min(p), max(p)


def _square_range(a: tuple[float, float]) -> tuple[float, float]:
    lo = 0.0 if a[0] <= 0.0 <= a[1] else min(a[0] ** 2, a[1] ** 2)
    return lo, max(a[0] ** 2, a[1] ** 2)


def link_bounds(phi_link: Array, bound: float) -> LinkBounds:
    """Bounds around a nominal link (paper eq. 37) as a convex set in φ.

    Args:
        phi_link: Nominal standard parameters, shape (10,).
        bound: Relative bound, e.g. 0.3 for ±30 %.

    Returns:
        The bounds.
    """
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.asarray(phi_link, dtype=float)
    c = np.array([hx, hy, hz]) / m
    io = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    s_c = np.dot(c, c) * np.eye(3) - np.outer(c, c)
    ic = io - m * s_c
    m_rng = ((1.0 - bound) * m, (1.0 + bound) * m)
    dc = bound * float(np.max(np.abs(c)))
    c_rng = [(c[i] - dc, c[i] + dc) for i in range(3)]
    di = bound * float(np.max(np.abs(ic)))
    sq = [_square_range(r) for r in c_rng]
    # Parallel-axis term m·S(c) per entry (xx, xy, yy, xz, yz, zz), by interval arithmetic.
    entries = {
        (0, 0): (sq[1][0] + sq[2][0], sq[1][1] + sq[2][1]),
        (1, 1): (sq[0][0] + sq[2][0], sq[0][1] + sq[2][1]),
        (2, 2): (sq[0][0] + sq[1][0], sq[0][1] + sq[1][1]),
        (0, 1): tuple(-v for v in reversed(_product_range(c_rng[0], c_rng[1]))),
        (0, 2): tuple(-v for v in reversed(_product_range(c_rng[0], c_rng[2]))),
        (1, 2): tuple(-v for v in reversed(_product_range(c_rng[1], c_rng[2]))),
    }
    order = [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]
    lo, hi = [], []
    for ij in order:
        ms = _product_range(m_rng, entries[ij])  # type: ignore[arg-type]
        lo.append(ic[ij] - di + ms[0])
        hi.append(ic[ij] + di + ms[1])
    return LinkBounds(
        mass=m_rng,
        com_lower=np.array([r[0] for r in c_rng]),
        com_upper=np.array([r[1] for r in c_rng]),
        inertia_lower=np.array(lo),
        inertia_upper=np.array(hi),
    )
