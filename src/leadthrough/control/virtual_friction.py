"""Virtual mass and virtual friction, the paper's force-following law (eq. 31–33).

Per Cartesian axis i (linear first, :data:`leadthrough.control.guiding_types.AXIS_NAMES`) the
TCP behaves like a mass M_i on a surface with dry friction:

* eq. 31: M_i·v̇_i = F̂_i − f_i, with F̂_i the estimated operator force (torque) and v_i the
  commanded velocity;
* eq. 32: while moving, friction opposes the velocity: f_i = δ_i·sgn(v_i);
* eq. 33: at rest, static friction holds up to δ_i: f_i = F̂_i if |F̂_i| < δ_i (no motion starts),
  f_i = δ_i·sgn(F̂_i) otherwise (motion starts with (|F̂_i| − δ_i)/M_i);
* stopping friction: once the force is removed, i.e. |F̂_i| < δ_i while moving, the larger
  δ_s,i replaces δ_i in eq. 32, so the robot comes to rest after a release in
  ≈ M_i·|v_i|/δ_s,i instead of coasting.

Discretised with one explicit Euler step per controller cycle: v⁺ = v + dt·(F̂ − f)/M. A moving
axis whose velocity would change sign lands exactly on 0 (friction stops motion, it never
reverses it); the next cycle applies eq. 33. At rest with |F̂_i| < δ_i the update is
v⁺ = 0 + dt·(F̂_i − F̂_i)/M_i, which is exactly 0.0 in floating point: estimator noise below the
friction produces no motion at all, the paper's claim.

Defaults are the paper's Table IV: 1000 kg and 1000 kg·m², δ = 15 N and 15 N·m,
δ_s = 50 N and 50 N·m. The speed and acceleration limits of Table IV are in
:class:`leadthrough.control.limits.CartesianLimits`; the automatic friction of eq. 36 in
:mod:`leadthrough.control.auto_friction`. :func:`virtual_friction` is the law (compiled: Numba,
``nopython``, cached on disk) that the guiding cycle runs
(:mod:`leadthrough.control.guiding_cycle`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import ControlError, check_fields

__all__ = ["VirtualFrictionConfig", "virtual_friction"]

Array = NDArray[np.float64]


def _six(values: tuple[float, ...], positive: bool) -> bool:
    if len(values) != 6:
        return False
    return all(math.isfinite(v) and (v > 0 if positive else v >= 0) for v in values)


@dataclass(frozen=True)
class VirtualFrictionConfig:
    """Virtual mass and friction per axis (x, y, z, ωx, ωy, ωz), validated once.

    Attributes:
        mass: M_i [kg, kg, kg, kg·m², kg·m², kg·m²], 6 values > 0.
        friction: δ_i while guiding [N, N, N, N·m, N·m, N·m], 6 values ≥ 0 (used when the
            friction is fixed; eq. 36 replaces it when automatic).
        stopping_friction: δ_s,i once the force is removed [N, N·m], 6 values ≥ ``friction``.
    """

    mass: tuple[float, ...] = (1000.0,) * 6
    friction: tuple[float, ...] = (15.0,) * 6
    stopping_friction: tuple[float, ...] = (50.0,) * 6

    def __post_init__(self) -> None:
        check_fields("virtual_friction", self, [
            ("mass", _six(self.mass, True), "6 finite values > 0 [kg, kg·m²]"),
            ("friction", _six(self.friction, False), "6 finite values >= 0 [N, N·m]"),
            ("stopping_friction",
             _six(self.stopping_friction, False)
             and all(s >= f for s, f in zip(self.stopping_friction, self.friction, strict=True)),
             "6 finite values >= friction [N, N·m]"),
        ], ControlError)

    def dt_over_mass(self, dt: float) -> Array:
        """dt/M_i per axis for a cycle of ``dt`` [s] [s/kg, s/(kg·m²)], shape (6,)."""
        return dt / np.asarray(self.mass, dtype=float)


@njit(cache=True, nogil=True)
def virtual_friction(twist: Array, wrench: Array, friction: Array, stopping_friction: Array,
                     dt_over_mass: Array, out: Array) -> None:
    """Eq. 31–33 with the stopping friction, one Euler step per axis: the desired twist after
    one cycle (see the module docstring).

    Args:
        twist: Twist of the last cycle, shape (6,).
        wrench: Estimated wrench, shape (6,).
        friction: δ, shape (6,).
        stopping_friction: δ_s, shape (6,).
        dt_over_mass: dt/M per axis [s/kg, s/(kg·m²)], shape (6,).
        out: Desired twist, shape (6,); must not alias an input.
    """
    for i in range(6):
        v, w, d = twist[i], wrench[i], friction[i]
        if v == 0.0:
            f = min(max(w, -d), d)            # eq. 33: static friction up to δ
        else:
            mag = stopping_friction[i] if abs(w) < d else d
            f = mag if v > 0.0 else -mag      # eq. 32
        new = (w - f) * dt_over_mass[i] + v   # eq. 31
        out[i] = 0.0 if new * v < 0.0 else new
