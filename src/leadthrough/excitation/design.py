"""Optimise a Fourier excitation trajectory for identification.

Objective: the condition number of the observation matrix W, stacked over samples of one period:
the base regressor of the links and rotor inertias (eq. 3, 16) next to the Coulomb and viscous
friction columns of each joint. A well-conditioned W makes every identified parameter sensitive
to the data.

Constraints, on a fine grid over one period:
* joint positions inside the limits with a margin, velocities and accelerations inside a fraction
  of their limits (linear in the coefficients, exact);
* joint torque of the nominal model (links + datasheet rotor inertia) inside a fraction of the
  max joint torque;
* the TCP above a floor plane (base frame z).

Solved with SLSQP from several random starts (multi-start); the best feasible start wins.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.optimize
from numpy.typing import NDArray

from leadthrough.dynamics.base_parameters import (
    BaseParameters,
    compute_base_parameters,
    rotor_columns,
)
from leadthrough.dynamics.regressor import link_regressor_batch
from leadthrough.errors import DataError, check_fields
from leadthrough.excitation.fourier import FourierTrajectory
from leadthrough.robot.description import Robot

__all__ = ["ExcitationConfig", "ExcitationResult", "design_excitation", "observation_matrix"]

Array = NDArray[np.float64]

#: Most harmonics per joint: at the largest base frequency (2 Hz) the top one is then 50 Hz,
#: past every servo's tracking, and the search has 2·H coefficients per joint.
MAX_HARMONICS = 25
#: Most random starts of the search (each is a whole SLSQP run).
MAX_STARTS = 64


@dataclass(frozen=True)
class ExcitationConfig:
    """Settings of the excitation design.

    Attributes:
        harmonics: Number of harmonics H (≥ 2).
        base_frequency: f0 [Hz]; the period is 1/f0.
        objective_samples: Samples per period used for the condition number.
        check_samples: Samples per period on which the constraints are enforced.
        position_margin: Distance kept from the joint limits [rad].
        velocity_fraction: Allowed fraction of each joint's velocity limit.
        acceleration_fraction: Allowed fraction of each joint's acceleration limit.
        torque_fraction: Allowed fraction of each joint's max torque (nominal model).
        floor_height: Minimum TCP height in the base frame [m].
        starts: Number of random starts.
        max_iterations: SLSQP iterations per start.
        seed: Seed of the random starts.
    """

    harmonics: int = 5
    base_frequency: float = 0.1
    objective_samples: int = 60
    check_samples: int = 200
    position_margin: float = 0.1
    velocity_fraction: float = 0.8
    acceleration_fraction: float = 0.8
    torque_fraction: float = 0.8
    floor_height: float = 0.3
    starts: int = 4
    max_iterations: int = 100
    seed: int = 0

    def __post_init__(self) -> None:
        checks = [
            ("harmonics", 2 <= self.harmonics <= MAX_HARMONICS, f"2 .. {MAX_HARMONICS}"),
            ("base_frequency", 0 < self.base_frequency <= 2.0, "0 < f0 <= 2 Hz"),
            ("objective_samples", self.objective_samples >= 10, ">= 10"),
            ("check_samples", self.check_samples >= 20, ">= 20"),
            ("velocity_fraction", 0 < self.velocity_fraction <= 1, "in (0, 1]"),
            ("acceleration_fraction", 0 < self.acceleration_fraction <= 1, "in (0, 1]"),
            ("torque_fraction", 0 < self.torque_fraction <= 1, "in (0, 1]"),
            ("starts", 1 <= self.starts <= MAX_STARTS, f"1 .. {MAX_STARTS}"),
            ("max_iterations", self.max_iterations >= 1, ">= 1"),
            # below the base, or above any industrial arm's reach: no trajectory to search for
            ("floor_height", -5.0 <= self.floor_height <= 5.0, "-5 <= floor <= 5 m"),
            ("seed", self.seed >= 0, ">= 0"),
        ]
        check_fields("excitation", self, checks)


@dataclass(frozen=True)
class ExcitationResult:
    """A designed excitation trajectory and how good it is.

    Attributes:
        trajectory: The trajectory (one period; repeat it for longer recordings).
        condition_number: cond(W) reached.
        start_conditions: cond(W) of each start (inf when a start ended infeasible).
        max_velocity_ratio: max |q̇| / velocity limit.
        max_acceleration_ratio: max |q̈| / acceleration limit.
        max_torque_ratio: max |τ_nominal| / max torque.
        min_position_margin: Smallest distance to a joint limit [rad].
        min_tcp_height: Lowest TCP height [m].
        runtime_s: Wall time of the design [s].
    """

    trajectory: FourierTrajectory
    condition_number: float
    start_conditions: tuple[float, ...]
    max_velocity_ratio: float
    max_acceleration_ratio: float
    max_torque_ratio: float
    min_position_margin: float
    min_tcp_height: float
    runtime_s: float


def observation_matrix(
    robot: Robot, base: BaseParameters, q: Array, qd: Array, qdd: Array
) -> Array:
    """W = [link + rotor base regressor | Coulomb columns | viscous columns], stacked.

    Args:
        robot: The robot.
        base: Base parameters built with ``include_rotor=True``.
        q: Positions [rad], shape (N, n).
        qd: Velocities [rad/s], shape (N, n).
        qdd: Accelerations [rad/s²], shape (N, n).

    Returns:
        W, shape (N·n, r + 2n).
    """
    n = robot.n
    K = link_regressor_batch(robot.model, q, qd, qdd)
    K = np.concatenate([K, rotor_columns(qdd)], axis=2)
    Kb = base.regressor(K)
    fr = np.zeros((q.shape[0], n, 2 * n))
    idx = np.arange(n)
    fr[:, idx, idx] = np.sign(qd)
    fr[:, idx, n + idx] = qd
    return np.concatenate([Kb, fr], axis=2).reshape(q.shape[0] * n, -1)


class _Problem:
    """Vectorised evaluation of objective and constraints for one robot."""

    def __init__(self, robot: Robot, config: ExcitationConfig) -> None:
        self.robot = robot
        self.cfg = config
        self.n = robot.n
        self.h = config.harmonics
        self.m = 2 * (config.harmonics - 1)          # free coefficients per joint
        self.base = compute_base_parameters(robot.model, include_rotor=True)
        T = 1.0 / config.base_frequency
        t_obj = np.linspace(0.0, T, config.objective_samples, endpoint=False)
        t_chk = np.linspace(0.0, T, config.check_samples, endpoint=False)
        self.B_obj = FourierTrajectory.basis(t_obj, config.base_frequency, config.harmonics)
        self.B_chk = FourierTrajectory.basis(t_chk, config.base_frequency, config.harmonics)
        t_nl = np.linspace(0.0, T, max(20, config.check_samples // 4), endpoint=False)
        self.B_nl = FourierTrajectory.basis(t_nl, config.base_frequency, config.harmonics)
        self.data = robot.model.createData()
        self.lo = robot.lower_limits + config.position_margin
        self.hi = robot.upper_limits - config.position_margin
        self.vmax = config.velocity_fraction * robot.velocity_limit
        self.amax = config.acceleration_fraction * robot.acceleration_limit
        self.tmax = config.torque_fraction * robot.max_torque
        self._build_linear()

    def unpack(self, x: Array) -> tuple[Array, Array, Array]:
        X = x.reshape(self.n, self.m + 1)
        coef = X[:, : self.m]
        return coef[:, : self.h - 1], coef[:, self.h - 1:], X[:, self.m]

    def trajectory(self, x: Array) -> FourierTrajectory:
        a, b, q0 = self.unpack(x)
        return FourierTrajectory(self.cfg.base_frequency, q0.copy(), a.copy(), b.copy())

    def kinematics(self, x: Array, B: tuple[Array, Array, Array]) -> tuple[Array, Array, Array]:
        X = x.reshape(self.n, self.m + 1)
        coef, q0 = X[:, : self.m], X[:, self.m]
        return q0 + B[0] @ coef.T, B[1] @ coef.T, B[2] @ coef.T

    def _build_linear(self) -> None:
        """Linear inequality constraints A·x + c ≥ 0 for positions, velocities, accelerations."""
        Bq, Bv, Ba = self.B_chk
        N = Bq.shape[0]
        rows: list[Array] = []
        consts: list[Array] = []
        width = self.m + 1
        for j in range(self.n):
            def block(mat: Array, q0_sign: float, j: int = j) -> Array:
                A = np.zeros((N, self.n * width))
                A[:, j * width: j * width + self.m] = mat
                A[:, j * width + self.m] = q0_sign
                return A
            # hi − q ≥ 0, q − lo ≥ 0, vmax ∓ q̇ ≥ 0, amax ∓ q̈ ≥ 0
            rows += [block(-Bq, -1.0), block(Bq, 1.0), block(-Bv, 0.0), block(Bv, 0.0),
                     block(-Ba, 0.0), block(Ba, 0.0)]
            consts += [np.full(N, self.hi[j]), np.full(N, -self.lo[j]),
                       np.full(N, self.vmax[j]), np.full(N, self.vmax[j]),
                       np.full(N, self.amax[j]), np.full(N, self.amax[j])]
        A = np.vstack(rows)
        c = np.concatenate(consts)
        self.A_lin, self.c_lin = A, c

    def linear(self, x: Array) -> Array:
        return self.A_lin @ x + self.c_lin

    def nonlinear(self, x: Array) -> Array:
        q, qd, qdd = self.kinematics(x, self.B_nl)
        model, data, robot = self.robot.model, self.data, self.robot
        out_t = np.empty_like(q)
        z = np.empty(q.shape[0])
        for k in range(q.shape[0]):
            out_t[k] = pin.rnea(model, data, q[k], qd[k], qdd[k])
            pin.framesForwardKinematics(model, data, q[k])
            z[k] = data.oMf[robot.tcp_frame_id].translation[2]
        out_t += robot.reflected_rotor_inertia * qdd
        margin_t = (self.tmax - np.abs(out_t)) / self.tmax
        return np.concatenate([margin_t.ravel(), z - self.cfg.floor_height])

    def log_cond(self, x: Array) -> float:
        q, qd, qdd = self.kinematics(x, self.B_obj)
        W = observation_matrix(self.robot, self.base, q, qd, qdd)
        s = np.linalg.svd(W, compute_uv=False)
        if s[-1] <= 1e-12 * s[0]:
            return 30.0
        return float(np.log(s[0] / s[-1]))

    def initial(self, rng: np.random.Generator) -> Array:
        X = np.zeros((self.n, self.m + 1))
        mid = 0.5 * (self.lo + self.hi)
        half = 0.5 * (self.hi - self.lo)
        X[:, self.m] = mid + 0.2 * half * rng.uniform(-1, 1, self.n)
        scale = 0.15 * np.minimum(self.vmax, half * 2 * np.pi * self.cfg.base_frequency)
        X[:, : self.m] = rng.uniform(-1, 1, (self.n, self.m)) * scale[:, None]
        return X.ravel()


def design_excitation(
    robot: Robot,
    config: ExcitationConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ExcitationResult:
    """Design an exciting, feasible Fourier trajectory for ``robot``.

    Args:
        robot: The robot.
        config: Design settings (defaults: 5 harmonics, 0.1 Hz).
        progress: Called as ``progress(starts_done, starts)``.

    Returns:
        The best trajectory found and its figures.

    Raises:
        DataError: No start produced a feasible trajectory.
    """
    cfg = config if config is not None else ExcitationConfig()
    t0 = time.perf_counter()
    prob = _Problem(robot, cfg)
    rng = np.random.default_rng(cfg.seed)
    constraints = [
        {"type": "ineq", "fun": prob.linear, "jac": lambda x: prob.A_lin},
        {"type": "ineq", "fun": prob.nonlinear},
    ]
    best_x: Array | None = None
    best = np.inf
    conds: list[float] = []
    for s in range(cfg.starts):
        x0 = prob.initial(rng)
        res = scipy.optimize.minimize(prob.log_cond, x0, method="SLSQP", constraints=constraints,
                                      options={"maxiter": cfg.max_iterations, "ftol": 1e-6})
        x = res.x
        feasible = prob.linear(x).min() >= -1e-6 and prob.nonlinear(x).min() >= -1e-6
        c = float(np.exp(prob.log_cond(x))) if feasible else float("inf")
        conds.append(c)
        if c < best:
            best, best_x = c, x
        if progress is not None:
            progress(s + 1, cfg.starts)
    if best_x is None:
        raise DataError("no feasible excitation trajectory found", field="excitation",
                        value=cfg.starts, expected="more starts, a lower floor_height or wider "
                                                   "velocity/torque fractions")
    traj = prob.trajectory(best_x)
    dense = traj.sample(np.linspace(0.0, traj.period, 2000, endpoint=False))
    nl = prob.nonlinear(best_x)
    n_t = prob.B_nl[0].shape[0] * robot.n
    return ExcitationResult(
        trajectory=traj,
        condition_number=best,
        start_conditions=tuple(conds),
        max_velocity_ratio=float(np.max(np.abs(dense.qd) / robot.velocity_limit)),
        max_acceleration_ratio=float(np.max(np.abs(dense.qdd) / robot.acceleration_limit)),
        max_torque_ratio=float(np.max(1.0 - nl[:n_t]) * cfg.torque_fraction),
        min_position_margin=float(np.min(np.minimum(dense.q - robot.lower_limits,
                                                    robot.upper_limits - dense.q))),
        min_tcp_height=float(np.min(nl[n_t:]) + cfg.floor_height),
        runtime_s=time.perf_counter() - t0,
    )
