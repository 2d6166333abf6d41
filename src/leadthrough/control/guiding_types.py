"""Settings, input, output and status of the guiding controller (see
:mod:`leadthrough.control.guiding`).

The input and the output are records (:mod:`leadthrough.state_records`) that the compiled cycle
reads and writes by field: their arrays are attributes to fill or read in place.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import IntEnum
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.auto_friction import AutoFrictionConfig
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.control.ik import IKConfig
from leadthrough.control.limits import CartesianLimits
from leadthrough.control.operator_limits import OperatorLimits
from leadthrough.control.safety import SafetyConfig
from leadthrough.control.safety_states import Fault, State
from leadthrough.control.velocity_baseline import VelocityBaselineConfig
from leadthrough.control.virtual_friction import VirtualFrictionConfig
from leadthrough.errors import ControlError, check_fields
from leadthrough.state_records import RecordView
from leadthrough.state_records import field as record_field

__all__ = [
    "AXIS_NAMES",
    "CONTROLLERS",
    "GuidingConfig",
    "GuidingInput",
    "GuidingOutput",
    "GuidingStatus",
    "adjusted_config",
]

Array = NDArray[np.float64]

#: Names of the force-following laws.
CONTROLLERS: tuple[str, ...] = ("virtual-friction", "velocity")

#: Cartesian axis names in twist / wrench order: Pinocchio's, linear first (the paper lists
#: them angular first): x, y, z (force [N], velocity [m/s], mass [kg]), then ωx, ωy, ωz
#: (torque [N·m], angular velocity [rad/s], inertia [kg·m²]).
AXIS_NAMES: tuple[str, ...] = ("x", "y", "z", "rx", "ry", "rz")


class GuidingStatus(IntEnum):
    """Result of one update."""

    #: Normal cycle (IDLE, GUIDING or STOPPING).
    OK = 0
    #: A fault is latched (decelerating or holding); see ``GuidingOutput.fault``.
    FAULT = -1


@dataclass(frozen=True)
class GuidingConfig:
    """All settings of the guiding controller, validated once.

    Attributes:
        dt: Controller cycle [s].
        frame: ``"base"`` (base axes at the TCP) or ``"tool"`` (tool axes): the frame of the
            per-axis law, masses, friction and ``axes_enabled``.
        controller: ``"virtual-friction"`` (the paper, eq. 31–33) or ``"velocity"`` ([14]).
        axes_enabled: Per axis (x, y, z, ωx, ωy, ωz) of ``frame``: whether the operator can move
            it; e.g. ``(True,) * 3 + (False,) * 3`` for translation only.
        friction_mode: ``"fixed"`` (``virtual_friction.friction`` and ``stopping_friction``) or
            ``"auto"`` (eq. 36 from the identified noise, per pose).
        virtual_friction: Masses and fixed friction (Table IV).
        velocity_baseline: Gains of [14].
        auto_friction: Settings of eq. 36.
        limits: Cartesian speed and acceleration limits (Table IV).
        ik: Differential IK settings.
        safety: Safety thresholds.
        operator_limits: Bounds of what an operator may change at the robot (virtual mass
            and friction; :meth:`GuidingController.adjust
            <leadthrough.control.guiding.GuidingController.adjust>` clamps to them).
        settle_s: After the commanded motion stops, the drives settle (servo lag, the friction
            they keep): for ``settle_s + rezero_s`` the rest threshold of eq. 33 is the
            stopping friction instead of the guiding friction [s]. After a stop the gears'
            friction relaxes from its sliding level over about a second as the servo's integral
            unwinds, and no model of the currents can tell that from a push; on the simulated
            er20 a restart below the stopping friction within 1 s of a stop can be a phantom.
            The same window follows a release at rest (a hand letting go of the tool: the gears
            unload and the estimate swings the other way, by up to twice the released force).
        rezero_s: Then the guiding loop re-zeroes the estimator over this window (a
            zero-velocity update, see ``ExternalForceEstimator.rezero``); 0 disables [s].
        drift_s: At rest the force estimate drifts as the servo's integral loads the gears'
            static friction; a change of the estimate on an axis by its δ over ``drift_s`` or
            more slowly is taken for that drift, not a hand, and the rest threshold of eq. 33
            counts from it (:mod:`leadthrough.control.rest_drift`) [s]; 0: nothing is
            followed while guiding (the paper's law at rest, but the estimate's level at a
            press of the enabling device is still no push). Default 2.5 s, δ/drift_s =
            6 N/s with δ = 15 N: above the drift measured on the simulated er20's tuning
            instances 1-2 with the friction's relaxation at rest (2.4-5.7 N/s over 1 s after
            a release; 8.9-12.4 N/s without it, when the default was 1.5 s), below a hand's
            grip (δ within the estimator's 3 Hz filter and a 0.1 s onset, ~60 N/s). Params
            without a presliding test's relaxation drift faster than this follows.
        hand_release: The stop after the hand lets go of the moving tool
            (:mod:`leadthrough.control.hand_release`; virtual friction only: the velocity
            baseline [14] runs as published).
    """

    dt: float = 0.01
    frame: str = "base"
    controller: str = "virtual-friction"
    axes_enabled: tuple[bool, ...] = (True,) * 6
    friction_mode: str = "fixed"
    virtual_friction: VirtualFrictionConfig = field(default_factory=VirtualFrictionConfig)
    velocity_baseline: VelocityBaselineConfig = field(default_factory=VelocityBaselineConfig)
    auto_friction: AutoFrictionConfig = field(default_factory=AutoFrictionConfig)
    limits: CartesianLimits = field(default_factory=CartesianLimits)
    ik: IKConfig = field(default_factory=IKConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    operator_limits: OperatorLimits = field(default_factory=OperatorLimits)
    settle_s: float = 1.5
    rezero_s: float = 0.0
    drift_s: float = 2.5
    hand_release: HandReleaseConfig = field(default_factory=HandReleaseConfig)

    def __post_init__(self) -> None:
        check_fields("guiding", self, [
            ("dt", math.isfinite(self.dt) and 0 < self.dt <= 0.1, "0 < dt <= 0.1 s"),
            ("frame", self.frame in ("base", "tool"), "'base' or 'tool'"),
            ("controller", self.controller in CONTROLLERS, " or ".join(map(repr, CONTROLLERS))),
            ("axes_enabled", len(self.axes_enabled) == 6
             and all(isinstance(a, bool) for a in self.axes_enabled), "6 booleans"),
            ("friction_mode", self.friction_mode in ("fixed", "auto"), "'fixed' or 'auto'"),
            ("settle_s", math.isfinite(self.settle_s) and 0 <= self.settle_s <= 10,
             "0 <= settle_s <= 10 s"),
            ("rezero_s", math.isfinite(self.rezero_s) and 0 <= self.rezero_s <= 10,
             "0 <= rezero_s <= 10 s"),
            ("drift_s", math.isfinite(self.drift_s) and 0 <= self.drift_s <= 60,
             "0 <= drift_s <= 60 s (0: off)"),
        ], ControlError)
        if self.safety.joint_limit_margin <= self.ik.joint_limit_margin:
            raise ControlError("must exceed the IK's margin", field="safety.joint_limit_margin",
                               value=self.safety.joint_limit_margin,
                               expected=f"> ik.joint_limit_margin = {self.ik.joint_limit_margin}")



def adjusted_config(config: GuidingConfig, commissioned: GuidingConfig, *,
                    frame: str | None = None, axes_enabled: Sequence[bool] | None = None,
                    mass: tuple[float, float] | None = None,
                    friction: tuple[float, float] | None = None) -> GuidingConfig:
    """The controller's settings with an operator's change, mass and friction clamped to
    ``config.operator_limits``.

    Args:
        config: The settings in force.
        commissioned: The settings the controller was built with: the stopping friction δ_s
            stays theirs, raised to δ if the operator's δ exceeds it.
        frame: ``"base"`` or ``"tool"``; None: unchanged.
        axes_enabled: 6 booleans (x, y, z, ωx, ωy, ωz); None: unchanged.
        mass: (translational [kg], rotational [kg·m²]) virtual mass; None: unchanged.
        friction: (translational [N], rotational [N·m]) virtual friction δ; None: unchanged.

    Raises:
        ControlError: An unknown frame, not 6 booleans, a mass with the velocity law, a
            friction with the automatic friction (eq. 36 sets it), or a value that is not a
            finite number.
    """
    vf = config.virtual_friction
    changes: dict[str, object] = {}
    if frame is not None:
        changes["frame"] = frame
    if axes_enabled is not None:
        axes = tuple(axes_enabled)
        if len(axes) != 6 or not all(isinstance(a, bool) for a in axes):
            raise ControlError("not 6 booleans", field="axes_enabled", value=axes,
                               expected="6 booleans (x, y, z, ωx, ωy, ωz)")
        changes["axes_enabled"] = axes
    if mass is not None:
        if config.controller != "virtual-friction":
            raise ControlError("the velocity law has no virtual mass", field="mass",
                               value=mass, expected="the 'virtual-friction' controller")
        m, inertia = config.operator_limits.clamp_mass(*mass)
        vf = replace(vf, mass=(m,) * 3 + (inertia,) * 3)
    if friction is not None:
        if config.friction_mode != "fixed":
            raise ControlError("the friction is automatic (eq. 36)", field="friction",
                               value=friction, expected="friction_mode 'fixed'")
        f, t = config.operator_limits.clamp_friction(*friction)
        delta = (f,) * 3 + (t,) * 3
        stop = tuple(max(s, d) for s, d in zip(commissioned.virtual_friction.stopping_friction,
                                               delta, strict=True))
        vf = replace(vf, friction=delta, stopping_friction=stop)
    return replace(config, virtual_friction=vf, **changes)  # type: ignore[arg-type]


@cache
def input_dtype(n: int) -> np.dtype[Any]:
    """The record of :class:`GuidingInput` for ``n`` joints."""
    f8 = np.float64
    return np.dtype([("t", f8), ("sequence", np.int64), ("deadman", np.bool_),
                     ("estimator_status", np.int64), ("q", f8, (n,)), ("current", f8, (n,)),
                     ("wrench_base", f8, (6,))])


@cache
def output_dtype(n: int) -> np.dtype[Any]:
    """The record of :class:`GuidingOutput` for ``n`` joints."""
    f8, i8 = np.float64, np.int64
    return np.dtype([("q", f8, (n,)), ("qd", f8, (n,)), ("transform_tool_to_base", f8, (4, 4)),
                     ("twist_base", f8, (6,)), ("twist_tool", f8, (6,)), ("wrench", f8, (6,)),
                     ("friction", f8, (6,)), ("stopping_friction", f8, (6,)), ("state", i8),
                     ("fault", i8), ("status", i8), ("manipulability", f8),
                     ("speed_scale", f8), ("ik_scale", f8), ("ik_residual", f8),
                     ("rest_s", f8)])


class GuidingInput(RecordView):
    """One controller cycle's input (``GuidingController.make_input``; fill the arrays in
    place, set the scalars).

    Args:
        n: Number of joints.
    """

    __slots__ = ()

    t = record_field("t", "Time [s] (only logged; the controller never reads the clock).",
                     float)
    sequence = record_field("sequence", "Feedback sequence number; must advance every cycle.",
                            int)
    deadman = record_field("deadman", "Enabling input held.", bool)
    estimator_status = record_field(
        "estimator_status", "The estimator's status of the last sample "
        "(:class:`~leadthrough.estimation.estimator.EstimatorStatus`); a negative value (a "
        "latched fault: it ran every servo period, and may have seen a bad sample the "
        "controller did not) trips ``Fault.ESTIMATOR``.", int)
    q = record_field[Array]("q", "Measured joint positions [rad], shape (n,).")
    current = record_field[Array]("current", "Measured motor currents [A], shape (n,).")
    wrench_base = record_field[Array](
        "wrench_base", "Estimated operator wrench at the TCP in base axes (the estimator's "
        "``frame=\"base\"``), force first [N, N·m], shape (6,). With ``frame=\"tool\"`` it is "
        "rotated into tool axes with the commanded TCP orientation (which the measured one "
        "follows within the following-error limit).")

    def __init__(self, n: int) -> None:
        super().__init__(input_dtype(n))


class GuidingOutput(RecordView):
    """One controller cycle's result, filled by ``update`` (``GuidingController.make_output``).

    Args:
        n: Number of joints.
    """

    __slots__ = ()

    q = record_field[Array]("q", "Joint position setpoint for the end of the cycle [rad], "
                                 "shape (n,).")
    qd = record_field[Array]("qd", "Joint velocity over the cycle [rad/s], shape (n,) (exactly "
                                   "0.0 at rest).")
    transform_tool_to_base = record_field[Array](
        "transform_tool_to_base", "Commanded TCP pose, homogeneous, shape (4, 4) [m].")
    twist_base = record_field[Array](
        "twist_base", "Commanded TCP twist in base axes at the TCP, linear first [m/s, rad/s], "
        "shape (6,).")
    twist_tool = record_field[Array]("twist_tool", "The same twist in tool axes, shape (6,).")
    wrench = record_field[Array](
        "wrench", "Wrench fed to the law, in the controller's frame, disabled axes zeroed "
        "[N, N·m], shape (6,); NaN while the input is not finite.")
    friction = record_field[Array]("friction", "Virtual friction δ in use [N, N·m], shape (6,).")
    stopping_friction = record_field[Array](
        "stopping_friction", "Stopping friction δ_s in use [N, N·m], shape (6,).")
    state = record_field("state", "Safety state.", State)
    fault = record_field("fault", "Latched fault (``Fault.NONE`` unless ``state`` is FAULT).",
                         Fault)
    status = record_field("status", "Result of the update.", GuidingStatus)
    manipulability = record_field("manipulability", "μ = √det(J Jᵀ) at the commanded joint "
                                                    "position.", float)
    speed_scale = record_field("speed_scale", "Factor applied to the speed limits (singularity "
                                              "slow-down).", float)
    ik_scale = record_field("ik_scale", "Fraction of the IK step kept by the joint bounds (1: "
                                        "none active).", float)
    ik_residual = record_field("ik_residual", "‖log6(T(q_cmd)⁻¹·T_cmd)‖ left by the last IK "
                                              "step [m, rad].", float)
    rest_s = record_field("rest_s", "Time the commanded motion has been at rest since it last "
                                    "moved [s] (0 while moving; infinite before the first "
                                    "motion).", float)

    def __init__(self, n: int) -> None:
        super().__init__(output_dtype(n))
        self.transform_tool_to_base[3, 3] = 1.0
        self.rest_s = math.inf
        self.speed_scale = self.ik_scale = 1.0
