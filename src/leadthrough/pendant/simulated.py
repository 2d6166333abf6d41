"""A live session on the simulated robot, pushed by the pendant's mouse.

The simulated robot (:class:`~leadthrough.sim.robot.SimRobot`, instance ``seed``) starts at the
guiding pose with a :class:`~leadthrough.sim.operator.HandPush` as its operator: the only force
on the tool is the one the page applies. The loop is the one a robot runs
(:func:`~leadthrough.session.loop_config.build_loop`, :class:`~leadthrough.pendant.backend.
LiveSession`) with the given parameters: by default those shipped for the simulated er20
(:mod:`leadthrough.sim.guiding_params`), never the simulator's truth. The translational virtual
mass defaults to the push demonstrations' :data:`~leadthrough.sim.session.PUSH_MASS_KG` (a hand
feels Table IV's 1000 kg as a wall).
"""

from __future__ import annotations

from typing import NamedTuple

from leadthrough.control.guiding import GuidingConfig
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.backend import LiveSession
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.guiding_params import shipped_guiding_params
from leadthrough.sim.operator import HandPush
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.session import PUSH_MASS_KG, light_guiding, sim_robot_seed

__all__ = ["SimulatedPendantSession", "simulated_session"]


class SimulatedPendantSession(NamedTuple):
    """A live session on the simulator, not started.

    Attributes:
        live: The loop (start it with ``live.start()``).
        hand: What the page pushes the tool with.
        params: The parameters the loop runs with.
        params_note: Where they come from (one line).
    """

    live: LiveSession
    hand: HandPush
    params: ParamsFile
    params_note: str


def simulated_session(robot: Robot, params: ParamsFile | None = None, *,
                      seed: int | None = None, mass_kg: float = PUSH_MASS_KG,
                      guiding: GuidingConfig | None = None,
                      record_s: float = 600.0,
                      paced: bool = True, timing_window: int = 1000,
                      rt_priority: int | None = None) -> SimulatedPendantSession:
    """A live session on the simulated robot.

    Args:
        robot: The robot.
        params: Identified parameters; None: the shipped ones of the simulated er20.
        seed: Simulated robot instance (default: the parameters' own, see
            :func:`~leadthrough.sim.session.sim_robot_seed`).
        mass_kg: Translational virtual mass [kg] (clamped to the operator limits later on).
        guiding: Controller settings (default: Table IV's with ``mass_kg``).
        record_s: Length of the recording kept for the export [s].
        paced: Run in real time (False: as fast as the machine allows, for tests).
        timing_window: Servo periods whose timing the session keeps.
        rt_priority: Real-time priority of the loop's thread (see :class:`LiveSession`).

    Raises:
        DataError: No shipped parameters for this robot, or a ``seed`` other than the
            parameters'.
        ControlError, SimulationError: Invalid settings.
    """
    note = f"{params.path} ({params.method})" if params is not None and params.path else ""
    if params is None:
        params = shipped_guiding_params(robot)
        note = (f"shipped identification of the simulated {robot.name} "
                f"({params.method} with the friction sweep)")
    instance = sim_robot_seed(seed, params)
    hand = HandPush()
    sim = SimRobot(robot, SimConfig(seed=instance, run=500), q0=guide_start_pose(robot),
                   operator=hand)
    driver = SimDriver(sim)
    base = guiding if guiding is not None else GuidingConfig()
    parts = build_loop(robot, params, LoopConfig(guiding=light_guiding(mass_kg, base)),
                       driver.dt)
    settings: dict[str, object] = {"operator": "pendant", "seed": instance,
                                   "params_method": params.method,
                                   "controller": parts.controller.config.controller}
    live = LiveSession(driver, parts, robot, record_s=record_s,
                       applied_wrench=lambda: sim.applied_wrench, settings=settings,
                       paced=paced, timing_window=timing_window, rt_priority=rt_priority)
    return SimulatedPendantSession(live, hand, params, note or params.method)
