"""True link parameters of a simulated robot: the CAD values perturbed, physically consistent.

The paper's CAD model is inaccurate; the simulator plays that by drawing each link's true mass,
centre of mass and inertia within ±``max_deviation`` of nominal, in the paper's eq. 37 sense
(the box that the ``proposed`` and ``consistent`` identifications enforce):

* mass: m·(1 + u·d);
* CoM: c + u·d·max|c| per component;
* rotational inertia about the CoM: every entry within d·max|I_c| of nominal.

Inertia is perturbed through the second-moment matrix Σ = ½·tr(I)·1 − I (PSD for any real
body): its eigenvalues are scaled and its axes slightly rotated, and the result is pulled back
toward nominal until the entry bound holds. Σ stays PSD, so every drawn link is physically
consistent (positive mass, triangle inequalities).

The realistic plant (:mod:`leadthrough.sim.plant`) does not keep its links inside that box: a
CAD model misses parts, grease, cables and castings' tolerances unevenly. After the in-box draw,
each link with probability ``outlier_probability`` gets one quantity drawn outside it
(:func:`with_outliers`), still physically consistent:

* mass: m₀·(1 ± d·b), which stays positive for d·b < 1;
* CoM: one component c₀ₖ ± d·b·max|c₀|;
* inertia: the second moment Σ₀ scaled by (1 ± d·b) with a little anisotropy (Σ stays PSD),

with b the box's half-width and d drawn from ``outlier_deviation`` (> 1). On top comes the
unmodelled dress pack (:mod:`leadthrough.sim.dress_pack`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.errors import SimulationError
from leadthrough.sim.dress_pack import DressPackConfig, dress_pack_inertias

__all__ = ["LinkMismatchConfig", "outside_box", "perturb_inertia", "second_moment",
           "true_link_inertias", "with_model_mismatch", "with_outliers"]

#: Relative slack of :func:`outside_box` (rounding of a value drawn on the box's edge).
_BOX_SLACK = 1e-9


@dataclass(frozen=True)
class LinkMismatchConfig:
    """How the realistic plant's links differ from the CAD model beyond the identifier's box.

    Attributes:
        outlier_probability: Chance that a link has one quantity (mass, CoM or rotational
            inertia, equally likely) outside the box [-].
        outlier_deviation: Range of that quantity's deviation in units of the box's half-width
            [-] (1.15–2: 35–60 % of nominal for the ±30 % box).
        box: Relative half-width of the box the outliers leave (eq. 37; the identifiers'
            default bound) [-].
        dress_pack: The unmodelled hose and cable package.
    """

    outlier_probability: float = 0.15
    outlier_deviation: tuple[float, float] = (1.15, 2.0)
    box: float = 0.3
    dress_pack: DressPackConfig = field(default_factory=DressPackConfig)

    def __post_init__(self) -> None:
        lo, hi = self.outlier_deviation
        if not 0.0 <= self.outlier_probability <= 1.0:
            raise SimulationError("out of range", field="links.outlier_probability",
                                  value=self.outlier_probability, expected="0 <= p <= 1")
        if not 0.0 < self.box < 1.0:
            raise SimulationError("out of range", field="links.box", value=self.box,
                                  expected="0 < box < 1")
        if not (1.0 < lo <= hi and hi * self.box < 1.0):
            raise SimulationError("out of range", field="links.outlier_deviation",
                                  value=self.outlier_deviation,
                                  expected=f"1 < low <= high < {1.0 / self.box:g} (outside "
                                           "the box, mass stays positive)")


def outside_box(nominal: pin.Inertia, true: pin.Inertia, box: float) -> bool:
    """Whether a link's mass, a CoM component or an entry of its rotational inertia lies
    outside ±box of nominal (eq. 37: the mass relative to itself, CoM components relative to
    max|c₀|, inertia entries relative to max|I₀|)."""
    slack = 1.0 + _BOX_SLACK
    m0 = float(nominal.mass)
    c0 = np.asarray(nominal.lever, dtype=float)
    I0 = np.asarray(nominal.inertia, dtype=float)
    return bool(abs(float(true.mass) - m0) > slack * box * m0
                or np.any(np.abs(np.asarray(true.lever) - c0)
                          > slack * box * np.max(np.abs(c0)))
                or np.any(np.abs(np.asarray(true.inertia) - I0)
                          > slack * box * np.max(np.abs(I0))))


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


def _outlier(nominal: pin.Inertia, drawn: pin.Inertia, rng: np.random.Generator,
             config: LinkMismatchConfig) -> pin.Inertia:
    """``drawn`` with one quantity replaced by a draw outside the box (see the module doc)."""
    m, c, inertia = float(drawn.mass), np.array(drawn.lever), np.array(drawn.inertia)
    m0, c0 = float(nominal.mass), np.asarray(nominal.lever, dtype=float)
    dev = config.box * rng.uniform(*config.outlier_deviation)
    sign = rng.choice((-1.0, 1.0))
    kinds = ["mass", "inertia"] + (["com"] if np.max(np.abs(c0)) > 0.0 else [])
    kind = kinds[int(rng.integers(len(kinds)))]
    if kind == "mass":
        m = m0 * (1.0 + sign * dev)
    elif kind == "com":
        k = int(rng.integers(3))
        c[k] = c0[k] + sign * dev * float(np.max(np.abs(c0)))
    else:
        w, V = np.linalg.eigh(second_moment(np.asarray(nominal.inertia, dtype=float)))
        w = np.maximum(w, 0.0) * (1.0 + sign * dev) * (1.0 + 0.1 * rng.uniform(-1.0, 1.0, 3))
        inertia = _from_second_moment(V @ np.diag(w) @ V.T)
        if not outside_box(nominal, pin.Inertia(m0, c0, inertia), config.box):
            # the anisotropy pulled every entry back in: scale uniformly instead
            inertia = (1.0 + sign * dev) * np.asarray(nominal.inertia, dtype=float)
        inertia = 0.5 * (inertia + inertia.T)
    return pin.Inertia(m, c, inertia)


def with_outliers(model: pin.Model, inertias: list[pin.Inertia], rng: np.random.Generator,
                  config: LinkMismatchConfig) -> list[pin.Inertia]:
    """Links drawn in the box, with some quantities moved outside it (see the module doc).

    Args:
        model: Pinocchio model with the nominal inertias.
        inertias: The in-box draw, joint order 1..n.
        rng: Random generator of the outliers.
        config: Outlier probability and size.

    Returns:
        One inertia per link; each physically consistent.
    """
    out = []
    for j, drawn in enumerate(inertias, start=1):
        hit = rng.uniform() < config.outlier_probability
        out.append(_outlier(model.inertias[j], drawn, rng, config) if hit else drawn)
    return out


def with_model_mismatch(model: pin.Model, inertias: list[pin.Inertia],
                        rng: np.random.Generator, config: LinkMismatchConfig
                        ) -> list[pin.Inertia]:
    """The realistic plant's links: the in-box draw with outliers and the dress pack.

    Args:
        model: Pinocchio model with the nominal inertias.
        inertias: The in-box draw, joint order 1..n.
        rng: Random generator of the mismatch (not that of the in-box draw).
        config: Outliers and dress pack.

    Returns:
        One inertia per link, joint order.
    """
    out = with_outliers(model, inertias, rng, config)
    for j, pack in dress_pack_inertias(model, config.dress_pack, rng).items():
        out[j - 1] = out[j - 1] + pack
    return out
