"""A simulated robot instance: its settings, and the truth drawn from them.

A seed and a plant (:mod:`leadthrough.sim.plant`) name one robot: its true links, drive trains
and, on the realistic plant, its thermal behaviour. Sensor noise comes from the seed and the
recording number (``run``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.drive_mismatch import DriveMismatchConfig, with_drive_mismatch
from leadthrough.sim.drivetrain import DriveTrainConfig, DriveTrainTruth, sample_drive_truth
from leadthrough.sim.link_truth import (
    LinkMismatchConfig,
    true_link_inertias,
    with_model_mismatch,
)
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.sensors import SensorConfig
from leadthrough.sim.thermal import ThermalConfig, ThermalTruth, draw_thermal_truth

__all__ = ["SimConfig", "SimTruth", "TrueParameters", "draw_true_parameters"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SimConfig:
    """Settings of the simulated robot.

    Attributes:
        seed: Seeds the robot instance: true parameters and sensor noise (same seed, run and
            plant, bit-identical recording).
        run: Recording number on the same robot instance: each run gets independent sensor
            noise while the true parameters stay those of ``seed``.
        timestep: Physics and servo step [s].
        link_deviation: True link parameters deviate from nominal by up to this (eq. 37 sense).
        links: How the realistic plant's links leave that box (outliers, dress pack).
        drive: How the true drive train is drawn.
        drive_mismatch: What the realistic plant's drive trains add (friction shape, ...).
        sensors: Sensor noise model.
        servo_bandwidth_hz: Velocity-loop bandwidth of the position servo [Hz].
        plant: Which plant plays the robot (:mod:`leadthrough.sim.plant`): ``realistic``
            (default) or ``ideal`` (the plant before issue 24, bit-identical).
        thermal: How the realistic plant's joint temperatures behave.
        warm_up_s: Production-like motion the realistic robot has done before it starts
            (:mod:`leadthrough.sim.thermal`) [s]; 0: a cold robot.
    """

    seed: int = 0
    run: int = 0
    timestep: float = 1e-3
    link_deviation: float = 0.3
    links: LinkMismatchConfig = field(default_factory=LinkMismatchConfig)
    drive: DriveTrainConfig = field(default_factory=DriveTrainConfig)
    drive_mismatch: DriveMismatchConfig = field(default_factory=DriveMismatchConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    servo_bandwidth_hz: float = 20.0
    plant: PlantPreset = PlantPreset.REALISTIC
    thermal: ThermalConfig = field(default_factory=ThermalConfig)
    warm_up_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "plant", plant_preset(self.plant))
        if not (np.isfinite(self.warm_up_s) and self.warm_up_s >= 0.0):
            raise SimulationError("out of range", field="warm_up_s", value=self.warm_up_s,
                                  expected="a finite duration >= 0 s")
        if self.warm_up_s > 0.0 and self.plant is PlantPreset.IDEAL:
            raise SimulationError("the ideal plant has no thermal model", field="warm_up_s",
                                  value=self.warm_up_s,
                                  expected="0 on the ideal plant (or the realistic plant)")
        if self.seed < 0 or self.run < 0:
            raise SimulationError("must be >= 0", field="seed/run", value=(self.seed, self.run),
                                  expected="non-negative integers")
        if not (0.0 < self.timestep <= 0.01):
            raise SimulationError("out of range", field="timestep", value=self.timestep,
                                  expected="0 < timestep <= 0.01 s")
        if not (0.0 <= self.link_deviation < 1.0):
            raise SimulationError("out of range", field="link_deviation",
                                  value=self.link_deviation, expected="0 <= deviation < 1")
        if not (0.0 < self.servo_bandwidth_hz <= 0.1 / self.timestep):
            raise SimulationError("out of range", field="servo_bandwidth_hz",
                                  value=self.servo_bandwidth_hz,
                                  expected=f"0 < bandwidth <= {0.1 / self.timestep:g} Hz")


@dataclass(frozen=True)
class SimTruth:
    """What the simulator knows and a real robot would not tell.

    Attributes:
        inertias: True link inertias, joint order.
        phi: True standard link parameters, shape (10·n,).
        drive: True drive-train parameters (cold, on the realistic plant).
        thermal: Thermal parameters (the realistic plant), else None.
        current_lag_s: Lag of the current samples behind the positions [s] (0 on the ideal
            plant).
        current_bias: Current-sensor bias [A], shape (n,).
        current_noise: Current-sensor noise σ in motion (white and slow parts combined) [A],
            shape (n,).
    """

    inertias: tuple[pin.Inertia, ...]
    phi: Array
    drive: DriveTrainTruth
    thermal: ThermalTruth | None
    current_lag_s: float
    current_bias: Array
    current_noise: Array


class TrueParameters(NamedTuple):
    """A robot instance's drawn truth.

    Attributes:
        inertias: True link inertias, joint order.
        drive: True drive-train parameters (cold).
        thermal: Thermal parameters (the realistic plant), else None.
        current_lag_s: Lag of the current samples behind the positions [s].
    """

    inertias: list[pin.Inertia]
    drive: DriveTrainTruth
    thermal: ThermalTruth | None
    current_lag_s: float


def draw_true_parameters(robot: Robot, config: SimConfig) -> TrueParameters:
    """The truth of robot instance ``config.seed`` on ``config.plant``.

    The ideal plant's draws come first from the instance's stream (as before the presets); the
    realistic plant adds its mismatch from streams of its own, so that both plants of one seed
    share the in-box links and the friction levels.

    Args:
        robot: The robot (nominal model and drives).
        config: Simulator settings (seed, plant, deviations).

    Returns:
        The true link inertias (joint order), drive-train and thermal parameters.
    """
    rng_truth = np.random.default_rng([config.seed, 1])
    inertias = true_link_inertias(robot.model, rng_truth, config.link_deviation)
    drive = sample_drive_truth(robot, config.drive, rng_truth)
    if config.plant is PlantPreset.IDEAL:
        return TrueParameters(inertias, drive, None, 0.0)
    inertias = with_model_mismatch(robot.model, inertias,
                                   np.random.default_rng([config.seed, 4]), config.links)
    drive = with_drive_mismatch(drive, robot, config.drive_mismatch,
                                np.random.default_rng([config.seed, 5]))
    thermal = draw_thermal_truth(drive, robot, config.thermal,
                                 np.random.default_rng([config.seed, 6]))
    lag = float(np.random.default_rng([config.seed, 7]).uniform(*config.sensors.current_lag_s))
    return TrueParameters(inertias, drive, thermal, lag)
