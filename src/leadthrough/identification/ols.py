"""The two least-squares baselines of Table II.

* ``ols-cv``, ref. [7]: K·φ + Fc·sgn(q̇) + β·q̇ (eq. 7), solved by pseudo-inverse (eq. 10).
* ``ols-cbrt``, ref. [22]: adds γ·q̇^{1/3} and the rotor inertia M_j·q̈ (eq. 8–9), same solver.

Both estimate base parameters (the only identifiable combinations); standard parameters are then
chosen closest to nominal, so every method returns the same parameter type.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.identification.observations import Observations, solve_least_squares

__all__ = ["identify_ols_cbrt", "identify_ols_cv"]

Array = NDArray[np.float64]


def _friction_columns(qd: Array, kinds: tuple[str, ...]) -> Array:
    N, n = qd.shape
    idx = np.arange(n)
    out = np.zeros((N, n, len(kinds) * n))
    columns = {"coulomb": np.sign(qd), "viscous": qd, "cbrt": np.cbrt(qd)}
    for k, kind in enumerate(kinds):
        out[:, idx, k * n + idx] = columns[kind]
    return out


def _names(obs: Observations, base_names: tuple[str, ...], kinds: tuple[str, ...]) -> list[str]:
    return list(base_names) + [f"{j}.{k}" for k in kinds for j in obs.robot.joint_names]


def identify_ols_cv(obs: Observations) -> DriveModelParameters:
    """Baseline [7]: links + Coulomb + viscous friction, ordinary least squares."""
    n = obs.robot.n
    kinds = ("coulomb", "viscous")
    Y = np.concatenate([obs.base_link.regressor(obs.K), _friction_columns(obs.data.qd, kinds)],
                       axis=2)
    sol = solve_least_squares(Y, obs.data.torque, obs.used,
                              _names(obs, obs.base_link.names, kinds), obs.data.source)
    r = obs.base_link.count
    phi, M = obs.standard_from_base(sol[:r], aug=False)
    return DriveModelParameters(phi=phi, friction_model=FrictionModel.COULOMB_VISCOUS,
                                rotor_inertia=M, coulomb=sol[r:r + n],
                                viscous=sol[r + n:r + 2 * n])


def identify_ols_cbrt(obs: Observations) -> DriveModelParameters:
    """Baseline [22]: links + rotor inertia + Coulomb + viscous + cube-root friction, OLS."""
    n = obs.robot.n
    kinds = ("coulomb", "viscous", "cbrt")
    K_aug = np.concatenate([obs.K, obs.K_rotor], axis=2)
    Y = np.concatenate([obs.base_aug.regressor(K_aug), _friction_columns(obs.data.qd, kinds)],
                       axis=2)
    sol = solve_least_squares(Y, obs.data.torque, obs.used,
                              _names(obs, obs.base_aug.names, kinds), obs.data.source)
    r = obs.base_aug.count
    phi, M = obs.standard_from_base(sol[:r], aug=True)
    return DriveModelParameters(phi=phi, friction_model=FrictionModel.CBRT, rotor_inertia=M,
                                coulomb=sol[r:r + n], viscous=sol[r + n:r + 2 * n],
                                cbrt=sol[r + 2 * n:r + 3 * n])
