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
from leadthrough.estimation import kernels
from leadthrough.estimation.kernels import FRICTION_ROWS
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
        self.rotor = np.asarray(params.rotor_inertia, dtype=float)
        self.offset = params.offset if params.offset.size else np.zeros(n)
        fm = params.friction_model
        st = params.stribeck
        self.stribeck = fm is FrictionModel.STRIBECK and st is not None
        fp = np.zeros((FRICTION_ROWS, n))
        fp[0] = 1.0 / standstill_velocity
        if st is not None and self.stribeck:
            fp[1], fp[2], fp[4], fp[6] = st.f1, st.f4, st.f2, st.f3
            fp[3] = robot.gear_ratio / st.qd_sm
            fp[5] = 1.0 / st.qd_sg
        else:
            fp[1] = params.coulomb if params.coulomb.size else 0.0
            fp[2] = params.viscous if params.viscous.size else 0.0
            fp[7] = params.cbrt if params.cbrt.size else 0.0
        self.friction_rows = fp
        self.friction = np.zeros(n)
        self.sign = np.zeros(n)

    def friction_torque(self, qd: Array) -> Array:
        """Friction τ_f(q̇) with the smoothed sign [N·m]; returns an internal buffer."""
        kernels.smooth_sign(qd, self.friction_rows, self.sign)
        kernels.friction_torque(qd, self.sign, self.friction_rows, self.stribeck, self.friction)
        return self.friction

    def torque(self, q: Array, qd: Array, qdd: Array, out: Array) -> None:
        """τ̂_d into ``out`` [N·m] (eq. 21 right side, smoothed friction sign)."""
        out[:] = pin.rnea(self.model, self.data, q, qd, qdd)
        out += self.friction_torque(qd)
        out += self.rotor * qdd
        out += self.offset
