"""Force-following control for hand guiding (paper Section III-B, eq. 31–36), the algorithms only.

* :mod:`~leadthrough.control.virtual_friction`: virtual mass and friction per Cartesian axis
  (eq. 31–33) with the stopping friction, Table IV defaults;
* :mod:`~leadthrough.control.auto_friction`: friction from the identified noise (eq. 36);
* :mod:`~leadthrough.control.velocity_baseline`: the closed-loop velocity baseline [14] (Fig. 4);
* :mod:`~leadthrough.control.limits`: Cartesian speed and acceleration limits, braking;
* :mod:`~leadthrough.control.ik`: damped-least-squares differential IK with joint limits;
* :mod:`~leadthrough.control.interpolation`: 10 ms → 1 ms cubic Hermite joint commands;
* :mod:`~leadthrough.control.jerk_limit`: optional jerk-limited interpolation (``ruckig``, not a
  dependency: imported only when used);
* :mod:`~leadthrough.control.safety`: states, faults, transition log;
* :mod:`~leadthrough.control.guiding`: :class:`GuidingController`, all of the above in one
  ``update(inp, out) -> Status`` per 10 ms cycle (its settings, input and output types in
  :mod:`~leadthrough.control.guiding_types`).

Twists and wrenches are 6-vectors, linear first (Pinocchio's order).
"""

from leadthrough.control.admittance import AXIS_NAMES, AdmittanceLaw
from leadthrough.control.auto_friction import AutoFriction, AutoFrictionConfig
from leadthrough.control.guiding import GuidingController
from leadthrough.control.guiding_types import (
    CONTROLLERS,
    GuidingConfig,
    GuidingInput,
    GuidingOutput,
    Status,
)
from leadthrough.control.ik import DifferentialIK, IKConfig, IKResult, dls_damping
from leadthrough.control.interpolation import (
    CommandBuffer,
    HermiteInterpolator,
    InterpolatorStatus,
    JointCommand,
    JointInterpolator,
)
from leadthrough.control.jerk_limit import JerkLimitConfig, JerkLimitedInterpolator
from leadthrough.control.limits import CartesianLimits, TwistLimiter
from leadthrough.control.safety import Cause, Event, Fault, SafetyConfig, SafetySupervisor, State
from leadthrough.control.velocity_baseline import VelocityBaseline, VelocityBaselineConfig
from leadthrough.control.virtual_friction import VirtualFriction, VirtualFrictionConfig

__all__ = [
    "AXIS_NAMES",
    "CONTROLLERS",
    "AdmittanceLaw",
    "AutoFriction",
    "AutoFrictionConfig",
    "CartesianLimits",
    "Cause",
    "CommandBuffer",
    "DifferentialIK",
    "Event",
    "Fault",
    "GuidingConfig",
    "GuidingController",
    "GuidingInput",
    "GuidingOutput",
    "HermiteInterpolator",
    "IKConfig",
    "IKResult",
    "InterpolatorStatus",
    "JerkLimitConfig",
    "JerkLimitedInterpolator",
    "JointCommand",
    "JointInterpolator",
    "SafetyConfig",
    "SafetySupervisor",
    "State",
    "Status",
    "TwistLimiter",
    "VelocityBaseline",
    "VelocityBaselineConfig",
    "VirtualFriction",
    "VirtualFrictionConfig",
    "dls_damping",
]
