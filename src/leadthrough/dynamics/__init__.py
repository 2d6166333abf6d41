"""Dynamic model: link regressor (eq. 3), base parameters, drive friction (eq. 15, 5, 8) and the
full model torque (eq. 21)."""

from leadthrough.dynamics.base_parameters import BaseParameters, compute_base_parameters
from leadthrough.dynamics.friction import (
    StribeckParameters,
    cbrt_friction,
    coulomb_level,
    coulomb_viscous_friction,
    load_friction_column,
    rotor_inertia_torque,
    stribeck_friction,
)
from leadthrough.dynamics.model import (
    DriveModelParameters,
    FrictionModel,
    model_torque,
    nominal_drive_parameters,
)
from leadthrough.dynamics.regressor import (
    LINK_PARAMETER_NAMES,
    link_regressor,
    link_regressor_batch,
    link_torque,
    standard_parameter_names,
    standard_parameters,
)

__all__ = [
    "LINK_PARAMETER_NAMES",
    "BaseParameters",
    "DriveModelParameters",
    "FrictionModel",
    "StribeckParameters",
    "cbrt_friction",
    "compute_base_parameters",
    "coulomb_level",
    "coulomb_viscous_friction",
    "link_regressor",
    "link_regressor_batch",
    "link_torque",
    "load_friction_column",
    "model_torque",
    "nominal_drive_parameters",
    "rotor_inertia_torque",
    "standard_parameter_names",
    "standard_parameters",
    "stribeck_friction",
]
