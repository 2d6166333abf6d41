"""Settings, input, output and status of the guiding controller (see
:mod:`leadthrough.control.guiding`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.auto_friction import AutoFrictionConfig
from leadthrough.control.cycle_kernel import output_size, output_views
from leadthrough.control.ik import IKConfig
from leadthrough.control.limits import CartesianLimits
from leadthrough.control.safety import Fault, SafetyConfig, State
from leadthrough.control.velocity_baseline import VelocityBaselineConfig
from leadthrough.control.virtual_friction import VirtualFrictionConfig
from leadthrough.errors import ControlError, check_fields

__all__ = [
    "CONTROLLERS",
    "GuidingConfig",
    "GuidingInput",
    "GuidingOutput",
    "Status",
]

Array = NDArray[np.float64]

#: Names of the force-following laws.
CONTROLLERS: tuple[str, ...] = ("virtual-friction", "velocity")


class Status(IntEnum):
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
    settle_s: float = 1.5
    rezero_s: float = 0.0

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
        ], ControlError)
        if self.safety.joint_limit_margin <= self.ik.joint_limit_margin:
            raise ControlError("must exceed the IK's margin", field="safety.joint_limit_margin",
                               value=self.safety.joint_limit_margin,
                               expected=f"> ik.joint_limit_margin = {self.ik.joint_limit_margin}")


@dataclass
class GuidingInput:
    """One controller cycle's input (write into the arrays in place).

    Attributes:
        t: Time [s] (only logged; the controller never reads the clock).
        sequence: Feedback sequence number; must advance every cycle.
        q: Measured joint positions [rad], shape (n,).
        current: Measured motor currents [A], shape (n,).
        wrench_base: Estimated operator wrench at the TCP in base axes (the estimator's
            ``frame="base"``), force first [N, N·m], shape (6,). With ``frame="tool"`` it is
            rotated into tool axes with the commanded TCP orientation (which the measured one
            follows within the following-error limit).
        deadman: Enabling input held.
        estimator_status: The estimator's status of the last sample
            (:class:`~leadthrough.estimation.estimator.Status`); a negative value (a latched
            fault: it ran every servo period, and may have seen a bad sample the controller did
            not) trips ``Fault.ESTIMATOR``.
    """

    t: float
    sequence: int
    q: Array
    current: Array
    wrench_base: Array
    deadman: bool = False
    estimator_status: int = 0


@dataclass
class GuidingOutput:
    """One controller cycle's result, filled by ``update``.

    Built from one buffer (``GuidingController.make_output`` allocates it), which ``update``
    fills in one compiled call: the arrays are views of it, written in place (read or copy
    them; never rebind them).

    Args:
        buffer: The output's storage, shape (46 + 2·n,) for n joints
            (``cycle_kernel.output_size``).

    Attributes:
        q: Joint position setpoint for the end of the cycle [rad], shape (n,).
        qd: Joint velocity over the cycle [rad/s], shape (n,) (exactly 0.0 at rest).
        transform_tool_to_base: Commanded TCP pose, homogeneous, shape (4, 4) [m].
        twist_base: Commanded TCP twist in base axes at the TCP, linear first [m/s, rad/s],
            shape (6,).
        twist_tool: The same twist in tool axes, shape (6,).
        wrench: Wrench fed to the law, in the controller's frame, disabled axes zeroed
            [N, N·m], shape (6,); NaN while the input is not finite.
        friction: Virtual friction δ in use [N, N·m], shape (6,).
        stopping_friction: Stopping friction δ_s in use [N, N·m], shape (6,).
        state: Safety state.
        fault: Latched fault (``Fault.NONE`` unless ``state`` is FAULT).
        status: Result of the update.
        manipulability: μ = √det(J Jᵀ) at the commanded joint position.
        speed_scale: Factor applied to the speed limits (singularity slow-down).
        ik_scale: Fraction of the IK step kept by the joint bounds (1: none active).
        ik_residual: ‖log6(T(q_cmd)⁻¹·T_cmd)‖ left by the last IK step [m, rad].
        rest_s: Time the commanded motion has been at rest since it last moved [s] (0 while
            moving; infinite before the first motion).
    """

    buffer: Array
    q: Array = field(init=False)
    qd: Array = field(init=False)
    transform_tool_to_base: Array = field(init=False)
    twist_base: Array = field(init=False)
    twist_tool: Array = field(init=False)
    wrench: Array = field(init=False)
    friction: Array = field(init=False)
    stopping_friction: Array = field(init=False)
    state: State = State.IDLE
    fault: Fault = Fault.NONE
    status: Status = Status.OK
    manipulability: float = 0.0
    speed_scale: float = 1.0
    ik_scale: float = 1.0
    ik_residual: float = 0.0
    rest_s: float = math.inf

    def __post_init__(self) -> None:
        b = self.buffer
        n = (b.size - output_size(0)) // 2 if isinstance(b, np.ndarray) else -1
        if (not isinstance(b, np.ndarray) or b.dtype != np.float64 or b.ndim != 1
                or not b.flags.c_contiguous or n < 1 or b.size != output_size(n)):
            raise ControlError("not an output buffer", field="buffer",
                               value=getattr(b, "shape", type(b).__name__),
                               expected="a contiguous float64 vector of 46 + 2·n values "
                                        "(GuidingController.make_output)")
        self.transform_tool_to_base, six, self.q, self.qd = output_views(b, n)
        self.twist_base, self.twist_tool, self.wrench = six[0], six[1], six[2]
        self.friction, self.stopping_friction = six[3], six[4]
        self.transform_tool_to_base[3, 3] = 1.0
