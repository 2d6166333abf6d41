"""Base (identifiable) parameters by column-pivoted QR of the regressor on random samples.

Many standard parameters never affect the joint torques, and others only in fixed linear
combinations. With the regressor W stacked over random samples, a column-pivoted QR
``W·P = Q·[R11 R12; 0 0]`` splits the columns into r independent ones (P1) and dependent ones
(P2). Then

    β = φ_P1 + R11⁻¹·R12·φ_P2      and      W·φ = W_P1·β,

so the base regressor is simply the independent columns of K. The mapping β = C·φ is kept
explicit (:attr:`BaseParameters.combination`) and every base parameter has a readable name and
expression.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg
from numpy.typing import NDArray

from leadthrough.dynamics.regressor import link_regressor_batch, standard_parameter_names

__all__ = ["BaseParameters", "compute_base_parameters", "random_samples", "rotor_columns"]


@dataclass(frozen=True)
class BaseParameters:
    """Mapping from standard to base parameters.

    Attributes:
        standard_names: Names of the standard parameters φ, length 10·n (+ n rotor inertias
            when built with ``include_rotor``).
        independent: Indices (into φ) of the base columns, shape (r,).
        dependent: Indices of the regrouped columns, shape (10·n − r,).
        combination: C with β = C·φ, shape (r, 10·n).
        names: Base parameter names (the independent standard parameter each is anchored on,
            suffixed ``'`` when other parameters are regrouped into it), length r.
        expressions: Human-readable β_k = φ_a + c·φ_b + ... , length r.
    """

    standard_names: tuple[str, ...]
    independent: NDArray[np.intp]
    dependent: NDArray[np.intp]
    combination: NDArray[np.float64]
    names: tuple[str, ...]
    expressions: tuple[str, ...]

    @property
    def count(self) -> int:
        """Number of base parameters r."""
        return int(self.independent.size)

    def from_standard(self, phi: NDArray[np.float64]) -> NDArray[np.float64]:
        """Base parameters β = C·φ.

        Args:
            phi: Standard parameters, shape (10·n,) or (..., 10·n).

        Returns:
            β, shape (r,) or (..., r).
        """
        return np.asarray(phi, dtype=float) @ self.combination.T

    def regressor(self, K: NDArray[np.float64]) -> NDArray[np.float64]:
        """Base regressor from the full regressor (its independent columns).

        Args:
            K: Regressor, shape (..., 10·n).

        Returns:
            Base regressor, shape (..., r).
        """
        return np.asarray(K)[..., self.independent]


def random_samples(
    model: pin.Model, count: int, rng: np.random.Generator, speed: float = 2.0, acc: float = 5.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Random (q, q̇, q̈) within the model's position limits.

    Args:
        model: Pinocchio model with finite position limits.
        count: Number of samples N.
        rng: Random generator.
        speed: Velocity range ± [rad/s].
        acc: Acceleration range ± [rad/s²].

    Returns:
        q [rad], q̇ [rad/s], q̈ [rad/s²], each shape (N, n).
    """
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    q = rng.uniform(lo, hi, size=(count, model.nq))
    qd = rng.uniform(-speed, speed, size=(count, model.nv))
    qdd = rng.uniform(-acc, acc, size=(count, model.nv))
    return q, qd, qdd


def rotor_columns(qdd: NDArray[np.float64]) -> NDArray[np.float64]:
    """Regressor columns of the rotor inertias M_j·q̈_j (eq. 16).

    Args:
        qdd: Joint accelerations [rad/s²], shape (N, n).

    Returns:
        Columns, shape (N, n, n): entry [k, j, j] = q̈_j.
    """
    qdd = np.atleast_2d(qdd)
    n = qdd.shape[1]
    out = np.zeros((qdd.shape[0], n, n))
    idx = np.arange(n)
    out[:, idx, idx] = qdd
    return out


def compute_base_parameters(
    model: pin.Model,
    samples: int = 200,
    seed: int = 0,
    tol: float = 1e-8,
    include_rotor: bool = False,
) -> BaseParameters:
    """Find the base parameters of a model.

    Args:
        model: Pinocchio model.
        samples: Number of random (q, q̇, q̈) samples to stack.
        seed: Seed of the random samples (fixed so the mapping is reproducible).
        tol: Rank threshold, relative to the largest |R_ii|.
        include_rotor: Append the n rotor inertias M_j (eq. 16) to the standard parameters
            (named ``"<joint>.Mj"``); e.g. M_1 of a vertical first axis is then regrouped into
            ``joint_1.Izz'``.

    Returns:
        The standard-to-base mapping.
    """
    rng = np.random.default_rng(seed)
    q, qd, qdd = random_samples(model, samples, rng)
    K = link_regressor_batch(model, q, qd, qdd)
    if include_rotor:
        K = np.concatenate([K, rotor_columns(qdd)], axis=2)
    W = K.reshape(-1, K.shape[2])
    ind = _independent_columns(W, tol)
    rank = ind.size
    dep = np.setdiff1d(np.arange(W.shape[1]), ind).astype(np.intp)
    if dep.size:
        regroup, *_ = scipy.linalg.lstsq(W[:, ind], W[:, dep])
    else:
        regroup = np.zeros((rank, 0))
    regroup[np.abs(regroup) < 1e-9] = 0.0
    n_std = W.shape[1]
    C = np.zeros((rank, n_std))
    C[np.arange(rank), ind] = 1.0
    C[:, dep] = regroup
    std_names = tuple(standard_parameter_names(model)
                      + ([f"{model.names[j]}.Mj" for j in range(1, model.njoints)]
                         if include_rotor else []))
    names, exprs = _base_names(std_names, ind, dep, regroup)
    return BaseParameters(
        standard_names=std_names,
        independent=ind,
        dependent=dep,
        combination=C,
        names=tuple(names),
        expressions=tuple(exprs),
    )


def _independent_columns(W: NDArray[np.float64], tol: float) -> NDArray[np.intp]:
    """The columns of a stacked regressor that span it: the rank from a column-pivoted QR of
    the column-normalised regressor, the columns chosen greedily in natural parameter order, so
    that parameters of outer links are regrouped into inner ones (the textbook grouping,
    readable coefficients)."""
    norms = np.linalg.norm(W, axis=0)
    # Columns that are zero up to round-off (parameters with no effect at all).
    norms[norms <= 1e-10 * norms.max()] = 0.0
    scale = np.where(norms > 0.0, norms, 1.0)
    Wn = np.where(norms > 0.0, W / scale, 0.0)
    _, R, _ = scipy.linalg.qr(Wn, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > tol * diag[0]))
    chosen: list[int] = []
    basis = np.zeros((Wn.shape[0], 0))
    for j in range(Wn.shape[1]):
        if norms[j] == 0.0:
            continue
        col = Wn[:, j] - basis @ (basis.T @ Wn[:, j])
        col -= basis @ (basis.T @ col)  # re-orthogonalise once for accuracy
        nrm = float(np.linalg.norm(col))
        if nrm > np.sqrt(tol):
            chosen.append(j)
            basis = np.column_stack([basis, col / nrm])
        if len(chosen) == rank:
            break
    return np.asarray(chosen, dtype=np.intp)


def _base_names(std_names: tuple[str, ...], ind: NDArray[np.intp], dep: NDArray[np.intp],
                regroup: NDArray[np.float64]) -> tuple[list[str], list[str]]:
    """Each base parameter's name (primed when it regroups others) and its expression."""
    names: list[str] = []
    exprs: list[str] = []
    for k in range(ind.size):
        terms = [std_names[ind[k]]]
        for j, c in zip(dep, regroup[k], strict=True):
            if c != 0.0:
                sign = "+" if c > 0 else "-"
                mag = abs(c)
                terms.append(f"{sign} {std_names[j]}" if np.isclose(mag, 1.0)
                             else f"{sign} {mag:.6g}·{std_names[j]}")
        names.append(std_names[ind[k]] + ("'" if len(terms) > 1 else ""))
        exprs.append(" ".join(terms))
    return names, exprs
