"""The two least-squares baselines of Table II.

* ``ols-cv``, ref. [7]: K·φ + Fc·sgn(q̇) + β·q̇ (eq. 7), solved by pseudo-inverse (eq. 10).
* ``ols-cbrt``, ref. [22]: adds γ·q̇^{1/3} and the rotor inertia M_j·q̈ (eq. 8–9), same solver.

Both estimate base parameters (the only identifiable combinations); standard parameters are then
chosen closest to nominal, so every method returns the same parameter type.

Given a load term (τ_load, :mod:`leadthrough.identification.load_friction`), both add the
load-dependent Coulomb column |τ_load|·sgn(q̇) per joint, with 0 <= f_cL <= the term's bound
(bounded least squares where the plain solution is outside).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.base_parameters import BaseParameters
from leadthrough.dynamics.friction import load_friction_column
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.identification.load_friction import LoadTerm
from leadthrough.identification.observations import Observations, solve_least_squares

__all__ = ["identify_ols_cbrt", "identify_ols_cv"]

Array = NDArray[np.float64]


def _friction_columns(qd: Array, kinds: tuple[str, ...], load: LoadTerm | None) -> Array:
    N, n = qd.shape
    idx = np.arange(n)
    out = np.zeros((N, n, len(kinds) * n))
    columns = {"coulomb": np.sign(qd), "viscous": qd, "cbrt": np.cbrt(qd)}
    if load is not None:
        columns["load_friction"] = load_friction_column(qd, load.torque)
    for k, kind in enumerate(kinds):
        out[:, idx, k * n + idx] = columns[kind]
    return out


def _solve(obs: Observations, base: BaseParameters, K: Array, kinds: tuple[str, ...],
           load: LoadTerm | None) -> tuple[Array, Array, Array]:
    """Base parameters and the friction columns' coefficients (with 0 <= f_cL <= its bound, on
    the joints whose bound is > 0, when a load term is given); returns the standard φ, M
    (closest to nominal) and the friction coefficients, shape (len(kinds) (+1), n)."""
    n = obs.robot.n
    if load is not None:
        kinds = (*kinds, "load_friction")
    Y = np.concatenate([base.regressor(K), _friction_columns(obs.data.qd, kinds, load)],
                       axis=2)
    names = list(base.names) + [f"{j}.{k}" for k in kinds for j in obs.robot.joint_names]
    keep = np.ones(len(names), dtype=bool)
    bounds = None
    if load is not None:
        fitted = load.upper > 0
        keep[len(names) - n:] = fitted
        free = np.full(int(keep.sum()) - int(fitted.sum()), np.inf)
        bounds = (np.r_[-free, np.zeros(int(fitted.sum()))], np.r_[free, load.upper[fitted]])
    sol = np.zeros(len(names))
    sol[keep] = solve_least_squares(Y[..., keep], obs.data.torque, obs.used,
                                    [m for m, k in zip(names, keep, strict=True) if k],
                                    obs.data.source, bounds)
    r = base.count
    phi, M = obs.standard_from_base(sol[:r], aug=base is obs.base_aug)
    return phi, M, sol[r:].reshape(len(kinds), n)


def _load_friction(f: Array, load: LoadTerm | None) -> Array:
    return np.clip(f[-1], 0.0, load.upper) if load is not None else np.zeros(0)


def identify_ols_cv(obs: Observations, load: LoadTerm | None = None) -> DriveModelParameters:
    """Baseline [7]: links + Coulomb + viscous friction, ordinary least squares.

    Args:
        obs: The observations.
        load: τ_load at the samples and the bound of f_cL, to fit f_cL too; None: no
            load-dependent friction.
    """
    phi, M, f = _solve(obs, obs.base_link, obs.K, ("coulomb", "viscous"), load)
    return DriveModelParameters(phi=phi, friction_model=FrictionModel.COULOMB_VISCOUS,
                                rotor_inertia=M, coulomb=f[0], viscous=f[1],
                                load_friction=_load_friction(f, load))


def identify_ols_cbrt(obs: Observations, load: LoadTerm | None = None) -> DriveModelParameters:
    """Baseline [22]: links + rotor inertia + Coulomb + viscous + cube-root friction, OLS.

    Args:
        obs: The observations.
        load: As :func:`identify_ols_cv`.
    """
    K_aug = np.concatenate([obs.K, obs.K_rotor], axis=2)
    phi, M, f = _solve(obs, obs.base_aug, K_aug, ("coulomb", "viscous", "cbrt"), load)
    return DriveModelParameters(phi=phi, friction_model=FrictionModel.CBRT, rotor_inertia=M,
                                coulomb=f[0], viscous=f[1], cbrt=f[2],
                                load_friction=_load_friction(f, load))
