"""The computing side of a guiding loop, built from its configuration: the external force
estimator, the guiding controller and the interpolator, for any driver.

    parts = build_loop(robot, params, LoopConfig(), driver.dt)
    run_session(driver, *parts, duration_s=...)

The parameters come from calibration (a params file); nothing here knows whether the driver is
a real controller or the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

from leadthrough.control.guiding import GuidingConfig, GuidingController
from leadthrough.control.interpolation import HermiteInterpolator
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot.description import Robot

__all__ = ["LoopConfig", "LoopParts", "build_loop"]


def _guiding_estimator() -> EstimatorConfig:
    return EstimatorConfig(axes="force", tare_s=0.5, friction_velocity="command",
                           friction_weighting=1.0)


@dataclass(frozen=True)
class LoopConfig:
    """Settings of a guiding loop.

    Attributes:
        estimator: Estimator settings; its ``dt`` and ``frame`` are set by :func:`build_loop`
            (the driver's period, the base frame). The default guides: a pure force at the TCP
            (a hand on a handle), tared at the start, the friction following the commanded
            velocity (see ``EstimatorConfig.friction_velocity``) and the force fit weighing the
            joints by their friction's uncertainty (``friction_weighting``).
        guiding: Controller settings (the law: ``guiding.controller``).
    """

    estimator: EstimatorConfig = field(default_factory=_guiding_estimator)
    guiding: GuidingConfig = field(default_factory=GuidingConfig)


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
