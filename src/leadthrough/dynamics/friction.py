"""Drive-train friction and rotor inertia models, all joint-side [N·m].

* :func:`stribeck_friction`: the paper's model, eq. 15 (motor and gearbox friction, each Coulomb +
  Stribeck, plus viscous):

      τ_f = f1·sgn(q̇) + f2·exp(−(R·q̇/q̇sm)²)·sgn(q̇) + f3·exp(−(q̇/q̇sg)²)·sgn(q̇) + f4·q̇

  q̇sm is the motor-side Stribeck velocity (compared with the motor speed R·q̇), q̇sg the gear-side
  one (compared with the joint speed q̇).
* :func:`coulomb_viscous_friction`: baseline [7], eq. 5: Fc·sgn(q̇) + β·q̇.
* :func:`cbrt_friction`: baseline [22], eq. 8: Fc·sgn(q̇) + β·q̇ + γ·q̇^{1/3}.
* :func:`rotor_inertia_torque`: eq. 16, M_j·q̈ with M_j the reflected rotor inertia.
* :func:`coulomb_level`: the load-dependent Coulomb level f_c0 + f_cL·|τ_load| that replaces the
  Coulomb coefficient (f1 of eq. 15, Fc of eq. 5 and 8) of every model, and
  :func:`load_friction_column`, its regressor column |τ_load|·sgn(q̇) (∂τ_f/∂f_cL).

Load-dependent friction (not in the paper): gear-tooth and bearing friction grow with the torque
the gear transmits. Bittencourt, Wernholt, Sander-Tavallaey and Brogårdh ("An extended friction
model to capture load and temperature effects in robot joints", IROS 2010) measured it on an
ABB arm and added the load torque to the static friction model; Bittencourt and Axelsson
("Modeling and experiment design for identification of wear in a robot joint under load and
temperature uncertainties based on friction data", IEEE/ASME Trans. Mechatronics 19(5), 2014)
use the same load dependence. Here the Coulomb level becomes f_c0 + f_cL·|τ_load| with f_cL ≥ 0
dimensionless, τ_load the joint's transmitted (link-side) torque; f_cL = 0 is the paper's model,
bit for bit (:func:`coulomb_level` returns f_c0 itself).

Eq. 15 is defined once, here, per sample and compiled (:func:`stribeck_decay`,
:func:`stribeck_terms`, :func:`eq15_friction`: Numba, cached on disk; NumPy ufuncs that also run
inside compiled code on scalars). The offline model, the identification's regressor columns and
the real-time estimator (:mod:`leadthrough.estimation`) all call them.

All functions broadcast over samples: inputs of shape (N, n) with parameters of shape (n,).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numba import njit, vectorize
from numpy.typing import NDArray

__all__ = [
    "StribeckParameters",
    "cbrt_friction",
    "coulomb_level",
    "coulomb_viscous_friction",
    "eq15_friction",
    "friction_dtype",
    "load_friction_column",
    "rotor_inertia_torque",
    "stribeck_decay",
    "stribeck_friction",
    "stribeck_shapes",
    "stribeck_terms",
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


@cache
def friction_dtype(n: int) -> np.dtype[Any]:
    """The friction parameters of ``n`` joints as a record, for compiled per-sample code.

    Fields (per joint, shape (n,), except ``stribeck``): ``coulomb`` f1 [N·m], ``viscous``
    f4 [N·m·s/rad], ``motor_stribeck`` f2 [N·m], ``motor_rate`` R/q̇sm [s/rad],
    ``gear_stribeck`` f3 [N·m], ``gear_rate`` 1/q̇sg [s/rad], ``cbrt`` γ of [22]'s cube-root
    term [N·m·(s/rad)^{1/3}], ``load`` f_cL of the load-dependent Coulomb level [-]
    (:func:`coulomb_level`; 0: none); ``stribeck``: eq. 15 (else the baselines' Coulomb +
    viscous (+ cube root) model, with the Stribeck fields zero).
    """
    f8 = np.float64
    return np.dtype([("coulomb", f8, (n,)), ("viscous", f8, (n,)),
                     ("motor_stribeck", f8, (n,)), ("motor_rate", f8, (n,)),
                     ("gear_stribeck", f8, (n,)), ("gear_rate", f8, (n,)),
                     ("cbrt", f8, (n,)), ("load", f8, (n,)), ("stribeck", np.bool_)])


@vectorize(["float64(float64, float64, float64)"], cache=True, nopython=True)
def coulomb_level(f_c0: float, f_cl: float, load_torque: float) -> float:  # pragma: no cover
    """The load-dependent Coulomb level f_c0 + f_cL·|τ_load| [N·m] (a NumPy ufunc, also
    callable in compiled code). With f_cL = 0 it returns f_c0 itself (bit for bit, whatever
    τ_load is), so models without the load term are unchanged.

    Args:
        f_c0: Coulomb friction at no load [N·m] (f1 of eq. 15, Fc of eq. 5 and 8).
        f_cl: f_cL, extra Coulomb friction per N·m transmitted [-], >= 0.
        load_torque: τ_load, the torque the joint's gear transmits to the link [N·m].
    """
    if f_cl == 0.0:
        return f_c0
    return f_c0 + f_cl * abs(load_torque)


def load_friction_column(qd: Array, load_torque: Array) -> Array:
    """The regressor column of f_cL, |τ_load|·sgn(q̇) (what f_cL multiplies in τ_f).

    Args:
        qd: Joint velocities [rad/s], shape (N, n) (or any shape).
        load_torque: τ_load [N·m], same shape.

    Returns:
        |τ_load|·sgn(q̇) [N·m], same shape.
    """
    return np.abs(load_torque) * np.sign(qd)


@vectorize(["float64(float64)"], cache=True, nopython=True)
def stribeck_decay(ratio: float) -> float:  # pragma: no cover (compiled)
    """The Stribeck decay of eq. 15, exp(−x²), of a speed ratio x = q̇/q̇s (a NumPy ufunc)."""
    return math.exp(-ratio * ratio)


@njit(cache=True, nogil=True)
def stribeck_terms(speed: float, f2: float, motor_rate: float, f3: float,
                   gear_rate: float) -> float:
    """The Stribeck part of eq. 15's friction level at a joint speed q̇ [N·m]:
    f2·exp(−(R·q̇/q̇sm)²) + f3·exp(−(q̇/q̇sg)²).

    Args:
        speed: q̇ [rad/s].
        f2: Motor-side Stribeck amplitude [N·m].
        motor_rate: R/q̇sm [s/rad].
        f3: Gear-side Stribeck amplitude [N·m].
        gear_rate: 1/q̇sg [s/rad].
    """
    return f2 * stribeck_decay(speed * motor_rate) + f3 * stribeck_decay(speed * gear_rate)


@vectorize(["float64(float64, float64, float64, float64, float64, float64, float64, float64)"],
           cache=True, nopython=True)
def eq15_friction(qd: float, sign: float, f1: float, f2: float, motor_rate: float, f3: float,
                  gear_rate: float, f4: float) -> float:  # pragma: no cover (compiled)
    """Eq. 15 for a given friction direction [N·m] (a NumPy ufunc):
    f1·s + f4·q̇ + s·(f2·exp(−(R·q̇/q̇sm)²) + f3·exp(−(q̇/q̇sg)²)).

    Args:
        qd: q̇ [rad/s].
        sign: The friction's direction s: sgn(q̇) offline, a smoothed sign in real time.
        f1: Coulomb friction [N·m].
        f2: Motor-side Stribeck amplitude [N·m].
        motor_rate: R/q̇sm [s/rad].
        f3: Gear-side Stribeck amplitude [N·m].
        gear_rate: 1/q̇sg [s/rad].
        f4: Viscous friction [N·m·s/rad].
    """
    return sign * f1 + qd * f4 + sign * stribeck_terms(qd, f2, motor_rate, f3, gear_rate)


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
    motor = stribeck_decay(gear_ratio * qd / qd_sm) * s
    gear = stribeck_decay(qd / qd_sg) * s
    return s, motor, gear


def stribeck_friction(qd: Array, gear_ratio: Array, p: StribeckParameters,
                      coulomb: Array | None = None) -> Array:
    """Joint friction of eq. 15.

    Args:
        qd: Joint velocities [rad/s], shape (N, n) or (n,).
        gear_ratio: R, shape (n,).
        p: Friction parameters.
        coulomb: The Coulomb level to use instead of ``p.f1`` [N·m] (the load-dependent one of
            :func:`coulomb_level`), broadcastable to ``qd``; None: ``p.f1``.

    Returns:
        Friction torque [N·m], same shape as ``qd``.
    """
    f1 = p.f1 if coulomb is None else coulomb
    return np.asarray(eq15_friction(qd, np.sign(qd), f1, p.f2, gear_ratio / p.qd_sm, p.f3,
                                    1.0 / p.qd_sg, p.f4))


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
