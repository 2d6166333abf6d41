"""The identified model in real-time form: Pinocchio model with the identified inertias plus the
drive terms, for the estimator's per-sample evaluation.

τ̂_d(q, q̇, q̈) = RNEA_φ̂(q, q̇, q̈) + M_j·q̈ + τ_f(q̇, τ_load) + τ_0        (right side of eq. 21)

The estimator (:mod:`leadthrough.estimation.estimator_step`) evaluates it every sample: RNEA on
:attr:`IdentifiedModel.model`, the friction from :attr:`IdentifiedModel.friction` (eq. 15, or
the baselines' Coulomb + viscous (+ cube root) model), rotor inertia and offset.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import friction_dtype
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.dynamics.regressor import parameters_to_inertias
from leadthrough.robot.description import Robot
from leadthrough.state_records import new_record, view

__all__ = ["IdentifiedModel"]

Array = NDArray[np.float64]


class IdentifiedModel:
    """The identified model's parts for real-time evaluation.

    Args:
        robot: The robot.
        params: Identified parameters (any friction model).

    Attributes:
        model: Pinocchio model with the identified link inertias.
        data: Its data.
        rotor: Rotor inertias M_j [kg·m²], shape (n,).
        offset: Torque offsets τ_0 [N·m], shape (n,) (zeros if none were identified).
        friction: The friction parameters (a record of
            :func:`~leadthrough.dynamics.friction.friction_dtype`, one element).
    """

    def __init__(self, robot: Robot, params: DriveModelParameters) -> None:
        self.robot = robot
        self.params = params
        self.model = robot.model.copy()
        for j, inertia in enumerate(parameters_to_inertias(params.phi), start=1):
            self.model.inertias[j] = inertia
        self.data = self.model.createData()
        n = robot.n
        self.rotor = np.asarray(params.rotor_inertia, dtype=float)
        self.offset = params.offset if params.offset.size else np.zeros(n)
        self.friction = new_record(friction_dtype(n))
        fp = view(self.friction)
        fp.load = params.load_friction if params.load_friction.size else 0.0
        st = params.stribeck
        fp.stribeck = params.friction_model is FrictionModel.STRIBECK and st is not None
        if st is not None and fp.stribeck:
            fp.coulomb, fp.viscous = st.f1, st.f4
            fp.motor_stribeck, fp.gear_stribeck = st.f2, st.f3
            fp.motor_rate = robot.gear_ratio / st.qd_sm
            fp.gear_rate = 1.0 / st.qd_sg
        else:
            fp.coulomb = params.coulomb if params.coulomb.size else 0.0
            fp.viscous = params.viscous if params.viscous.size else 0.0
            fp.cbrt = params.cbrt if params.cbrt.size else 0.0
