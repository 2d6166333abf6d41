"""Sanity checks of the simulated robot against the drive model (issue: foundation, must-show 2).

* :func:`check_hold`: commanded pose held under gravity; currents vs the gravity torque through
  the drive model, i = (τ_g − τ_cog) / (R·Kt).
* :func:`check_push`: a constant force at the TCP changes the currents by −J^T·F / (R·Kt) (the
  motors oppose the push, so the estimated external torque τ̂_d − τ̂_j of eq. 27 equals +J^T·F),
  plus the change of the gears' friction (presliding hysteresis, reported separately).

R·Kt is the simulator's true torque constant and τ_cog its motors' cogging torque at the pose
(on the realistic plant a few per cent off the drive file's, and nonzero; on the ideal plant the
drive file's and zero): the checks test the simulator against its own drive model.

"Within the noise" means: the error of the averaged current is well below the per-sample current
noise σ. The averaging windows are seconds long because the sensor noise has a slow component
(50 ms correlation). The residual that remains is physical (the sensor bias, and the presliding
hysteresis of the drive friction after a load change), and much smaller than σ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.robot.description import Robot
from leadthrough.sim.operator import ConstantWrench
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.run import hold

__all__ = [
    "HoldCheck",
    "PushCheck",
    "RegressorCheck",
    "check_hold",
    "check_push",
    "check_regressor",
    "tcp_jacobian",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class HoldCheck:
    """Result of holding a pose.

    Attributes:
        q0: Commanded pose [rad], shape (n,).
        max_joint_error: Max |q_true − q0| over the hold [rad], shape (n,).
        current_mean: Mean measured current [A], shape (n,).
        current_expected: (τ_g(q0) − τ_cog(q0)) / (R·Kt) with the true links and the true
            torque constant [A], shape (n,).
        noise_sigma: Per-sample current noise σ [A], shape (n,).
    """

    q0: Array
    max_joint_error: Array
    current_mean: Array
    current_expected: Array
    noise_sigma: Array

    @property
    def error_in_sigma(self) -> Array:
        """|mean − expected| / σ per joint."""
        return np.abs(self.current_mean - self.current_expected) / self.noise_sigma


@dataclass(frozen=True)
class PushCheck:
    """Result of pushing on the TCP of a held robot.

    Attributes:
        wrench_base: Applied wrench, base frame [N, N·m], shape (6,).
        delta_current: Mean current after minus before [A], shape (n,).
        expected_delta: −J^T·F / (R·Kt) at the pose (the true R·Kt) [A], shape (n,).
        noise_sigma: Per-sample current noise σ [A], shape (n,).
        max_deflection: Max joint deflection during the push [rad].
        friction_delta: Change of the drive train's true friction torque, as current
            Δτ_f / (R·Kt) [A], shape (n,): the presliding hysteresis of the gears keeps part
            of the deflection's friction after the servo has pulled the joint back.
    """

    wrench_base: Array
    delta_current: Array
    expected_delta: Array
    noise_sigma: Array
    max_deflection: float
    friction_delta: Array

    @property
    def error_in_sigma(self) -> Array:
        """|Δ − expected − friction change| / σ per joint."""
        return (np.abs(self.delta_current - self.expected_delta - self.friction_delta)
                / self.noise_sigma)

    @property
    def presliding_share(self) -> float:
        """max |friction change| / max |expected change|: how much of the push the gears'
        presliding friction carries."""
        return float(np.max(np.abs(self.friction_delta))
                     / max(float(np.max(np.abs(self.expected_delta))), 1e-300))


def tcp_jacobian(robot: Robot, q: Array) -> Array:
    """TCP Jacobian in the base-aligned frame at the TCP, shape (6, n) (linear rows first)."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    return np.array(pin.getFrameJacobian(model, data, robot.tcp_frame_id,
                                         pin.LOCAL_WORLD_ALIGNED))


def check_hold(robot: Robot, config: SimConfig, q0: Array, duration: float = 4.0) -> HoldCheck:
    """Hold ``q0`` for ``duration`` s and compare currents with the gravity torque.

    Args:
        robot: The robot.
        config: Simulator settings (seed).
        q0: Pose [rad], shape (n,).
        duration: Hold time [s].

    Returns:
        The measured figures.
    """
    sim = SimRobot(robot, config, q0=q0)
    log = hold(sim, duration)
    expected = ((sim.true_gravity_torque(q0) - sim.true_cogging_torque(q0))
                / sim.true_torque_per_amp)
    return HoldCheck(
        q0=np.asarray(q0, dtype=float),
        max_joint_error=np.max(np.abs(log.truth.q - q0), axis=0),
        current_mean=log.current.mean(axis=0),
        current_expected=expected,
        noise_sigma=sim.truth.current_noise,
    )


def check_push(
    robot: Robot,
    config: SimConfig,
    q0: Array,
    wrench_base: Array,
    before: float = 3.0,
    settle: float = 1.5,
    window: float = 5.0,
) -> PushCheck:
    """Push on the TCP of a held robot and compare the current change with −J^T·F/(R·Kt).

    Args:
        robot: The robot.
        config: Simulator settings (seed).
        q0: Pose [rad], shape (n,).
        wrench_base: Wrench at the TCP, base frame [N, N·m], shape (6,).
        before: Hold time before the push [s]; all but the first 0.5 s is averaged.
        settle: Time after the push starts before averaging [s].
        window: Averaging window after settling [s].

    Returns:
        The measured figures.
    """
    w = np.asarray(wrench_base, dtype=float)
    sim = SimRobot(robot, config, q0=q0,
                   operator=ConstantWrench(tuple(w.tolist()), t_start=before))
    dt = config.timestep
    steps = round((before + settle + window) / dt)
    current = np.empty((steps, robot.n))
    friction = np.empty((steps, robot.n))
    deflection = 0.0
    for k in range(steps):
        sim.step()
        current[k] = sim.read().current
        friction[k] = sim.true_friction_torque
        deflection = max(deflection, float(np.max(np.abs(sim.true_state()[0] - q0))))
    pre = slice(int(0.5 / dt), int(before / dt))
    post = slice(int((before + settle) / dt), steps)
    expected = -(tcp_jacobian(robot, q0).T @ w) / sim.true_torque_per_amp
    return PushCheck(
        wrench_base=w,
        delta_current=current[post].mean(axis=0) - current[pre].mean(axis=0),
        expected_delta=expected,
        noise_sigma=sim.truth.current_noise,
        max_deflection=deflection,
        friction_delta=(friction[post].mean(axis=0) - friction[pre].mean(axis=0))
        / sim.true_torque_per_amp,
    )


@dataclass(frozen=True)
class RegressorCheck:
    """Agreement of K·φ with Pinocchio RNEA, MuJoCo inverse dynamics and the base regressor.

    Attributes:
        samples: Number of random (q, q̇, q̈) samples.
        base_parameters: Number of base parameters.
        rel_error_rnea: max|K·φ − rnea| / max|rnea|.
        rel_error_mujoco: max|K·φ − mj_inverse| / max|mj_inverse|.
        rel_error_base: max|Y_base·β − K·φ| / max|K·φ|.
    """

    samples: int
    base_parameters: int
    rel_error_rnea: float
    rel_error_mujoco: float
    rel_error_base: float


def check_regressor(robot: Robot, samples: int = 1000, seed: int = 0) -> RegressorCheck:
    """Compare the regressor model with Pinocchio and MuJoCo on the nominal model.

    Args:
        robot: The robot.
        samples: Random samples within the joint limits (±2 rad/s, ±5 rad/s²).
        seed: Seed of the samples.

    Returns:
        The relative errors.
    """
    import mujoco

    from leadthrough.dynamics.base_parameters import compute_base_parameters, random_samples
    from leadthrough.dynamics.regressor import link_regressor_batch, standard_parameters
    from leadthrough.sim.mujoco_model import build_mujoco_model

    model = robot.model
    q, qd, qdd = random_samples(model, samples, np.random.default_rng(seed))
    K = link_regressor_batch(model, q, qd, qdd)
    phi = standard_parameters(model)
    tau = K @ phi
    data = model.createData()
    rnea = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(samples)])
    mj_model = build_mujoco_model(robot)
    mj_data = mujoco.MjData(mj_model)
    inv = np.empty_like(tau)
    for k in range(samples):
        mj_data.qpos[:] = q[k]
        mj_data.qvel[:] = qd[k]
        mj_data.qacc[:] = qdd[k]
        mujoco.mj_inverse(mj_model, mj_data)
        inv[k] = mj_data.qfrc_inverse
    base = compute_base_parameters(model)
    tau_base = base.regressor(K) @ base.from_standard(phi)
    return RegressorCheck(
        samples=samples,
        base_parameters=base.count,
        rel_error_rnea=float(np.max(np.abs(tau - rnea)) / np.max(np.abs(rnea))),
        rel_error_mujoco=float(np.max(np.abs(tau - inv)) / np.max(np.abs(inv))),
        rel_error_base=float(np.max(np.abs(tau_base - tau)) / np.max(np.abs(tau))),
    )
