"""The computing side of a guiding loop, built from its configuration: the external force
estimator, the guiding controller and the interpolator, for any driver.

    parts = build_loop(robot, params, LoopConfig(), driver.dt)
    run_session(driver, *parts, duration_s=..., options=LoopOptions(enable_input=0))

The parameters come from calibration (a params file); nothing here knows whether the driver is
a real controller or the simulator. :class:`LoopOptions` say how the loop meets the driver and
the operator: which digital input is the enabling device, pacing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig, GuidingController
from leadthrough.control.interpolation import HermiteInterpolator
from leadthrough.errors import ControlError, check_fields
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot.description import Robot
from leadthrough.session.realtime import RealtimeRequest

__all__ = ["MAX_INPUT_BIT", "SLOW_COMMAND_VELOCITY", "LoopConfig", "LoopOptions", "LoopParts",
           "build_loop"]

#: The guiding estimator's ``slow_command_velocity`` [rad/s]: chosen on the simulated er20's
#: tuning instances 1-2 (0.005 and 0.01 rad/s both helped, 0.0025 less so), not from the plant.
SLOW_COMMAND_VELOCITY = 0.01

#: Highest digital input bit a driver can report (a 64-bit field).
MAX_INPUT_BIT = 63

Array = NDArray[np.float64]


def _guiding_estimator() -> EstimatorConfig:
    return EstimatorConfig(axes="force", tare_s=0.5, friction_velocity="command",
                           friction_weighting=1.0, slow_command_velocity=SLOW_COMMAND_VELOCITY)


@dataclass(frozen=True)
class LoopConfig:
    """Settings of a guiding loop.

    Attributes:
        estimator: Estimator settings; its ``dt`` and ``frame`` are set by :func:`build_loop`
            (the driver's period, the base frame). The default guides: a pure force at the TCP
            (a hand on a handle), tared at the start, the friction following the commanded
            velocity (see ``EstimatorConfig.friction_velocity``), or the encoder where a joint
            creeps and the params carry a presliding test (``slow_command_velocity``), and the
            force fit weighing the joints by their friction's uncertainty
            (``friction_weighting``).
        guiding: Controller settings (the law: ``guiding.controller``).
    """

    estimator: EstimatorConfig = field(default_factory=_guiding_estimator)
    guiding: GuidingConfig = field(default_factory=GuidingConfig)


def _bit_or_none(bit: int | None) -> bool:
    return bit is None or (isinstance(bit, int) and 0 <= bit <= MAX_INPUT_BIT)


@dataclass(frozen=True)
class LoopOptions:
    """How the loop meets the driver and the operator.

    Attributes:
        enable_input: The digital input (bit of ``DriverFeedback.inputs``) wired to
            the enabling device; None: no enabling input from the driver. Guiding starts only
            on a fresh press of it (:class:`~leadthrough.session.operator_inputs.EnablingDevice`);
            with no enabling input at all, the loop never guides.
        mark_input: The digital input wired to the "mark point" button; None: no marks.
        reset_input: The digital input wired to the fault reset button; None: resets come
            only from ``LoopRequests.reset_fault``. A fresh press (debounced as the mark
            button) is a reset request: accepted with a fault latched, its cause cleared
            (the controller reporting OK, the feedback finite and within the following-error
            limit) and the commanded motion at rest; guiding then needs a fresh press of the
            enabling device
            (:meth:`ServoLoop.reset_fault <leadthrough.session.servo_loop.ServoLoop.reset_fault>`).
        paced: Pace a simulated driver to the wall clock (real time) instead of running flat
            out; a real driver paces the loop itself.
        watchdog_s: A driver exchange (write, step, read) longer than this is a fault, and one
            that blocks is aborted (:mod:`~leadthrough.session.watchdog`) [s]; real drivers
            only (a simulation's wall time means nothing). More than two periods.
        abort_s: A driver exchange blocked longer than this is aborted and the link taken as
            gone: the loop ends without commanding (the controller's own watchdog stops the
            robot) [s]; at least ``watchdog_s``.
        stop_timeout_s: A stop (requested, or the end of ``duration_s``) that has not brought
            the commanded motion to rest after this long ends the loop anyway [s].
        realtime: The real-time set-up of the loop's process (SCHED_FIFO priority, memory
            locked, CPUs), applied as the loop starts; each step the OS refuses is noted and
            the loop runs without it (:mod:`~leadthrough.session.realtime`). Default: none.
    """

    enable_input: int | None = None
    mark_input: int | None = None
    reset_input: int | None = None
    paced: bool = False
    watchdog_s: float = 0.05
    abort_s: float = 1.0
    stop_timeout_s: float = 10.0
    realtime: RealtimeRequest = field(default_factory=RealtimeRequest)

    def __post_init__(self) -> None:
        bits = f"None or an input bit 0..{MAX_INPUT_BIT}"
        check_fields("loop", self, [
            ("enable_input", _bit_or_none(self.enable_input), bits),
            ("mark_input", _bit_or_none(self.mark_input)
             and (self.mark_input is None or self.mark_input != self.enable_input),
             bits + ", not the enabling input"),
            ("reset_input", _bit_or_none(self.reset_input)
             and (self.reset_input is None
                  or self.reset_input not in (self.enable_input, self.mark_input)),
             bits + ", not the enabling or the mark input"),
            ("watchdog_s", math.isfinite(self.watchdog_s) and self.watchdog_s > 0, "> 0 s"),
            ("abort_s", math.isfinite(self.abort_s) and self.abort_s >= self.watchdog_s,
             ">= watchdog_s"),
            ("stop_timeout_s", math.isfinite(self.stop_timeout_s) and self.stop_timeout_s > 0,
             "> 0 s"),
        ], ControlError)


#: The paper's controller cycle [s] (Table IV: 10 ms).
PAPER_CYCLE_S = 0.01


def controller_cycle(servo_dt: float) -> float:
    """The guiding controller's cycle on a controller of period ``servo_dt`` [s]: the multiple
    of it nearest the paper's 10 ms (8 ms on J519 at 8 ms, 8 ms on RSI at 4 ms, 10 ms on an
    e-Series UR at 2 ms)."""
    return max(1, round(PAPER_CYCLE_S / servo_dt)) * servo_dt


class LoopParts(NamedTuple):
    """The computing side of a session's loop, built from its settings.

    Attributes:
        estimator: External force estimator (base frame, at the servo period).
        controller: Guiding controller.
        interpolator: Controller cycle → servo period interpolation.
    """

    estimator: ExternalForceEstimator
    controller: GuidingController
    interpolator: HermiteInterpolator


def build_loop(robot: Robot, params: ParamsFile, config: LoopConfig, dt: float) -> LoopParts:
    """Estimator, controller and interpolator of a loop, fresh (nothing run yet).

    Args:
        robot: The robot.
        params: Identified parameters.
        config: Loop settings.
        dt: Servo period of the driver [s].

    Raises:
        ControlError, DataError: Invalid settings.
    """
    est_cfg = replace(config.estimator, dt=dt, frame="base")
    estimator = ExternalForceEstimator(robot, params.params, params.noise_mean, est_cfg,
                                       noise_std=params.noise_std)
    guiding = config.guiding
    controller = GuidingController(robot, guiding, params.noise_mean, params.noise_std)
    interpolator = HermiteInterpolator(robot.n, guiding.dt, round(guiding.dt / dt))
    return LoopParts(estimator, controller, interpolator)


def warm_up_parts(parts: LoopParts, q0: Array,
                  progress: Callable[[int], None] | None = None) -> None:
    """Load (or compile, on a first run) each part's compiled code on copies of its state, at
    the pose ``q0`` [rad], shape (n,): built before a real controller's stream opens, the
    loop's first cycle then runs at full speed. ``progress`` is called with 1, 2, 3 as each
    part is done."""
    parts.estimator.reset(q0)
    parts.estimator.warm_up()
    if progress is not None:
        progress(1)
    parts.controller.reset(q0, 0.0)
    parts.controller.warm_up()
    if progress is not None:
        progress(2)
    parts.interpolator.reset(q0)
    parts.interpolator.warm_up()
    if progress is not None:
        progress(3)
