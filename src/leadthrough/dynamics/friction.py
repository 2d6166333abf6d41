"""Drive-train friction and rotor inertia models, all joint-side [N·m].

* :func:`stribeck_friction`: the paper's model, eq. 15 (motor and gearbox friction, each Coulomb +
  Stribeck, plus viscous):

      τ_f = f1·sgn(q̇) + f2·exp(−(R·q̇/q̇sm)²)·sgn(q̇) + f3·exp(−(q̇/q̇sg)²)·sgn(q̇) + f4·q̇

  q̇sm is the motor-side Stribeck velocity (compared with the motor speed R·q̇), q̇sg the gear-side
  one (compared with the joint speed q̇).
* :func:`coulomb_viscous_friction`: baseline [7], eq. 5: Fc·sgn(q̇) + β·q̇.
* :func:`cbrt_friction`: baseline [22], eq. 8: Fc·sgn(q̇) + β·q̇ + γ·q̇^{1/3}.
* :func:`rotor_inertia_torque`: eq. 16, M_j·q̈ with M_j the reflected rotor inertia.

All functions broadcast over samples: inputs of shape (N, n) with parameters of shape (n,).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "StribeckParameters",
    "cbrt_friction",
    "coulomb_viscous_friction",
    "rotor_inertia_torque",
    "stribeck_friction",
    "stribeck_shapes",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StribeckParameters:
    """Parameters of eq. 15, one entry per joint, shape (n,) each.

    Attributes:
        f1: Coulomb friction [N·m].
        f2: Motor-side Stribeck amplitude [N·m].
        qd_sm: Motor-side Stribeck velocity [rad/s, motor side].
        f3: Gear-side Stribeck amplitude [N·m].
        qd_sg: Gear-side Stribeck velocity [rad/s, joint side].
        f4: Viscous friction [N·m·s/rad].
    """

    f1: Array
    f2: Array
    qd_sm: Array
    f3: Array
    qd_sg: Array
    f4: Array


def stribeck_shapes(
    qd: Array, gear_ratio: Array, qd_sm: Array, qd_sg: Array
) -> tuple[Array, Array, Array]:
    """The nonlinear shape functions of eq. 15 (what f2 and f3 multiply).

    Args:
        qd: Joint velocities [rad/s], shape (N, n).
        gear_ratio: R, shape (n,).
        qd_sm: Motor-side Stribeck velocities [rad/s motor], shape (n,).
        qd_sg: Gear-side Stribeck velocities [rad/s joint], shape (n,).

    Returns:
        sgn(q̇), exp(−(R·q̇/q̇sm)²)·sgn(q̇) and exp(−(q̇/q̇sg)²)·sgn(q̇), each shape (N, n).
    """
    s = np.sign(qd)
    motor = np.exp(-np.square(gear_ratio * qd / qd_sm)) * s
    gear = np.exp(-np.square(qd / qd_sg)) * s
    return s, motor, gear


def stribeck_friction(qd: Array, gear_ratio: Array, p: StribeckParameters) -> Array:
    """Joint friction of eq. 15.

    Args:
        qd: Joint velocities [rad/s], shape (N, n) or (n,).
        gear_ratio: R, shape (n,).
        p: Friction parameters.

    Returns:
        Friction torque [N·m], same shape as ``qd``.
    """
    s, motor, gear = stribeck_shapes(qd, gear_ratio, p.qd_sm, p.qd_sg)
    return p.f1 * s + p.f2 * motor + p.f3 * gear + p.f4 * qd


def coulomb_viscous_friction(qd: Array, fc: Array, fv: Array) -> Array:
    """Baseline friction of ref. [7], eq. 5: Fc·sgn(q̇) + β·q̇.

    Args:
        qd: Joint velocities [rad/s], shape (N, n).
        fc: Coulomb friction [N·m], shape (n,).
        fv: Viscous friction [N·m·s/rad], shape (n,).

    Returns:
        Friction torque [N·m], shape (N, n).
    """
    return fc * np.sign(qd) + fv * qd


def cbrt_friction(qd: Array, fc: Array, fv: Array, gamma: Array) -> Array:
    """Baseline friction of ref. [22], eq. 8: Fc·sgn(q̇) + β·q̇ + γ·q̇^{1/3}.

    Args:
        qd: Joint velocities [rad/s], shape (N, n).
        fc: Coulomb friction [N·m], shape (n,).
        fv: Viscous friction [N·m·s/rad], shape (n,).
        gamma: Cube-root coefficient [N·m·(s/rad)^{1/3}], shape (n,).

    Returns:
        Friction torque [N·m], shape (N, n).
    """
    return coulomb_viscous_friction(qd, fc, fv) + gamma * np.cbrt(qd)


def rotor_inertia_torque(qdd: Array, rotor_inertia: Array) -> Array:
    """Rotor inertia torque of eq. 16, M_j·q̈ (M_j = R²·J_motor, joint side).

    Args:
        qdd: Joint accelerations [rad/s²], shape (N, n).
        rotor_inertia: M_j [kg·m²], shape (n,).

    Returns:
        Torque [N·m], shape (N, n).
    """
    return rotor_inertia * qdd
