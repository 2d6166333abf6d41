"""Virtual mass and virtual friction, the paper's force-following law (eq. 31–33).

Per Cartesian axis i (see :mod:`leadthrough.control.admittance` for the axis order) the TCP
behaves like a mass M_i on a surface with dry friction:

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
:mod:`leadthrough.control.auto_friction`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import kernels
from leadthrough.control.guiding_kernel import LAW_VIRTUAL_FRICTION
from leadthrough.errors import ControlError, check_fields, check_period

__all__ = ["VirtualFriction", "VirtualFrictionConfig"]

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


class VirtualFriction:
    """The virtual mass / virtual friction law (eq. 31–33); an :class:`AdmittanceLaw`.

    Args:
        config: Masses (the friction values of the config are defaults for the caller; ``step``
            takes the friction explicitly so that eq. 36 can set it per cycle).
        dt: Controller cycle [s].

    Raises:
        ControlError: ``dt`` not finite and positive.
    """

    def __init__(self, config: VirtualFrictionConfig | None = None, dt: float = 0.01) -> None:
        check_period("dt", dt, ControlError)
        self.config = cfg = config if config is not None else VirtualFrictionConfig()
        self.dt = dt
        self.law_id = LAW_VIRTUAL_FRICTION
        #: dt/M_i per axis [s/kg, s/(kg·m²)].
        self.coefficients = dt / np.asarray(cfg.mass, dtype=float)
        self.alpha = 0.0

    def step(self, twist: Array, wrench: Array, friction: Array, stopping_friction: Array,
             out: Array) -> None:
        """Desired twist after one cycle (eq. 31–33, with the stopping friction).

        Args:
            twist: Commanded twist of the last cycle, shape (6,) [m/s, rad/s].
            wrench: Estimated operator wrench F̂, shape (6,) [N, N·m].
            friction: δ, shape (6,) [N, N·m], ≥ 0.
            stopping_friction: δ_s, shape (6,) [N, N·m], ≥ δ.
            out: Desired twist, shape (6,), written in place; must not alias an input.
        """
        kernels.virtual_friction_step(twist, wrench, friction, stopping_friction,
                                      self.coefficients, out)
