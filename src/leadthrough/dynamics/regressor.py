"""Link dynamics in linear form, τ_d = K(q, q̇, q̈)·φ (paper eq. 2–3).

The regressor comes from Pinocchio (``computeJointTorqueRegressor``). The standard parameter
vector φ stacks 10 inertial parameters per link (one link per actuated joint, fixed child links
merged), in Pinocchio's order::

    m, m·cx, m·cy, m·cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz

with units kg, kg·m and kg·m². The first moments m·c and the inertia tensor are expressed in the
link's joint frame and taken about the joint frame origin (not about the CoM). Parameter names
are ``"<joint name>.<param>"``, e.g. ``"joint_2.mx"``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

__all__ = [
    "LINK_PARAMETER_NAMES",
    "LINK_PARAMETER_UNITS",
    "link_regressor",
    "link_regressor_batch",
    "link_torque",
    "parameters_to_inertias",
    "standard_parameter_names",
    "standard_parameters",
]

LINK_PARAMETER_NAMES: tuple[str, ...] = (
    "m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz",
)
LINK_PARAMETER_UNITS: tuple[str, ...] = (
    "kg", "kg·m", "kg·m", "kg·m", "kg·m²", "kg·m²", "kg·m²", "kg·m²", "kg·m²", "kg·m²",
)


def standard_parameter_names(model: pin.Model) -> list[str]:
    """Names of the standard parameters φ, ``"<joint>.<param>"``, length 10·n."""
    return [f"{model.names[j]}.{p}" for j in range(1, model.njoints) for p in LINK_PARAMETER_NAMES]


def standard_parameters(model: pin.Model) -> NDArray[np.float64]:
    """Standard parameters φ of a model's link inertias, shape (10·n,)."""
    return np.concatenate(
        [np.asarray(model.inertias[j].toDynamicParameters()).ravel()
         for j in range(1, model.njoints)]
    )


def parameters_to_inertias(phi: NDArray[np.float64]) -> list[pin.Inertia]:
    """Link inertias from a standard parameter vector.

    Args:
        phi: Standard parameters, shape (10·n,).

    Returns:
        One ``pin.Inertia`` per link.
    """
    phi = np.asarray(phi, dtype=float)
    return [pin.Inertia.FromDynamicParameters(phi[10 * k: 10 * k + 10].copy())
            for k in range(phi.size // 10)]


def link_regressor(
    model: pin.Model,
    data: pin.Data,
    q: NDArray[np.float64],
    qd: NDArray[np.float64],
    qdd: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Joint torque regressor K(q, q̇, q̈) of eq. 3 at one sample.

    Args:
        model: Pinocchio model.
        data: Matching Pinocchio data (workspace).
        q: Joint positions [rad], shape (n,).
        qd: Joint velocities [rad/s], shape (n,).
        qdd: Joint accelerations [rad/s²], shape (n,).

    Returns:
        K, shape (n, 10·n), such that K·φ is the link torque [N·m].
    """
    return np.array(pin.computeJointTorqueRegressor(model, data, q, qd, qdd))


def link_regressor_batch(
    model: pin.Model,
    q: NDArray[np.float64],
    qd: NDArray[np.float64],
    qdd: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Regressor for many samples.

    Args:
        model: Pinocchio model.
        q: Joint positions [rad], shape (N, n).
        qd: Joint velocities [rad/s], shape (N, n).
        qdd: Joint accelerations [rad/s²], shape (N, n).

    Returns:
        K per sample, shape (N, n, 10·n).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    qd = np.atleast_2d(np.asarray(qd, dtype=float))
    qdd = np.atleast_2d(np.asarray(qdd, dtype=float))
    data = model.createData()
    out = np.empty((q.shape[0], model.nv, 10 * (model.njoints - 1)))
    for k in range(q.shape[0]):
        out[k] = pin.computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k])
    return out


def link_torque(
    model: pin.Model,
    phi: NDArray[np.float64],
    q: NDArray[np.float64],
    qd: NDArray[np.float64],
    qdd: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Link torque τ_d = K·φ for many samples (eq. 3).

    Args:
        model: Pinocchio model (its own inertias are ignored).
        phi: Standard parameters, shape (10·n,).
        q: Joint positions [rad], shape (N, n).
        qd: Joint velocities [rad/s], shape (N, n).
        qdd: Joint accelerations [rad/s²], shape (N, n).

    Returns:
        Link torques [N·m], shape (N, n).
    """
    return link_regressor_batch(model, q, qd, qdd) @ np.asarray(phi, dtype=float)
