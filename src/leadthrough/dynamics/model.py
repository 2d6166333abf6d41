"""The full identification model of eq. 21 (without the noise term).

    R·τ_total = K(q, q̇, q̈)·φ + τ_f(q̇, τ_load) + M_j·q̈

The left side is what the drive delivers at the joint, R·Kt·i. ``model_torque`` evaluates the
right side for any of the three friction models (paper eq. 15, baselines [7] and [22]).

Beyond eq. 21, the Coulomb level of each model may depend on the load,
f_c0 + f_cL·|τ_load| (:func:`leadthrough.dynamics.friction.coulomb_level`, Bittencourt et al.
2010). Offline, τ_load is the link torque K·φ of the identified links at the state: the torque
the gear passes to the link when no external force acts (what calibration records). It excludes
the rotor inertia M_j·q̈, which the motor spends before the gear. ``load_friction`` zero (the
default, and every params file without the field) is eq. 21 exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import (
    StribeckParameters,
    cbrt_friction,
    coulomb_level,
    coulomb_viscous_friction,
    rotor_inertia_torque,
    stribeck_friction,
)
from leadthrough.dynamics.regressor import link_torque, standard_parameters
from leadthrough.errors import DataError
from leadthrough.robot.description import Robot

__all__ = ["MAX_COMMAND_LAG_S", "MAX_LOAD_FRICTION", "MAX_PRESLIDING_RAD",
           "MAX_PRESLIDING_RELAXATION",
           "DriveModelParameters", "FrictionModel", "model_torque", "model_torque_from_links",
           "nominal_drive_parameters"]

Array = NDArray[np.float64]

#: Largest presliding length z₀ accepted anywhere [rad] (gear presliding is ≲ 1e-3)
MAX_PRESLIDING_RAD = 0.1

#: Largest relaxation rate of the friction carried at rest accepted anywhere [1/s] (a time
#: constant of 0.1 s: faster than that, the friction would not outlast a guiding cycle's stop).
MAX_PRESLIDING_RELAXATION = 10.0

#: Largest command-to-position lag accepted anywhere [s]: a controller interface's transport
#: and servo delay is a few of its 1-8 ms cycles.
MAX_COMMAND_LAG_S = 0.1

#: Largest load-dependent Coulomb coefficient f_cL accepted anywhere [-] (exclusive): a gear whose
#: friction grew by as much as the torque it transmits would lock; published values are a few
#: percent (Bittencourt et al. 2010), and the estimator's load estimate needs f_cL < 1.
MAX_LOAD_FRICTION = 1.0


class FrictionModel(StrEnum):
    """Which friction law the drive parameters follow."""

    STRIBECK = "stribeck"          # paper eq. 15
    COULOMB_VISCOUS = "coulomb-viscous"  # ref. [7], eq. 5
    CBRT = "cbrt"                  # ref. [22], eq. 8


@dataclass(frozen=True)
class DriveModelParameters:
    """All parameters of eq. 21.

    Attributes:
        phi: Standard link parameters, shape (10·n,) (see :mod:`leadthrough.dynamics.regressor`).
        friction_model: Which friction law applies.
        stribeck: Eq. 15 parameters (used when ``friction_model`` is STRIBECK).
        coulomb: Coulomb friction Fc [N·m], shape (n,) (baselines).
        viscous: Viscous friction β [N·m·s/rad], shape (n,) (baselines).
        cbrt: Cube-root coefficient γ, shape (n,) (baseline [22]).
        rotor_inertia: Joint-side rotor inertia M_j [kg·m²], shape (n,).
        offset: Constant joint-torque offset τ_0 [N·m], shape (n,), or empty for none. Not in
            eq. 21; the ``consistent`` method identifies it (current-sensor offsets).
        presliding: Presliding length z₀ of each drive's Coulomb + Stribeck friction [rad],
            shape (n,), or empty if not identified. Not in eq. 21 (eq. 15 is its steady state):
            the displacement over which the friction of a joint at rest turns over
            (:mod:`leadthrough.identification.presliding`); the estimator's friction at rest
            uses it.
        presliding_relaxation: Rate at which the friction carried at rest relaxes toward zero
            [1/s], shape (n,), or empty for none (only with ``presliding``): the servo's
            dither of a joint held still wears its friction state down, by a motion far below
            one encoder count (:mod:`leadthrough.identification.presliding`). 0 <= rate <=
            :data:`MAX_PRESLIDING_RELAXATION`.
        load_friction: f_cL per joint [-], shape (n,), or empty for none (zeros): the Coulomb
            level is f_c0 + f_cL·|τ_load| (f_c0 is ``stribeck.f1`` or ``coulomb``). Not in
            eq. 21 (see the module docstring). 0 <= f_cL < :data:`MAX_LOAD_FRICTION`.
        command_lag: How long a joint command takes to show in the measured position [s]
            (the controller interface's transport and the servo's delay), measured on the
            identification recording (:mod:`leadthrough.identification.command_lag`); 0 where
            the recording carried no commands. Not in eq. 21: the estimator's friction follows
            the command this much later. 0 <= lag <= :data:`MAX_COMMAND_LAG_S`.
    """

    phi: Array
    friction_model: FrictionModel
    rotor_inertia: Array
    stribeck: StribeckParameters | None = None
    coulomb: Array = field(default_factory=lambda: np.zeros(0))
    viscous: Array = field(default_factory=lambda: np.zeros(0))
    cbrt: Array = field(default_factory=lambda: np.zeros(0))
    offset: Array = field(default_factory=lambda: np.zeros(0))
    presliding: Array = field(default_factory=lambda: np.zeros(0))
    presliding_relaxation: Array = field(default_factory=lambda: np.zeros(0))
    load_friction: Array = field(default_factory=lambda: np.zeros(0))
    command_lag: float = 0.0

    def __post_init__(self) -> None:
        if self.friction_model is FrictionModel.STRIBECK and self.stribeck is None:
            raise DataError("Stribeck friction model without Stribeck parameters",
                            field="stribeck", expected="StribeckParameters")
        z0 = np.asarray(self.presliding, dtype=float)
        n = np.size(self.rotor_inertia)
        if z0.size and (z0.shape != (n,)
                        or not np.all((z0 > 0) & (z0 <= MAX_PRESLIDING_RAD))):
            raise DataError("presliding lengths out of range", field="presliding",
                            value=z0.tolist(),
                            expected=f"{n} values in (0, {MAX_PRESLIDING_RAD:g}] rad, or none")
        rr = np.asarray(self.presliding_relaxation, dtype=float)
        if rr.size and (rr.shape != (n,) or not z0.size or not np.all(
                (rr >= 0) & (rr <= MAX_PRESLIDING_RELAXATION))):
            raise DataError("presliding relaxation out of range", field="presliding_relaxation",
                            value=rr.tolist(),
                            expected=f"{n} values in [0, {MAX_PRESLIDING_RELAXATION:g}] 1/s "
                                     "with the presliding lengths, or none")
        fl = np.asarray(self.load_friction, dtype=float)
        if fl.size and (fl.shape != (n,) or not np.all((fl >= 0) & (fl < MAX_LOAD_FRICTION))):
            raise DataError("load-dependent friction out of range", field="load_friction",
                            value=fl.tolist(),
                            expected=f"{n} values in [0, {MAX_LOAD_FRICTION:g}), or none")
        if not 0.0 <= self.command_lag <= MAX_COMMAND_LAG_S:
            raise DataError("command lag out of range", field="command_lag",
                            value=self.command_lag, expected=f"0 to {MAX_COMMAND_LAG_S:g} s")

    @property
    def has_load_friction(self) -> bool:
        """Whether some joint's Coulomb level depends on the load (f_cL > 0)."""
        return bool(np.any(np.asarray(self.load_friction) > 0))

    def friction(self, qd: Array, gear_ratio: Array, load_torque: Array | None = None) -> Array:
        """Friction torque [N·m].

        Args:
            qd: Joint velocities [rad/s], shape (N, n).
            gear_ratio: R, shape (n,).
            load_torque: τ_load [N·m], shape (N, n); needed when :attr:`has_load_friction`.

        Raises:
            DataError: Load-dependent friction without ``load_torque``.
        """
        st = self.stribeck if self.friction_model is FrictionModel.STRIBECK else None
        f_c0 = st.f1 if st is not None else self.coulomb
        if self.has_load_friction:
            if load_torque is None:
                raise DataError("the friction depends on the load: the load torque is needed",
                                field="load_torque", expected="τ_load, shape (N, n)")
            f_c0 = coulomb_level(f_c0, self.load_friction, load_torque)
        if st is not None:
            return stribeck_friction(qd, gear_ratio, st, f_c0)
        if self.friction_model is FrictionModel.CBRT:
            return cbrt_friction(qd, f_c0, self.viscous, self.cbrt)
        return coulomb_viscous_friction(qd, f_c0, self.viscous)


def nominal_drive_parameters(robot: Robot) -> DriveModelParameters:
    """Nominal parameters: CAD link inertias, datasheet rotor inertia, no friction."""
    n = robot.n
    zeros = np.zeros(n)
    return DriveModelParameters(
        phi=standard_parameters(robot.model),
        friction_model=FrictionModel.COULOMB_VISCOUS,
        rotor_inertia=robot.reflected_rotor_inertia.copy(),
        coulomb=zeros.copy(),
        viscous=zeros.copy(),
    )


def model_torque(
    robot: Robot, params: DriveModelParameters, q: Array, qd: Array, qdd: Array
) -> Array:
    """Model joint torque R·τ_total = K·φ + τ_f + M_j·q̈ (eq. 21 without noise), plus τ_0.

    A load-dependent friction (``params.load_friction``) takes τ_load = K·φ, the link torque.

    Args:
        robot: The robot.
        params: Model parameters.
        q: Joint positions [rad], shape (N, n).
        qd: Joint velocities [rad/s], shape (N, n).
        qdd: Joint accelerations [rad/s²], shape (N, n).

    Returns:
        Joint torque the drives must deliver [N·m], shape (N, n); divide by R·Kt for current.
    """
    q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
    links = link_torque(robot.model, params.phi, q, qd, qdd)
    return model_torque_from_links(robot, params, links, qd, qdd)


def model_torque_from_links(
    robot: Robot, params: DriveModelParameters, links: Array, qd: Array, qdd: Array
) -> Array:
    """:func:`model_torque` given its link torque K·φ (for a caller that needs that too).

    Args:
        robot: The robot.
        params: Model parameters.
        links: Link torque K·φ of ``params.phi`` [N·m], shape (N, n).
        qd: Joint velocities [rad/s], shape (N, n).
        qdd: Joint accelerations [rad/s²], shape (N, n).

    Returns:
        Joint torque the drives must deliver [N·m], shape (N, n).
    """
    tau = (
        links
        + params.friction(qd, robot.gear_ratio, links)
        + rotor_inertia_torque(qdd, params.rotor_inertia)
    )
    if params.offset.size:
        tau += params.offset
    return tau
