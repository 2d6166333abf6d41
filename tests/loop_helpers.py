"""A guiding loop on the simulated er20 for tests of the loop's logic: its parts built as a
session builds them, on a clock the test owns (:class:`~leadthrough.session.pacing.
VirtualClock`)."""

from __future__ import annotations

from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.session.pacing import Clock, VirtualClock
from leadthrough.session.requests import RequestSource
from leadthrough.session.servo_loop import ServoLoop, Simulator
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.session import light_guiding


def bare_loop(robot: Robot, params: ParamsFile, *, clock: Clock | None = None,
              options: LoopOptions | None = None, requests: RequestSource | None = None,
              simulator: Simulator | None = None, seed: int = 1) -> ServoLoop:
    """A :class:`ServoLoop` on the simulated ``robot`` (instance ``seed``), not started."""
    driver = SimDriver(SimRobot(robot, SimConfig(seed=seed), q0=guide_start_pose(robot)))
    parts = build_loop(robot, params, LoopConfig(guiding=light_guiding()), driver.dt)
    every = round(parts.controller.config.dt / driver.dt)
    return ServoLoop(driver, parts.estimator, parts.controller, parts.interpolator, every,
                     options if options is not None else LoopOptions(), requests, None,
                     simulator, clock if clock is not None else VirtualClock())
