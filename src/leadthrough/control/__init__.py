"""Force-following control for hand guiding (paper Section III-B, eq. 31–36), the algorithms only.

* :mod:`~leadthrough.control.virtual_friction`: virtual mass and friction per Cartesian axis
  (eq. 31–33) with the stopping friction, Table IV defaults;
* :mod:`~leadthrough.control.release`: a hand letting go at rest (the stopping friction while
  the drives settle);
* :mod:`~leadthrough.control.hand_release`: a hand letting go of the moving tool: a stop at the
  acceleration limit whatever the force estimate says, guiding again on a fresh grip;
* :mod:`~leadthrough.control.auto_friction`: friction from the identified noise (eq. 36);
* :mod:`~leadthrough.control.velocity_baseline`: the closed-loop velocity baseline [14] (Fig. 4);
* :mod:`~leadthrough.control.limits`: Cartesian speed and acceleration limits, stops;
* :mod:`~leadthrough.control.se3`: pose integration, log6, frames;
* :mod:`~leadthrough.control.ik` and :mod:`~leadthrough.control.ik_step`: damped-least-squares
  differential IK with joint limits;
* :mod:`~leadthrough.control.interpolation`: 10 ms → 1 ms cubic Hermite joint commands;
* :mod:`~leadthrough.control.jerk_limit`: optional jerk-limited interpolation (``ruckig``, not a
  dependency: imported only when used);
* :mod:`~leadthrough.control.safety` (with :mod:`~leadthrough.control.safety_states` and
  :mod:`~leadthrough.control.safety_rules`): states, faults, transition log;
* :mod:`~leadthrough.control.guiding`: :class:`GuidingController`, all of the above in one
  ``update(inp, out) -> GuidingStatus`` per 10 ms cycle (its settings, input and output types
  in :mod:`~leadthrough.control.guiding_types`, its record in
  :mod:`~leadthrough.control.guiding_state`, its compiled cycle in
  :mod:`~leadthrough.control.guiding_cycle`).

Twists and wrenches are 6-vectors, linear first (Pinocchio's order, :data:`AXIS_NAMES`).
"""

from leadthrough.control import ik_step, se3
from leadthrough.control.auto_friction import AutoFriction, AutoFrictionConfig
from leadthrough.control.guiding import GuidingController
from leadthrough.control.guiding_types import (
    AXIS_NAMES,
    CONTROLLERS,
    GuidingConfig,
    GuidingInput,
    GuidingOutput,
    GuidingStatus,
)
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.control.ik import DifferentialIK, IKConfig, IKResult
from leadthrough.control.interpolation import (
    CommandBuffer,
    HermiteInterpolator,
    InterpolatedCommand,
    InterpolatorStatus,
    JointInterpolator,
)
from leadthrough.control.jerk_limit import JerkLimitConfig, JerkLimitedInterpolator
from leadthrough.control.limits import CartesianLimits
from leadthrough.control.safety import Event, SafetyConfig, SafetySupervisor
from leadthrough.control.safety_states import Cause, Fault, State
from leadthrough.control.velocity_baseline import VelocityBaselineConfig
from leadthrough.control.virtual_friction import VirtualFrictionConfig

__all__ = [
    "AXIS_NAMES",
    "CONTROLLERS",
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
    "GuidingStatus",
    "HandReleaseConfig",
    "HermiteInterpolator",
    "IKConfig",
    "IKResult",
    "InterpolatedCommand",
    "InterpolatorStatus",
    "JerkLimitConfig",
    "JerkLimitedInterpolator",
    "JointInterpolator",
    "SafetyConfig",
    "SafetySupervisor",
    "State",
    "VelocityBaselineConfig",
    "VirtualFrictionConfig",
    "ik_step",
    "se3",
]
