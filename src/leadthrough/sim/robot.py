"""The simulated robot: plays a real industrial arm in position mode, stepped at 1 kHz.

What a real controller would report is read with :meth:`SimRobot.read` (time, encoder positions,
measured motor currents, sequence number). The simulator's own truth (true link and drive
parameters, true state, true current and true external joint torque) lives apart in
:attr:`SimRobot.truth` and :meth:`SimRobot.true_state`, for tests and noise floors only.

Each step (dt = 1 ms):
1. sensors read the state at t_k (encoder quantisation; current noise, bias, ADC);
2. the cascaded servo turns the commanded position into a current command (saturated);
3. the drive train turns current into torque R·Kt·i and sets the true friction
   (see :mod:`leadthrough.sim.drivetrain`);
4. the operator's wrench is applied at the TCP, and MuJoCo integrates to t_{k+1}.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.dynamics.regressor import standard_parameters
from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.drive_mismatch import DriveMismatchConfig, with_drive_mismatch
from leadthrough.sim.drivetrain import (
    DriveTrain,
    DriveTrainConfig,
    DriveTrainTruth,
    sample_drive_truth,
)
from leadthrough.sim.link_truth import (
    LinkMismatchConfig,
    true_link_inertias,
    with_model_mismatch,
)
from leadthrough.sim.mujoco_model import TCP_SITE, Payload, build_mujoco_model
from leadthrough.sim.operator import Operator
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.sensors import CurrentSensor, SensorConfig
from leadthrough.sim.servo import CascadedServo, design_servo_gains

__all__ = ["Feedback", "SimConfig", "SimRobot", "SimTruth", "draw_true_parameters"]

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

    def __post_init__(self) -> None:
        object.__setattr__(self, "plant", plant_preset(self.plant))
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
        drive: True drive-train parameters.
        current_bias: Current-sensor bias [A], shape (n,).
        current_noise: Current-sensor noise σ in motion (white and slow parts combined) [A],
            shape (n,).
    """

    inertias: tuple[pin.Inertia, ...]
    phi: Array
    drive: DriveTrainTruth
    current_bias: Array
    current_noise: Array


@dataclass(frozen=True)
class Feedback:
    """One sample as a real controller reports it.

    Attributes:
        t: Time [s].
        q: Encoder joint positions [rad], shape (n,).
        current: Measured motor currents [A], shape (n,).
        sequence: Sample counter.
    """

    t: float
    q: Array
    current: Array
    sequence: int


def draw_true_parameters(robot: Robot, config: SimConfig
                         ) -> tuple[list[pin.Inertia], DriveTrainTruth]:
    """The true links and drive train of robot instance ``config.seed`` on ``config.plant``.

    The ideal plant's draws come first from the instance's stream (as before the presets); the
    realistic plant adds its mismatch from streams of its own, so that both plants of one seed
    share the in-box links and the friction levels.

    Args:
        robot: The robot (nominal model and drives).
        config: Simulator settings (seed, plant, deviations).

    Returns:
        The true link inertias (joint order) and drive-train parameters.
    """
    rng_truth = np.random.default_rng([config.seed, 1])
    inertias = true_link_inertias(robot.model, rng_truth, config.link_deviation)
    drive = sample_drive_truth(robot, config.drive, rng_truth)
    if config.plant is PlantPreset.REALISTIC:
        inertias = with_model_mismatch(robot.model, inertias,
                                       np.random.default_rng([config.seed, 4]), config.links)
        drive = with_drive_mismatch(drive, robot, config.drive_mismatch,
                                    np.random.default_rng([config.seed, 5]))
    return inertias, drive


class SimRobot:
    """Simulated position-controlled robot.

    Args:
        robot: Robot description (nominal model, drives).
        config: Simulator settings (seed, noise, friction).
        payload: Optional payload at the TCP.
        operator: Optional operator pushing on the TCP.
        q0: Initial configuration [rad], shape (n,); default mid-range clipped to zero.
    """

    def __init__(
        self,
        robot: Robot,
        config: SimConfig | None = None,
        *,
        payload: Payload | None = None,
        operator: Operator | None = None,
        q0: Array | None = None,
    ) -> None:
        self.robot = robot
        self.config = config = config if config is not None else SimConfig()
        rng_noise = np.random.default_rng([config.seed, 2, config.run])
        inertias, drive = draw_true_parameters(robot, config)
        self._drive = DriveTrain(drive, robot.gear_ratio)
        self._sensor = CurrentSensor(config.sensors, robot.max_current, rng_noise,
                                     config.timestep,
                                     bias_rng=np.random.default_rng([config.seed, 3]))
        model_true = robot.model.copy()
        for j, inertia in enumerate(inertias, start=1):
            model_true.inertias[j] = inertia
        self.truth = SimTruth(
            inertias=tuple(inertias),
            phi=standard_parameters(model_true),
            drive=drive,
            current_bias=self._sensor.bias.copy(),
            current_noise=self._sensor.sigma.copy(),
        )
        self.payload = payload
        self.operator = operator
        self._servo = CascadedServo(design_servo_gains(robot, config.servo_bandwidth_hz),
                                    robot.torque_per_amp, robot.max_current)
        n = robot.n
        self._res = robot.encoder_resolution
        self._inv_res = 1.0 / self._res
        self._tpa = robot.torque_per_amp
        self._q_meas = np.zeros(n)
        self._q_cmd = np.zeros(n)
        self._qd_ff = np.zeros(n)
        self._tau_motor = np.zeros(n)
        self._tau_ext = np.zeros(n)
        self._wrench = np.zeros(6)
        self._i_true = np.zeros(n)
        self._i_meas = np.zeros(n)
        self._speed = np.zeros(n)
        self._seq = 0
        self._build()
        self.reset(robot.neutral() if q0 is None else q0)

    # ----------------------------------------------------------------------------------- setup
    def _build(self) -> None:
        cfg = self.config
        self.mj_model = build_mujoco_model(
            self.robot, list(self.truth.inertias), armature=self.truth.drive.armature,
            damping=self.truth.drive.viscous, timestep=cfg.timestep, payload=self.payload)
        self.mj_data = mujoco.MjData(self.mj_model)
        self._tcp_site = mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_SITE, TCP_SITE)
        self._tcp_body = int(self.mj_model.site_bodyid[self._tcp_site])

    def attach_payload(self, payload: Payload | None) -> None:
        """Attach (or with None, remove) a payload, keeping the state and settling the servo."""
        q = self.mj_data.qpos.copy()
        self.payload = payload
        self._build()
        self.reset(q)

    def reset(self, q0: Array) -> None:
        """Place the robot at rest at ``q0``, settled: the servo holds exactly the gravity load.

        Args:
            q0: Joint positions [rad], shape (n,), within the joint limits.

        Raises:
            SimulationError: ``q0`` has the wrong shape, is not finite or is outside the limits.
        """
        q0 = np.asarray(q0, dtype=float)
        r = self.robot
        if q0.shape != (r.n,) or not np.all(np.isfinite(q0)):
            raise SimulationError("bad initial configuration", field="q0", value=q0.tolist(),
                                  expected=f"{r.n} finite joint positions [rad]")
        if np.any(q0 < r.lower_limits) or np.any(q0 > r.upper_limits):
            raise SimulationError("initial configuration outside the joint limits", field="q0",
                                  value=q0.tolist(), expected="within the drive file's limits")
        d = self.mj_data
        mujoco.mj_resetData(self.mj_model, d)
        d.qpos[:] = q0
        mujoco.mj_forward(self.mj_model, d)
        hold = d.qfrc_bias.copy()
        self._drive.reset()
        self._servo.reset(self._quantise(q0), hold)
        self._q_cmd[:] = q0
        self._qd_ff[:] = 0.0
        self._i_true[:] = self._servo.current
        self._seq = 0

    def _quantise(self, q: Array) -> Array:
        np.multiply(q, self._inv_res, out=self._q_meas)
        np.rint(self._q_meas, out=self._q_meas)
        self._q_meas *= self._res
        return self._q_meas

    # -------------------------------------------------------------------------------- running
    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.mj_data.time)

    @property
    def q_command(self) -> Array:
        """The current position command [rad], shape (n,)."""
        return self._q_cmd.copy()

    def command(self, q: Array, qd: Array | None = None) -> None:
        """Set the position command (and optional velocity feed-forward) for the next steps.

        Args:
            q: Commanded joint positions [rad], shape (n,).
            qd: Velocity feed-forward [rad/s], shape (n,); default zero.
        """
        self._q_cmd[:] = q
        if qd is None:
            self._qd_ff[:] = 0.0
        else:
            self._qd_ff[:] = qd

    def step(self) -> None:
        """Advance one timestep (sensors, servo, drive train, physics)."""
        m, d, dt = self.mj_model, self.mj_data, self.config.timestep
        q_meas = self._quantise(d.qpos)
        current = self._servo.update(q_meas, self._q_cmd, self._qd_ff, dt)
        self._i_true[:] = current
        np.abs(d.qvel, out=self._speed)
        self._i_meas[:] = self._sensor.read(current, self._speed)
        np.multiply(current, self._tpa, out=self._tau_motor)
        self._drive.update(d.qpos, d.qvel, self._tau_motor, dt)
        mujoco.mj_step1(m, d)
        np.subtract(self._tau_motor, self._drive.friction, out=d.qfrc_applied)
        if self.operator is not None:
            self._apply_operator()
        elif self._tau_ext.any():
            self._tau_ext[:] = 0.0
            self._wrench[:] = 0.0
        mujoco.mj_step2(m, d)
        self._seq += 1

    def _apply_operator(self) -> None:
        assert self.operator is not None
        m, d = self.mj_model, self.mj_data
        point = d.site_xpos[self._tcp_site]
        self._wrench[:] = self.operator.wrench(float(d.time), point)
        self._tau_ext[:] = 0.0
        if self._wrench.any():
            mujoco.mj_applyFT(m, d, self._wrench[:3], self._wrench[3:], point, self._tcp_body,
                              self._tau_ext)
            d.qfrc_applied += self._tau_ext

    def read(self) -> Feedback:
        """The last sample as a real controller reports it (positions and currents at t_k).

        Returns:
            Time, encoder positions, measured currents and sequence number of the last step.
        """
        dt = self.config.timestep
        return Feedback(t=(self._seq - 1) * dt if self._seq else 0.0, q=self._q_meas.copy(),
                        current=self._i_meas.copy(), sequence=self._seq)

    # ---------------------------------------------------------------------------------- truth
    def true_state(self) -> tuple[Array, Array]:
        """True joint positions [rad] and velocities [rad/s] now (simulator truth)."""
        return self.mj_data.qpos.copy(), self.mj_data.qvel.copy()

    @property
    def true_current(self) -> Array:
        """Actual motor current of the last step, before the sensor [A] (simulator truth)."""
        return self._i_true.copy()

    @property
    def true_friction_torque(self) -> Array:
        """Drive-train friction torque (all but the linear viscous part) of the last step [N·m]
        (truth)."""
        return self._drive.friction.copy()

    @property
    def true_external_torque(self) -> Array:
        """Joint torque of the operator's wrench in the last step, J^T·F [N·m] (truth)."""
        return self._tau_ext.copy()

    @property
    def applied_wrench(self) -> Array:
        """Wrench the operator applied in the last step, base frame [N, N·m] (truth)."""
        return self._wrench.copy()

    def true_gravity_torque(self, q: Array) -> Array:
        """Gravity torque of the true links (and payload) at ``q`` [N·m] (simulator truth)."""
        d = mujoco.MjData(self.mj_model)
        d.qpos[:] = q
        mujoco.mj_forward(self.mj_model, d)
        return d.qfrc_bias.copy()
