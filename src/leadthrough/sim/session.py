"""A guiding session on the simulated robot: simulator + scripted operator, driving the loop that
a real robot runs (:func:`~leadthrough.session.loop_config.build_loop`,
:func:`~leadthrough.session.loop.run_session`).

The parameters come from calibration (a params file), never from the simulator's truth: the
simulated robot is a different, richer plant than the identified model.

The scripted operator holds an enabling device wired to digital input :data:`ENABLE_INPUT` of
the simulated controller: by default pressed once the loop is ready (the estimator's warm-up and
tare, ``warm_up_s + tare_s`` after the first sample) and held to the end; the loop starts guiding
on that fresh press, as it would on a real robot. The script's marks are presses of a "mark
point" button on input :data:`MARK_INPUT` (:data:`MARK_PRESS_S` long): the loop takes them live,
as ``P1``, ``P2``, ...
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.data.recording import is_sim_seed
from leadthrough.drivers.protocol import Driver
from leadthrough.drivers.replay import FeedbackTrace, RecordingDriver, ReplayDriver
from leadthrough.errors import ControlError, DataError, check_fields
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import LoopResult, run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, LoopParts, build_loop
from leadthrough.session.metrics import SessionSummary, summarize
from leadthrough.session.requests import LoopRequests
from leadthrough.session_format import SessionLog
from leadthrough.sim.driver import InjectedFault, InputScript, SimDriver
from leadthrough.sim.operator import ScriptedOperator
from leadthrough.sim.operator_scripts import make_operator
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.robot import SimConfig, SimRobot

__all__ = ["DEFAULT_SIM_SEED", "ENABLE_INPUT", "MARK_INPUT", "PUSH_MASS_KG", "SimSession",
           "SimSessionConfig", "light_guiding", "replay_session", "run_sim_session",
           "sim_robot_seed"]

#: The simulated controller's digital input wired to the enabling device.
ENABLE_INPUT = 0
#: The simulated controller's digital input wired to the "mark point" button.
MARK_INPUT = 1
#: How long the scripted operator presses the mark button [s].
MARK_PRESS_S = 0.1

#: Virtual mass [kg] of the push demonstrations: 40 N for 3 s then reaches the 0.2 m/s cap
#: ((40 − 15) N / 100 kg = 0.25 m/s²). With Table IV's 1000 kg it reaches 0.075 m/s.
PUSH_MASS_KG = 100.0

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SimSessionConfig:
    """A simulated guiding session.

    Attributes:
        operator: Operator script name (``rest``, ``push-x``, ``diagonal``, ``random``,
            ``seam``).
        duration_s: Session length [s]; None: the script's own length; inf: until
            ``LoopRequests.stop`` (a session run with ``requests``).
        seed: Simulated robot instance (its true parameters): the one the params were
            identified on, or the force estimate is made with another robot's model.
        run: Recording number on that robot (independent sensor noise).
        operator_seed: Seed of the operator's random pushes (``random``); None: ``seed``.
            Vary this, not ``seed``, for other push sequences on the same robot.
        q0: Start pose [rad], shape (n,); None: :func:`guide_start_pose`.
        loop: The loop's settings: the estimator's and the controller's (the law:
            ``loop.guiding.controller``).
        paced: Run in real time instead of as fast as possible.
        faults: Feedback faults injected by the simulated driver (safety tests).
        enable_held_s: When the operator holds the enabling device: ``(t_press, t_release)``
            intervals of sample time [s] (``t_release`` may be inf); None: pressed when the
            loop is ready (``loop.estimator.warm_up_s + tare_s``) and held to the end; ``()``:
            never pressed (the loop then never guides).
        plant: Simulated plant (:mod:`leadthrough.sim.plant`): the one the params were
            identified on.
        warm_up_s: Production-like motion the (realistic) robot did before the session [s]:
            its friction has fallen from the cold robot's (:mod:`leadthrough.sim.thermal`).
    """

    operator: str = "push-x"
    duration_s: float | None = None
    seed: int = 1
    run: int = 500
    operator_seed: int | None = None
    q0: tuple[float, ...] | None = None
    loop: LoopConfig = field(default_factory=LoopConfig)
    paced: bool = False
    faults: tuple[InjectedFault, ...] = ()
    enable_held_s: tuple[tuple[float, float], ...] | None = None
    plant: PlantPreset = PlantPreset.REALISTIC
    warm_up_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "plant", plant_preset(self.plant, "session.plant"))
        if self.enable_held_s is not None:
            InputScript(ENABLE_INPUT, self.enable_held_s)       # checks the intervals
        check_fields("session", self, [
            ("duration_s", self.duration_s is None or 0 < self.duration_s <= 3600
             or self.duration_s == math.inf, "0 < duration <= 3600 s, or inf"),
            ("seed", is_sim_seed(self.seed), "an integer >= 0"),
            ("operator_seed", self.operator_seed is None
             or (isinstance(self.operator_seed, int) and self.operator_seed >= 0),
             "None or an integer >= 0"),
            ("warm_up_s", bool(np.isfinite(self.warm_up_s)) and self.warm_up_s >= 0.0,
             "a finite duration >= 0 s"),
            ("warm_up_s", self.warm_up_s == 0.0 or self.plant is PlantPreset.REALISTIC,
             "0 on the ideal plant (it has no thermal model)"),
        ], ControlError)


@dataclass(frozen=True)
class SimSession:
    """A finished simulated session.

    Attributes:
        result: The recording and compute times.
        summary: Speeds, accelerations, rest drift, faults, cycle times.
        p1_base: The operator's target P1 [m] (``seam`` only), shape (3,), or None.
        p2_base: The operator's target P2 [m] (``seam`` only), shape (3,), or None.
        feedback: Every read of the driver (with ``record_feedback``), else None.
    """

    result: LoopResult
    summary: SessionSummary
    p1_base: Array | None = None
    p2_base: Array | None = None
    feedback: FeedbackTrace | None = None

    @property
    def log(self) -> SessionLog:
        """The recording (a simulated session keeps it in memory)."""
        if self.result.log is None:
            raise ControlError("the session was recorded to a file", field="result.log",
                               expected="a session recorded in memory")
        return self.result.log


def light_guiding(mass_kg: float = PUSH_MASS_KG, base: GuidingConfig | None = None
                  ) -> GuidingConfig:
    """Guiding settings with a lighter translational virtual mass (rotations keep Table IV's).

    Args:
        mass_kg: M of x, y and z [kg].
        base: Settings to modify (default: all defaults).

    Raises:
        ControlError: A mass that is not finite and positive.
    """
    cfg = base if base is not None else GuidingConfig()
    vf = cfg.virtual_friction
    return replace(cfg, virtual_friction=replace(vf, mass=(mass_kg,) * 3 + tuple(vf.mass[3:])))


#: The simulated robot instance when nothing says which (the demo's).
DEFAULT_SIM_SEED = 1


def sim_robot_seed(requested: int | None, params: ParamsFile) -> int:
    """The simulated robot instance a session runs on: the one the parameters were identified
    on (``ParamsFile.sim_seed``), else the requested one, else :data:`DEFAULT_SIM_SEED`.

    Guiding another instance than the identified one runs the estimator with another robot's
    model (up to 20 N·m of rigid-body error on the er20), which looks like a controller fault.

    Args:
        requested: The instance asked for (``--seed``), or None.
        params: The parameters.

    Raises:
        DataError: ``requested`` differs from the parameters' instance.
    """
    if params.sim_seed is None:
        return DEFAULT_SIM_SEED if requested is None else requested
    if requested is not None and requested != params.sim_seed:
        raise DataError("the params were identified on another simulated robot",
                        source=params.path, field="--seed", value=requested,
                        expected=f"{params.sim_seed} (their [meta] sim_seed), or leave it out")
    return params.sim_seed


def run_sim_session(robot: Robot, params: ParamsFile, config: SimSessionConfig,
                    record_feedback: bool = False,
                    wrap_driver: Callable[[Driver], Driver] | None = None, *,
                    requests: LoopRequests | None = None,
                    inspect_loop: Callable[[LoopParts], None] | None = None) -> SimSession:
    """Run one guiding session on the simulated robot.

    Args:
        robot: The robot (the simulator plays it with seed-drawn "true" parameters).
        params: Identified parameters (from calibration) for the estimator and eq. 36.
        config: Session settings.
        record_feedback: Keep every read of the driver in ``SimSession.feedback`` (for
            :func:`replay_session`).
        wrap_driver: Wraps the driver the loop talks to (e.g. to probe every servo period).
        requests: Requests into the loop from other threads (a stop, a fault reset).
        inspect_loop: Called with the loop's estimator, controller and interpolator once they
            are built, before the session starts (to read their state as it runs, e.g.
            ``benchmarks/force_error_budget.py``); it must not change them.

    Returns:
        The session and its summary.

    Raises:
        ControlError, SimulationError: Invalid settings (before anything runs).
    """
    q0, operator, duration = _scene(robot, config)
    op_seed = config.seed if config.operator_seed is None else config.operator_seed
    sim = SimRobot(robot, SimConfig(seed=config.seed, run=config.run, plant=config.plant,
                                    warm_up_s=config.warm_up_s), q0=q0, operator=operator)
    sim_driver = SimDriver(sim)
    for fault in config.faults:
        sim_driver.inject(fault)
    sim_driver.script_input(InputScript(ENABLE_INPUT, _enable_held(config)))
    sim_driver.script_input(InputScript(MARK_INPUT, tuple((m.t, m.t + MARK_PRESS_S)
                                                          for m in operator.marks)))
    if record_feedback and not math.isfinite(duration):
        raise ControlError("cannot keep the feedback of a session without an end",
                           field="record_feedback", value=True,
                           expected="False, or a finite duration_s")
    recorder = None
    if record_feedback:     # the reads of the session and of its stop after the duration
        reads = round((duration + LoopOptions().stop_timeout_s) / sim_driver.dt) + 1
        recorder = RecordingDriver(sim_driver, reads)
    driver: Driver = sim_driver if recorder is None else recorder
    if wrap_driver is not None:
        driver = wrap_driver(driver)
    parts = build_loop(robot, params, config.loop, driver.dt)
    if inspect_loop is not None:
        inspect_loop(parts)
    est_cfg, guiding = parts.estimator.config, parts.controller.config
    settings: dict[str, object] = {
        "operator": config.operator, "controller": guiding.controller, "seed": config.seed,
        "plant": str(config.plant), "warm_up_s": config.warm_up_s, "run": config.run,
        "operator_seed": op_seed, "duration_s": duration,
        "params_method": params.method,
        "estimator": {"method": est_cfg.method, "axes": est_cfg.axes,
                      "output_cutoff_hz": est_cfg.output_cutoff_hz, "tare_s": est_cfg.tare_s},
        "friction_mode": guiding.friction_mode,
    }
    result = run_session(driver, parts.estimator, parts.controller, parts.interpolator,
                         duration if math.isfinite(duration) else None,
                         options=_options(config), requests=requests,
                         applied_wrench=lambda: sim.applied_wrench, settings=settings)
    p1 = getattr(operator, "p1_base", None)
    p2 = getattr(operator, "p2_base", None)
    return SimSession(result=result, summary=summarize(result, guiding.dt,
                                                       guiding.limits.max_linear_acceleration),
                      p1_base=None if p1 is None else np.asarray(p1, dtype=float),
                      p2_base=None if p2 is None else np.asarray(p2, dtype=float),
                      feedback=None if recorder is None else recorder.trace())


def replay_session(robot: Robot, params: ParamsFile, config: SimSessionConfig,
                   feedback: FeedbackTrace,
                   wrap_driver: Callable[[Driver], Driver] | None = None) -> LoopResult:
    """Run a session's loop again on its recorded feedback, without the simulator.

    With the settings and parameters of the recording, the loop computes exactly what it
    computed then (see :mod:`leadthrough.drivers.replay`); its cycle times are those of the
    loop alone.

    Args:
        robot: The robot.
        params: Identified parameters of the recorded session.
        config: Settings of the recorded session.
        feedback: ``SimSession.feedback`` of a session run with ``record_feedback=True``.
        wrap_driver: Wraps the replay driver (e.g. to probe every servo period).

    Raises:
        ControlError, DataError: Invalid settings or trace.
    """
    replay = ReplayDriver(feedback)
    driver: Driver = replay if wrap_driver is None else wrap_driver(replay)
    parts = build_loop(robot, params, config.loop, driver.dt)
    return run_session(driver, parts.estimator, parts.controller, parts.interpolator,
                       _scene(robot, config)[2], options=_options(config))


def _scene(robot: Robot, config: SimSessionConfig) -> tuple[Array, ScriptedOperator, float]:
    """The start pose, the scripted operator and the session's length [s]."""
    q0 = guide_start_pose(robot) if config.q0 is None else np.asarray(config.q0, dtype=float)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q0)
    tcp0 = data.oMf[robot.tcp_frame_id].translation.copy()
    op_seed = config.seed if config.operator_seed is None else config.operator_seed
    operator = make_operator(config.operator, seed=op_seed, tcp_start_base=tcp0)
    duration = operator.duration_s if config.duration_s is None else config.duration_s
    return q0, operator, duration


def _options(config: SimSessionConfig) -> LoopOptions:
    """The loop's options of a simulated session: the enabling device on its input."""
    return LoopOptions(enable_input=ENABLE_INPUT, mark_input=MARK_INPUT, paced=config.paced)


def _enable_held(config: SimSessionConfig) -> tuple[tuple[float, float], ...]:
    """When the scripted operator holds the enabling device (see ``enable_held_s``)."""
    if config.enable_held_s is not None:
        return config.enable_held_s
    est = config.loop.estimator
    return ((est.warm_up_s + est.tare_s, math.inf),)
