"""Record a calibration data set on the simulated robot: an optimised excitation trajectory for
identification and a different one held out for validation, with the true currents alongside
(for the noise floor)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.excitation.design import ExcitationConfig, ExcitationResult, design_excitation
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.friction_sweep import FrictionSweepConfig, design_friction_sweep
from leadthrough.excitation.presliding import PreslidingTestConfig, design_presliding_test
from leadthrough.identification.api import IdentifyConfig
from leadthrough.identification.comparison import MethodComparison, compare_methods, noise_floor
from leadthrough.identification.metrics import ResidualStats
from leadthrough.robot.description import Robot
from leadthrough.sim.mujoco_model import Payload
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.run import SimLog, run_trajectory

Array = NDArray[np.float64]

__all__ = [
    "CalibrationComparison",
    "CalibrationSet",
    "SimRecording",
    "compare_on_calibration_set",
    "record_calibration_set",
    "record_excitation",
    "record_friction_sweep",
    "record_presliding_test",
]


@dataclass(frozen=True)
class SimRecording:
    """A simulated recording and its noise-free twin.

    Attributes:
        measured: What the controller logs (encoder q, measured current).
        true: The same samples with the true (noise-free) motor currents.
        log: The full simulator log (truth included).
    """

    measured: Recording
    true: Recording
    log: SimLog


@dataclass(frozen=True)
class CalibrationSet:
    """Identification and held-out recordings of one simulated robot instance.

    Attributes:
        identification: Recording of the optimised excitation trajectory.
        held_out: Recording of a different excitation trajectory.
        excitation: Design result of the identification trajectory.
        held_out_excitation: Design result of the held-out trajectory.
    """

    identification: SimRecording
    held_out: SimRecording
    excitation: ExcitationResult
    held_out_excitation: ExcitationResult


def record_excitation(
    robot: Robot,
    excitation: ExcitationResult,
    duration: float,
    config: SimConfig,
    payload: Payload | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SimRecording:
    """Run an excitation trajectory (whole periods) on the simulated robot.

    Args:
        robot: The robot.
        excitation: Designed trajectory.
        duration: Length [s].
        config: Simulator settings (robot instance seed and run).
        payload: Optional payload.
        progress: Progress callback.

    Returns:
        Measured and true recordings.
    """
    samples = excitation.trajectory.at_rate(duration, 1.0 / config.timestep)
    return _run(robot, samples, config, payload, progress, "")


def _run(robot: Robot, samples: TrajectorySamples, config: SimConfig, payload: Payload | None,
         progress: Callable[[int, int], None] | None, what: str) -> SimRecording:
    """Play samples at the simulator's rate; the measured and the true-current recordings."""
    sim = SimRobot(robot, config, payload=payload, q0=samples.q[0])
    log = run_trajectory(sim, samples.q, samples.qd, progress=progress)
    src = f"sim {config.plant} plant seed {config.seed} run {config.run}{what}"
    measured = Recording(time=log.time, q=log.q, current=log.current, q_cmd=log.q_cmd,
                         robot=robot.name, source=src, sim_seed=config.seed)
    true = Recording(time=log.time, q=log.q, current=log.truth.current, robot=robot.name,
                     source=f"{src} (true current)", sim_seed=config.seed)
    return SimRecording(measured=measured, true=true, log=log)


def record_friction_sweep(
    robot: Robot,
    seed: int = 1,
    run: int = 2,
    q_start: Array | None = None,
    sweep_config: FrictionSweepConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    plant: PlantPreset | str = PlantPreset.REALISTIC,
    warm_up_s: float = 0.0,
) -> SimRecording:
    """Run a friction sweep (:func:`design_friction_sweep`) on simulated robot ``seed``.

    Args:
        robot: The robot.
        seed: Simulated robot instance.
        run: Recording number (independent sensor noise).
        q_start: Start configuration [rad], shape (n,); default: the neutral pose.
        sweep_config: Sweep layout.
        progress: Progress callback.
        plant: Simulated plant (:mod:`leadthrough.sim.plant`).
        warm_up_s: Production-like motion before the recording (realistic plant) [s].

    Returns:
        Measured and true recordings.
    """
    config = SimConfig(seed=seed, run=run, plant=plant_preset(plant), warm_up_s=warm_up_s)
    layout = sweep_config if sweep_config is not None else FrictionSweepConfig()
    sweep = design_friction_sweep(robot, q_start, replace(layout, rate_hz=1.0 / config.timestep))
    return _run(robot, sweep.samples, config, None, progress, " friction sweep")


def record_presliding_test(
    robot: Robot,
    seed: int = 1,
    run: int = 3,
    q_start: Array | None = None,
    test_config: PreslidingTestConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    plant: PlantPreset | str = PlantPreset.REALISTIC,
    warm_up_s: float = 0.0,
) -> SimRecording:
    """Run a presliding test (:func:`design_presliding_test`) on simulated robot ``seed``.

    Args:
        robot: The robot.
        seed: Simulated robot instance.
        run: Recording number (independent sensor noise).
        q_start: Test configuration [rad], shape (n,); default: the neutral pose.
        test_config: Test layout.
        progress: Progress callback.
        plant: Simulated plant (:mod:`leadthrough.sim.plant`).
        warm_up_s: Production-like motion before the recording (realistic plant) [s].

    Returns:
        Measured and true recordings.
    """
    config = SimConfig(seed=seed, run=run, plant=plant_preset(plant), warm_up_s=warm_up_s)
    layout = test_config if test_config is not None else PreslidingTestConfig()
    test = design_presliding_test(robot, q_start, replace(layout, rate_hz=1.0 / config.timestep))
    return _run(robot, test.samples, config, None, progress, " presliding test")


def record_calibration_set(
    robot: Robot,
    seed: int = 1,
    duration: float = 60.0,
    excitation_config: ExcitationConfig | None = None,
    progress: Callable[[str], None] | None = None,
    plant: PlantPreset | str = PlantPreset.REALISTIC,
    warm_up_s: float = 0.0,
) -> CalibrationSet:
    """Design two excitation trajectories and record both on robot instance ``seed``.

    Args:
        robot: The robot.
        seed: Simulated robot instance (true parameters); runs 0 and 1 get independent noise.
        duration: Length of each recording [s] (whole periods of the trajectory).
        excitation_config: Design settings (its seed is used for identification, +1 held out).
        progress: Called with a line of text after each step.
        plant: Simulated plant (:mod:`leadthrough.sim.plant`).
        warm_up_s: Production-like motion before each recording (realistic plant) [s].

    Returns:
        The data set.
    """
    cfg = excitation_config if excitation_config is not None else ExcitationConfig()
    say = progress if progress is not None else (lambda _: None)
    exc = design_excitation(robot, cfg)
    say(f"excitation designed: cond = {exc.condition_number:.1f} ({exc.runtime_s:.1f} s)")
    held_cfg = replace(cfg, seed=cfg.seed + 1)
    exc_h = design_excitation(robot, held_cfg)
    say(f"held-out trajectory designed: cond = {exc_h.condition_number:.1f}")
    preset = plant_preset(plant)
    ident = record_excitation(robot, exc, duration, SimConfig(seed=seed, run=0, plant=preset,
                                                              warm_up_s=warm_up_s))
    held = record_excitation(robot, exc_h, duration, SimConfig(seed=seed, run=1, plant=preset,
                                                               warm_up_s=warm_up_s))
    say(f"recorded 2 × {duration:g} s at 1 kHz; max tracking error "
        f"{1e3 * float(np.max(np.abs(ident.log.truth.q - ident.log.q_cmd))):.2f} mrad")
    return CalibrationSet(identification=ident, held_out=held, excitation=exc,
                          held_out_excitation=exc_h)


@dataclass(frozen=True)
class CalibrationComparison:
    """Table II on a simulated calibration set.

    Attributes:
        comparison: All methods, identified on the identification run, evaluated held out.
        floors: Noise floor per data-set label ("identification", "held-out").
    """

    comparison: MethodComparison
    floors: dict[str, ResidualStats]


def compare_on_calibration_set(
    robot: Robot,
    cal: CalibrationSet,
    methods: Sequence[str],
    config: IdentifyConfig | None = None,
    progress: Callable[[str], None] | None = None,
) -> CalibrationComparison:
    """Identify with every method, validate held out, and measure both noise floors."""
    cfg = config if config is not None else IdentifyConfig()
    comp = compare_methods(robot, cal.identification.measured,
                           {"held-out": cal.held_out.measured}, methods, cfg, progress=progress)
    floors = {"identification": noise_floor(robot, cal.identification.measured,
                                            cal.identification.true, cfg),
              "held-out": noise_floor(robot, cal.held_out.measured, cal.held_out.true, cfg)}
    return CalibrationComparison(comparison=comp, floors=floors)
