"""The identified model in real-time form: Pinocchio model with identified inertias plus the
drive terms, evaluated one sample at a time with preallocated buffers.

τ̂_d(q, q̇, q̈) = RNEA_φ̂(q, q̇, q̈) + M_j·q̈ + τ_f(q̇) + τ_0        (right side of eq. 21)

At standstill the sign of a noisy velocity estimate is meaningless, so friction uses a smoothed
sign, sat(q̇ / v_ε), with v_ε the calibration's standstill threshold: below it the friction term
fades linearly to zero.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.dynamics.regressor import parameters_to_inertias
from leadthrough.robot.description import Robot

__all__ = ["IdentifiedModel"]

Array = NDArray[np.float64]


class IdentifiedModel:
    """Real-time evaluation of the identified model.

    Args:
        robot: The robot.
        params: Identified parameters (any friction model).
        standstill_velocity: v_ε of the smoothed sign [rad/s].
    """

    def __init__(self, robot: Robot, params: DriveModelParameters,
                 standstill_velocity: float = 0.02) -> None:
        self.robot = robot
        self.params = params
        self.model = robot.model.copy()
        for j, inertia in enumerate(parameters_to_inertias(params.phi), start=1):
            self.model.inertias[j] = inertia
        self.data = self.model.createData()
        n = robot.n
        self._inv_eps = 1.0 / standstill_velocity
        self._rotor = np.asarray(params.rotor_inertia, dtype=float)
        self._offset = params.offset if params.offset.size else np.zeros(n)
        fm = params.friction_model
        self._stribeck = fm is FrictionModel.STRIBECK and params.stribeck is not None
        if self._stribeck:
            st = params.stribeck
            assert st is not None
            self._c1, self._c2, self._c3, self._visc = st.f1, st.f2, st.f3, st.f4
            self._am = robot.gear_ratio / st.qd_sm
            self._ag = 1.0 / st.qd_sg
        else:
            self._c1, self._visc = params.coulomb, params.viscous
            self._cbrt = params.cbrt if params.cbrt.size else np.zeros(n)
        self.friction = np.zeros(n)
        self.offset = self._offset
        self._s = np.zeros(n)
        self._t = np.zeros(n)

    def friction_torque(self, qd: Array) -> Array:
        """Friction τ_f(q̇) with the smoothed sign [N·m]; internal buffer."""
        s, t, f = self._s, self._t, self.friction
        np.multiply(qd, self._inv_eps, out=s)
        np.clip(s, -1.0, 1.0, out=s)
        np.multiply(s, self._c1, out=f)
        np.multiply(qd, self._visc, out=t)
        f += t
        if self._stribeck:
            # motor-side and gear-side Stribeck terms: c·exp(−(a·q̇)²)·sgn
            for a, c in ((self._am, self._c2), (self._ag, self._c3)):
                np.multiply(qd, a, out=t)
                np.square(t, out=t)
                np.negative(t, out=t)
                np.exp(t, out=t)
                t *= c
                t *= s
                f += t
        else:
            np.cbrt(qd, out=t)
            t *= self._cbrt
            f += t
        return f

    def torque(self, q: Array, qd: Array, qdd: Array, out: Array) -> None:
        """τ̂_d into ``out`` [N·m] (eq. 21 right side, smoothed friction sign)."""
        out[:] = pin.rnea(self.model, self.data, q, qd, qdd)
        out += self.friction_torque(qd)
        np.multiply(qdd, self._rotor, out=self._t)
        out += self._t
        out += self._offset
