"""A live session on the simulated robot, pushed by the pendant's mouse.

The simulated robot (:class:`~leadthrough.sim.robot.SimRobot`, instance ``seed``) starts at the
guiding pose with a :class:`~leadthrough.sim.operator.HandPush` as its operator: the only force
on the tool is the one the page applies. The loop is the one a robot runs
(:func:`~leadthrough.session.loop_config.build_loop`, :class:`~leadthrough.pendant.backend.
LiveSession`) with the given parameters: by default those shipped for the simulated er20
(:mod:`leadthrough.sim.guiding_params`), never the simulator's truth. The translational virtual
mass defaults to the push demonstrations' :data:`~leadthrough.sim.session.PUSH_MASS_KG` (a hand
feels Table IV's 1000 kg as a wall).

The simulator and the hand are built in the loop's process from a :class:`SimulatedRecipe`;
the pendant pushes through a :class:`~leadthrough.pendant.push.RemoteHand` and may inject a
feedback fault (:class:`InjectFault`, to practise clearing one).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from leadthrough.control.guiding import GuidingConfig
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.backend import LiveSession
from leadthrough.pendant.loop_process import LoopSetup
from leadthrough.pendant.messages import SimulatorRequest
from leadthrough.pendant.push import RemoteHand, apply_to_hand
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.sim.driver import InjectedFault, InjectedFaultKind, SimDriver
from leadthrough.sim.guiding_params import shipped_guiding_params
from leadthrough.sim.operator import HandPush
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.session import PUSH_MASS_KG, light_guiding, sim_robot_seed

__all__ = ["InjectFault", "SimulatedPendantSession", "SimulatedRecipe", "simulated_session"]


class SimulatedPendantSession(NamedTuple):
    """A live session on the simulator, not started.

    Attributes:
        live: The loop (start it with ``live.start()``).
        hand: What the page pushes the tool with.
        params: The parameters the loop runs with.
        params_note: Where they come from (one line).
    """

    live: LiveSession
    hand: RemoteHand
    params: ParamsFile
    params_note: str


@dataclass(frozen=True)
class InjectFault(SimulatorRequest):
    """A feedback fault of the simulated driver from ``after_s`` after the request for
    ``duration_s`` [s] (:class:`~leadthrough.sim.driver.InjectedFault`)."""

    kind: InjectedFaultKind
    after_s: float
    duration_s: float


@dataclass(frozen=True)
class SimulatedRecipe:
    """The simulated robot and its loop, as the loop's process builds them (picklable).

    Attributes:
        robot: The robot.
        params: Identified parameters.
        instance: Simulated robot instance.
        guiding: Controller settings.
    """

    robot: Robot
    params: ParamsFile
    instance: int
    guiding: GuidingConfig

    @property
    def with_truth(self) -> bool:
        """The simulator's applied wrench is recorded."""
        return True

    def build(self) -> LoopSetup:
        """The simulator with a hand, its driver and the loop's parts."""
        hand = HandPush()
        sim = SimRobot(self.robot, SimConfig(seed=self.instance, run=500),
                       q0=guide_start_pose(self.robot), operator=hand)
        driver = SimDriver(sim)
        parts = build_loop(self.robot, self.params, LoopConfig(guiding=self.guiding),
                           driver.dt)
        settings: dict[str, object] = {"operator": "pendant", "seed": self.instance,
                                       "params_method": self.params.method,
                                       "controller": parts.controller.config.controller}

        def simulator(request: object, t: float) -> str | None:
            if apply_to_hand(hand, request):
                return None
            if isinstance(request, InjectFault):
                driver.inject(InjectedFault(request.kind, t_start=t + request.after_s,
                                            t_end=t + request.after_s + request.duration_s))
                return f"simulated fault {request.kind.name} injected"
            return f"unknown simulator request {type(request).__name__}"

        return LoopSetup(driver, parts, settings, applied_wrench=lambda: sim.applied_wrench,
                         hand_force=lambda: hand.force_base, simulator=simulator)


def simulated_session(robot: Robot, params: ParamsFile | None = None, *,
                      seed: int | None = None, mass_kg: float = PUSH_MASS_KG,
                      guiding: GuidingConfig | None = None,
                      record_s: float = 600.0,
                      paced: bool = True, timing_window: int = 1000,
                      rt_priority: int | None = None) -> SimulatedPendantSession:
    """A live session on the simulated robot (its loop in a process of its own).

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
        rt_priority: Real-time priority of the loop's process (see :class:`LiveSession`).

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
    config = light_guiding(mass_kg, guiding if guiding is not None else GuidingConfig())
    recipe = SimulatedRecipe(robot, params, instance, config)
    live = LiveSession(recipe, robot, record_s=record_s, paced=paced,
                       timing_window=timing_window, rt_priority=rt_priority,
                       controller_dt=config.dt)
    return SimulatedPendantSession(live, RemoteHand(live), params, note or params.method)
