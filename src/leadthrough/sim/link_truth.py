"""True link parameters of a simulated robot: the CAD values perturbed, physically consistent.

The paper's CAD model is inaccurate; the simulator plays that by drawing each link's true mass,
centre of mass and inertia within ±``max_deviation`` of nominal, in the paper's eq. 37 sense:

* mass: m·(1 + u·d);
* CoM: c + u·d·max|c| per component;
* rotational inertia about the CoM: every entry within d·max|I_c| of nominal.

Inertia is perturbed through the second-moment matrix Σ = ½·tr(I)·1 − I (PSD for any real
body): its eigenvalues are scaled and its axes slightly rotated, and the result is pulled back
toward nominal until the entry bound holds. Σ stays PSD, so every drawn link is physically
consistent (positive mass, triangle inequalities).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

__all__ = ["perturb_inertia", "second_moment", "true_link_inertias"]


def second_moment(inertia_com: NDArray[np.float64]) -> NDArray[np.float64]:
    """Σ = ½·tr(I)·1 − I, the mass-weighted covariance of a body about its CoM [kg·m²]."""
    return 0.5 * np.trace(inertia_com) * np.eye(3) - inertia_com


def _from_second_moment(sigma: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.trace(sigma) * np.eye(3) - sigma


def perturb_inertia(
    nominal: pin.Inertia, rng: np.random.Generator, max_deviation: float
) -> pin.Inertia:
    """Draw a physically consistent link inertia within ±max_deviation of nominal (eq. 37 sense).

    Args:
        nominal: Nominal (CAD) link inertia.
        rng: Random generator.
        max_deviation: Relative bound d, e.g. 0.3 for ±30 %.

    Returns:
        The perturbed inertia.
    """
    d = float(max_deviation)
    m = float(nominal.mass) * (1.0 + d * rng.uniform(-1.0, 1.0))
    c_nom = np.asarray(nominal.lever, dtype=float)
    c_scale = float(np.max(np.abs(c_nom)))
    c = c_nom + d * c_scale * rng.uniform(-1.0, 1.0, 3)
    I_nom = np.asarray(nominal.inertia, dtype=float)
    sig_nom = second_moment(I_nom)
    w, V = np.linalg.eigh(sig_nom)
    w = np.maximum(w, 0.0) * (1.0 + d * rng.uniform(-1.0, 1.0, 3))
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.1 * d).as_matrix()
    V2 = rot @ V
    sig = V2 @ np.diag(w) @ V2.T
    I_new = _from_second_moment(sig)
    bound = d * float(np.max(np.abs(I_nom)))
    dev = float(np.max(np.abs(I_new - I_nom)))
    if dev > bound > 0.0:
        # Convex combination of two PSD second moments stays PSD.
        alpha = bound / dev
        I_new = _from_second_moment(sig_nom + alpha * (sig - sig_nom))
    I_new = 0.5 * (I_new + I_new.T)
    return pin.Inertia(m, c, I_new)


def true_link_inertias(
    model: pin.Model, rng: np.random.Generator, max_deviation: float
) -> list[pin.Inertia]:
    """Perturbed inertia for every link of a model (joint order 1..n).

    Args:
        model: Pinocchio model with nominal inertias.
        rng: Random generator.
        max_deviation: Relative bound d (0 returns the nominal inertias).

    Returns:
        One inertia per actuated link.
    """
    out = []
    for j in range(1, model.njoints):
        nominal = model.inertias[j]
        out.append(pin.Inertia(nominal) if max_deviation == 0.0
                   else perturb_inertia(nominal, rng, max_deviation))
    return out
