"""The simulated robot: plays a real industrial arm in position mode, stepped at 1 kHz.

What a real controller would report is read with :meth:`SimRobot.read` (time, encoder positions,
measured motor currents, sequence number: a :class:`~leadthrough.sim.sensors.Feedback`). The
simulator's own truth (true link and drive parameters, true state, true current and true
external joint torque) lives apart in :attr:`SimRobot.truth` and :meth:`SimRobot.true_state`, for
tests and noise floors only.

Each step (dt = 1 ms):
1. sensors read the state at t_k (encoder quantisation; current noise, bias, ADC; on the
   realistic plant the current of a fixed lag earlier, and with a jitter both of a random
   earlier instant: :class:`~leadthrough.sim.sensors.SampleTiming`);
2. the cascaded servo turns the commanded position into a current command (saturated);
3. the drive train turns current into torque R·Kt·i (the true Kt: on the realistic plant a few
   per cent off the drive file's, plus the motors' cogging) and sets the true friction
   (see :mod:`leadthrough.sim.drivetrain`, :mod:`leadthrough.sim.drive_friction`);
4. the operator's wrench is applied at the TCP, and MuJoCo integrates to t_{k+1}.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.regressor import standard_parameters
from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.drive_friction import DriveTrain
from leadthrough.sim.instance import SimConfig, SimTruth, draw_true_parameters
from leadthrough.sim.mujoco_model import TCP_SITE, Payload, build_mujoco_model
from leadthrough.sim.operator import Operator
from leadthrough.sim.sensors import CurrentSensor, Feedback, SampleTiming
from leadthrough.sim.servo import CascadedServo, design_servo_gains
from leadthrough.sim.thermal import JointTemperatures

__all__ = ["SimConfig", "SimRobot", "SimTruth", "draw_true_parameters"]

Array = NDArray[np.float64]


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
        inertias, drive, thermal, lag = draw_true_parameters(robot, config)
        self._drive = DriveTrain(drive, robot.gear_ratio, thermal=thermal is not None)
        self._temperatures = None if thermal is None else JointTemperatures(thermal)
        self._heat_every = max(1, round(config.thermal.update_period_s / config.timestep))
        self._heat_steps = 0
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
            thermal=thermal,
            current_lag_s=lag,
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
        # the true R·Kt (the servo converts with the drive file's)
        self._tpa = robot.torque_per_amp * drive.torque_constant_scale
        self._cogging = bool(np.any(drive.cogging != 0.0))
        self._tau_cog = np.zeros(n)
        self._q_meas = np.zeros(n)
        self._q_cmd = np.zeros(n)
        self._qd_ff = np.zeros(n)
        self._tau_motor = np.zeros(n)
        self._tau_ext = np.zeros(n)
        self._wrench = np.zeros(6)
        self._i_true = np.zeros(n)
        self._i_meas = np.zeros(n)
        self._speed = np.zeros(n)
        # sample timing: the current's lag and the jitter a driver asks for (sensors module)
        self._timing = SampleTiming(n, lag, config.timestep, self._res,
                                    np.random.default_rng([config.seed, 8, config.run]))
        self._q_read = self._q_meas
        self._seq = 0
        self._build()
        self.reset(robot.neutral() if q0 is None else q0)
        if config.warm_up_s > 0.0:
            self.warm_up(config.warm_up_s)

    # ----------------------------------------------------------------------------------- setup
    def _build(self) -> None:
        cfg = self.config
        self.mj_model = build_mujoco_model(
            self.robot, list(self.truth.inertias), armature=self.truth.drive.armature,
            damping=self.truth.drive.viscous, timestep=cfg.timestep, payload=self.payload)
        self.mj_data = mujoco.MjData(self.mj_model)
        self._tcp_site = mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_SITE, TCP_SITE)
        self._tcp_body = int(self.mj_model.site_bodyid[self._tcp_site])
        self._sync_thermal()

    # ---------------------------------------------------------------------------- temperature
    def _sync_thermal(self) -> None:
        """Give the drive train and MuJoCo's damping the friction scales of the temperatures."""
        temps = self._temperatures
        if temps is None:
            return
        self._drive.set_temperature_scales(temps.static_scale, temps.viscous_scale)
        np.multiply(self.truth.drive.viscous, temps.viscous_scale,
                    out=self.mj_model.dof_damping)

    def _apply_heat(self) -> None:
        """Advance the temperatures by the losses accumulated since the last update."""
        assert self._temperatures is not None
        dt = self.config.timestep
        duration = self._heat_steps * dt
        self._temperatures.advance(self._drive.take_losses(dt) / duration, duration)
        self._heat_steps = 0
        self._sync_thermal()

    def _thermal_or_raise(self) -> JointTemperatures:
        if self._temperatures is None:
            raise SimulationError("the ideal plant has no thermal model", field="plant",
                                  value=str(self.config.plant), expected="realistic")
        return self._temperatures

    @property
    def temperature_c(self) -> Array:
        """Joint temperatures [°C], shape (n,) (simulator truth; realistic plant).

        Raises:
            SimulationError: On the ideal plant.
        """
        return self._thermal_or_raise().temperature_c.copy()

    def set_temperature(self, temperature_c: Array) -> None:
        """Set the joint temperatures [°C], shape (n,) (realistic plant).

        Raises:
            SimulationError: On the ideal plant, or bad temperatures.
        """
        self._thermal_or_raise().set(temperature_c)
        self._sync_thermal()

    def warm_up(self, duration_s: float) -> None:
        """Fast-forward the joint temperatures through ``duration_s`` of production-like motion
        (:mod:`leadthrough.sim.thermal`); the robot's state and time do not change.

        Raises:
            SimulationError: On the ideal plant, or a negative duration.
        """
        self._thermal_or_raise().warm_up(duration_s, self.truth.drive, self.robot,
                                         self.config.thermal)
        self._sync_thermal()

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
        if self._cogging:
            hold -= self.true_cogging_torque(q0)
        self._drive.reset()
        # the servo commands nominal torque; the true torque constant delivers the hold
        self._servo.reset(self._quantise(q0), hold / self.truth.drive.torque_constant_scale)
        self._timing.reset(self._q_meas)
        self._q_cmd[:] = q0
        self._qd_ff[:] = 0.0
        self._i_true[:] = self._servo.current
        self._timing.sampled_current[:] = self._servo.current
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
        if not self._timing.late:
            self._i_meas[:] = self._sensor.read(current, self._speed)
        else:
            self._i_meas[:] = self._timing.read_late(self._sensor, current, self._speed, d.qpos,
                                                     d.qvel)
        np.multiply(current, self._tpa, out=self._tau_motor)
        self._drive.update(d.qpos, d.qvel, self._tau_motor, dt)
        mujoco.mj_step1(m, d)
        np.subtract(self._tau_motor, self._drive.friction, out=d.qfrc_applied)
        if self._cogging:
            self._add_cogging(d.qpos, d.qfrc_applied)
        if self.operator is not None:
            self._apply_operator()
        elif self._tau_ext.any():
            self._tau_ext[:] = 0.0
            self._wrench[:] = 0.0
        mujoco.mj_step2(m, d)
        self._seq += 1
        if self._temperatures is not None:
            self._heat_steps += 1
            if self._heat_steps >= self._heat_every:
                self._apply_heat()

    def set_sample_jitter(self, jitter_s: float) -> None:
        """From now on, take each sample a random time within [0, ``jitter_s``] before the
        instant it is reported for (positions and currents; the servo's own loop keeps its
        clock). What a driver asks for to test timing (:mod:`leadthrough.sim.sensors`).

        Args:
            jitter_s: Largest timing error [s], from 0 (none) to one timestep.

        Raises:
            SimulationError: Out of range.
        """
        sampled = self.true_sampled_current     # the last sample stays the one taken
        self._timing.set_jitter(jitter_s)
        self._timing.sampled_current[:] = sampled
        self._q_read = self._timing.q_jittered if jitter_s > 0.0 else self._q_meas

    def _add_cogging(self, q: Array, out: Array) -> None:
        """out += A·sin(k·R·q + ϕ), the motors' cogging torque at the joints."""
        dr, c = self.truth.drive, self._tau_cog
        np.multiply(q, dr.cogging_frequency, out=c)
        c += dr.cogging_phase
        np.sin(c, out=c)
        c *= dr.cogging
        out += c

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
        """The last sample as a real controller reports it (positions and currents at t_k; on
        the realistic plant the currents of an instant the fixed lag earlier, and with a
        sample jitter both of a random instant up to the jitter earlier).

        Returns:
            Time, encoder positions, measured currents and sequence number of the last step.
        """
        dt = self.config.timestep
        return Feedback(t=(self._seq - 1) * dt if self._seq else 0.0, q=self._q_read.copy(),
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
    def true_sampled_current(self) -> Array:
        """Actual motor current at the instant the last sample was taken (behind the step by
        the current's lag and any jitter), before the sensor's errors [A] (simulator truth)."""
        return (self._timing.sampled_current if self._timing.late else self._i_true).copy()

    @property
    def true_friction_torque(self) -> Array:
        """Drive-train friction torque (all but the linear viscous part) of the last step [N·m]
        (truth)."""
        return self._drive.friction.copy()

    @property
    def true_total_friction(self) -> Array:
        """All of the drive train's friction torque of the last step, the linear viscous part
        (MuJoCo's joint damping, in its passive force) included, against the motion [N·m]
        (truth)."""
        return np.asarray(self._drive.friction - self.mj_data.qfrc_passive)

    @property
    def true_external_torque(self) -> Array:
        """Joint torque of the operator's wrench in the last step, J^T·F [N·m] (truth)."""
        return self._tau_ext.copy()

    @property
    def applied_wrench(self) -> Array:
        """Wrench the operator applied in the last step, base frame [N, N·m] (truth)."""
        return self._wrench.copy()

    @property
    def true_torque_per_amp(self) -> Array:
        """True R·Kt per joint [N·m/A], shape (n,) (simulator truth)."""
        return self._tpa.copy()

    def true_cogging_torque(self, q: Array) -> Array:
        """The motors' cogging torque at ``q``, joint side [N·m], shape (n,) (truth)."""
        out = np.zeros(self.robot.n)
        self._add_cogging(np.asarray(q, dtype=float), out)
        return out

    def true_gravity_torque(self, q: Array) -> Array:
        """Gravity torque of the true links (and payload) at ``q`` [N·m] (simulator truth)."""
        d = mujoco.MjData(self.mj_model)
        d.qpos[:] = q
        mujoco.mj_forward(self.mj_model, d)
        return d.qfrc_bias.copy()
