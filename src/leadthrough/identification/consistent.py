"""Physically consistent, fast calibration: variable projection + convex inner problem (LMIs).

Almost every parameter of eq. 21 enters the torque linearly; only the 2n Stribeck velocities
(q̇sm, q̇sg) do not. So:

* **Outer problem** (the Stribeck velocities): variable projection on least squares. Per joint, a
  log-spaced grid of (q̇sm, q̇sg) pairs is scored at once (vectorised 5×5 normal equations of the
  joint's rotor-inertia and friction columns, the link torque held at the current estimate); the
  best pair is kept, the full linear least-squares problem re-solved, and this alternates a few
  times.
* **Inner problem** (everything else, for fixed velocities): convex, solved exactly with cvxpy +
  Clarabel. The objective is the paper's J = Σ|mean| + K_ω·Σ std (an SOCP) or least squares, under
  full physical consistency (each link's 4×4 pseudo-inertia ⪰ margin, see
  :mod:`leadthrough.identification.consistency`), optional bounds around nominal (default ±30 %,
  the paper's), friction ≥ 0 and M_j ≥ 0.
* **Compression**: per joint, the centred data [A_j, b_j] are reduced to a square triangular
  factor by QR, so the inner problem costs the same whatever the number of samples.
* **Standard parameters**: among all consistent parameter sets with the optimal base parameters,
  the one closest to nominal (a second small SDP).

Beyond eq. 21, a free constant torque offset τ_0 per joint is identified: drives report currents
with an offset (the simulator's sensor bias; ``F0`` in the UR10e reference model), which eq. 21
can only absorb into Coulomb terms, depending on the motion's direction balance.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from leadthrough.dynamics.friction import StribeckParameters
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.errors import LeadthroughError, check_fields
from leadthrough.identification.consistency import link_bounds, min_pseudo_inertia_eigenvalues
from leadthrough.identification.observations import Observations

__all__ = ["ConsistentConfig", "ConsistentOutcome", "SolverError", "identify_consistent"]

Array = NDArray[np.float64]


class SolverError(LeadthroughError):
    """The convex inner problem could not be solved (infeasible bounds, solver failure)."""


@dataclass(frozen=True)
class ConsistentConfig:
    """Settings of the consistent method.

    Attributes:
        bound: Relative bound around nominal (eq. 37 sense), or None for physical consistency
            only.
        objective: ``"J"`` (the paper's objective, an SOCP) or ``"ls"`` (least squares).
        k_omega: K_ω of J.
        margin: Relative margin δ: each link's pseudo-inertia ⪰ δ·s_k·1, s_k the largest nominal
            parameter magnitude of the link. The inner problem uses 2δ and the closest-to-nominal
            step δ, so the solver's tolerance never makes the second step infeasible.
        grid: Grid points per Stribeck velocity.
        alternations: Grid / unconstrained least-squares alternations (warm start).
        constrained_alternations: Grid / constrained inner-problem alternations (at most).
    """

    bound: float | None = 0.3
    objective: str = "J"
    k_omega: float = 1.0
    margin: float = 1e-5
    grid: int = 16
    alternations: int = 3
    constrained_alternations: int = 4

    def __post_init__(self) -> None:
        checks = [
            ("bound", self.bound is None or 0 < self.bound < 1, "None or 0 < bound < 1"),
            ("objective", self.objective in ("J", "ls"), "'J' or 'ls'"),
            ("k_omega", self.k_omega >= 0, ">= 0"),
            ("margin", self.margin >= 0, ">= 0"),
            ("grid", self.grid >= 2, ">= 2"),
            ("alternations", self.alternations >= 1, ">= 1"),
            ("constrained_alternations", self.constrained_alternations >= 1, ">= 1"),
        ]
        check_fields("consistent", self, checks)


@dataclass(frozen=True)
class ConsistentOutcome:
    """Result of the consistent method.

    Attributes:
        params: Identified parameters (eq. 15 friction).
        min_pseudo_inertia_eig: Smallest pseudo-inertia eigenvalue per link [kg·m²].
        iterations: Outer alternations + convex solves.
        runtime_s: Wall time [s].
    """

    params: DriveModelParameters
    min_pseudo_inertia_eig: Array
    iterations: int
    runtime_s: float


class _Joint:
    """One joint's used equations."""

    def __init__(self, obs: Observations, j: int) -> None:
        used = obs.used[:, j]
        self.K = obs.K[used, j, :]
        self.qdd = obs.data.qdd[used, j]
        self.qd = obs.data.qd[used, j]
        self.s = np.sign(self.qd)
        self.b = obs.data.torque[used, j]
        self.N = int(used.sum())
        self.R = float(obs.robot.gear_ratio[j])

    def stribeck(self, qd_sm: Array, qd_sg: Array) -> tuple[Array, Array]:
        """Columns exp(−(R q̇/q̇sm)²)·sgn and exp(−(q̇/q̇sg)²)·sgn, shapes (G, N)."""
        gm = np.exp(-np.square(self.R * self.qd[None, :] / np.atleast_1d(qd_sm)[:, None]))
        gg = np.exp(-np.square(self.qd[None, :] / np.atleast_1d(qd_sg)[:, None]))
        return gm * self.s, gg * self.s

    def columns(self, qd_sm: float, qd_sg: float) -> Array:
        """[K, q̈, sgn, g_m, g_g, q̇, 1], shape (N, 10n + 6)."""
        gm, gg = self.stribeck(np.array([qd_sm]), np.array([qd_sg]))
        return np.column_stack([self.K, self.qdd, self.s, gm[0], gg[0], self.qd,
                                np.ones(self.N)])


class _Layout:
    """Index layout of z = [φ (10n), M (n), f1 (n), f2 (n), f3 (n), f4 (n), τ_0 (n)]."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.size = 16 * n

    def joint(self, j: int) -> NDArray[np.intp]:
        n = self.n
        return np.r_[np.arange(10 * n), 10 * n + j + n * np.arange(6)].astype(np.intp)


def _best_stribeck(jt: _Joint, r0: Array, grid_m: Array, grid_g: Array) -> tuple[float, float]:
    """Grid search of one joint's (q̇sm, q̇sg) on least squares of its drive columns."""
    gm, gg = jt.stribeck(grid_m, grid_g)                     # (Gm, N), (Gg, N)
    # A free offset τ_0 is fitted too: centre every column (an intercept).
    gm = gm - gm.mean(axis=1, keepdims=True)
    gg = gg - gg.mean(axis=1, keepdims=True)
    r0 = r0 - r0.mean()
    fixed = np.vstack([jt.qdd, jt.s, jt.qd])                 # (3, N)
    fixed = fixed - fixed.mean(axis=1, keepdims=True)
    Gm, Gg = gm.shape[0], gg.shape[0]
    A = np.zeros((Gm, Gg, 5, 5))
    rhs = np.zeros((Gm, Gg, 5))
    ff = fixed @ fixed.T
    A[..., :3, :3] = ff
    fm = fixed @ gm.T                                        # (3, Gm)
    fg = fixed @ gg.T                                        # (3, Gg)
    A[..., :3, 3] = fm.T[:, None, :]
    A[..., 3, :3] = fm.T[:, None, :]
    A[..., :3, 4] = fg.T[None, :, :]
    A[..., 4, :3] = fg.T[None, :, :]
    A[..., 3, 3] = np.einsum("mn,mn->m", gm, gm)[:, None]
    A[..., 4, 4] = np.einsum("gn,gn->g", gg, gg)[None, :]
    cross = gm @ gg.T
    A[..., 3, 4] = cross
    A[..., 4, 3] = cross
    rhs[..., :3] = fixed @ r0
    rhs[..., 3] = (gm @ r0)[:, None]
    rhs[..., 4] = (gg @ r0)[None, :]
    A += 1e-9 * np.trace(ff) * np.eye(5)
    sse = _nonnegative_sse(A, rhs, float(r0 @ r0))
    k = int(np.argmin(sse))
    return float(grid_m[k // Gg]), float(grid_g[k % Gg])


_SUBSETS = np.array([[(s >> i) & 1 for i in range(5)] for s in range(1, 32)], dtype=bool)


def _nonnegative_sse(A: Array, rhs: Array, rr: float) -> Array:
    """Residual sum of squares of non-negative least squares, for a batch of 5×5 problems.

    The drive parameters (M_j, f1, f2, f3, f4) must be >= 0, as in the inner problem. The NNLS
    optimum is the best least-squares fit on a support whose coefficients are all >= 0, so every
    one of the 31 non-empty supports is solved at once and the best feasible one kept.

    Args:
        A: Normal matrices, shape (..., 5, 5).
        rhs: Right-hand sides, shape (..., 5).
        rr: Squared norm of the target.

    Returns:
        Minimal residual sum of squares, shape (...).
    """
    S = _SUBSETS.reshape((-1,) + (1,) * (A.ndim - 2) + (5,))
    keep = S[..., :, None] & S[..., None, :]
    eye = np.eye(5, dtype=bool)
    As = np.where(keep, A[None], np.where(eye, 1.0, 0.0))
    bs = np.where(S, rhs[None], 0.0)
    x = np.linalg.solve(As, bs[..., None])[..., 0]
    sse = rr - np.einsum("...i,...i->...", x, bs)
    feasible = np.all(x >= -1e-12 * np.abs(x).max(), axis=-1)
    sse = np.where(feasible, sse, np.inf)
    return np.asarray(np.minimum(sse.min(axis=0), rr))


def _least_squares(joints: list[_Joint], cols: list[Array], layout: _Layout, z_nom: Array,
                   scale: Array) -> Array:
    """Linear least squares over all joints, ridge-regularised toward nominal (rank defects)."""
    p = layout.size
    G = np.zeros((p, p))
    g = np.zeros(p)
    for j, (jt, A) in enumerate(zip(joints, cols, strict=True)):
        idx = layout.joint(j)
        As = A * scale[idx]
        G[np.ix_(idx, idx)] += As.T @ As
        g[idx] += As.T @ (jt.b - A @ z_nom[idx])
    G += 1e-9 * np.trace(G) / p * np.eye(p)
    return np.asarray(z_nom + scale * np.linalg.solve(G, g))


def identify_consistent(obs: Observations, config: ConsistentConfig | None = None
                        ) -> ConsistentOutcome:
    """Calibrate with variable projection and a physically consistent convex inner problem.

    Raises:
        SolverError: The inner problem is infeasible (naming the link whose bounds cannot be met)
            or the solver fails. There is no silent fallback.
    """
    cfg = config if config is not None else ConsistentConfig()
    t0 = time.perf_counter()
    robot = obs.robot
    n = robot.n
    layout = _Layout(n)
    joints = [_Joint(obs, j) for j in range(n)]
    tmax, vmax, R = robot.max_torque, robot.velocity_limit, robot.gear_ratio
    phi_nom = obs.x_nominal[: 10 * n]
    z_nom = np.concatenate([phi_nom, robot.reflected_rotor_inertia, np.zeros(5 * n)])
    phi_scale = np.concatenate([np.full(10, max(float(np.max(np.abs(phi_nom[10 * k:10 * k + 10]))),
                                                1e-3)) for k in range(n)])
    scale = np.concatenate([phi_scale, np.maximum(robot.reflected_rotor_inertia, 1e-3 * tmax / 10),
                            np.tile(0.01 * tmax, 3), 0.01 * tmax / vmax, 0.01 * tmax])
    grids_m = [np.geomspace(0.5, R[j] * vmax[j], cfg.grid) for j in range(n)]
    grids_g = [np.geomspace(1e-3 * vmax[j], vmax[j], cfg.grid) for j in range(n)]
    vel = [(float(np.sqrt(gm[0] * gm[-1])), float(np.sqrt(gg[0] * gg[-1])))
           for gm, gg in zip(grids_m, grids_g, strict=True)]
    # Warm start: alternate the per-joint grids with unconstrained least squares (cheap).
    z = z_nom
    for _ in range(cfg.alternations):
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = _least_squares(joints, cols, layout, z_nom, scale)
        vel = [_best_stribeck(jt, jt.b - jt.K @ z[: 10 * n], grids_m[j], grids_g[j])
               for j, jt in enumerate(joints)]
    # Then alternate with the constrained inner problem: the link torque the grids see is a
    # physically consistent one, so friction does not compensate unphysical link parameters.
    solves = 0
    for _ in range(cfg.constrained_alternations):
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = _inner_problem(obs, joints, cols, layout, z_nom, scale, cfg)
        solves += 1
        new_vel = [_best_stribeck(jt, jt.b - jt.K @ z[: 10 * n], grids_m[j], grids_g[j])
                   for j, jt in enumerate(joints)]
        if new_vel == vel:
            break
        vel = new_vel
    else:
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = _inner_problem(obs, joints, cols, layout, z_nom, scale, cfg)
        solves += 1
    phi, M = _closest_to_nominal(obs, z, z_nom, scale, cfg)
    f = z[11 * n:15 * n].reshape(4, n)
    params = DriveModelParameters(
        phi=phi, friction_model=FrictionModel.STRIBECK, rotor_inertia=M,
        stribeck=StribeckParameters(f1=f[0], f2=f[1], qd_sm=np.array([v[0] for v in vel]),
                                    f3=f[2], qd_sg=np.array([v[1] for v in vel]), f4=f[3]),
        offset=z[15 * n:].copy())
    return ConsistentOutcome(params=params, min_pseudo_inertia_eig=min_pseudo_inertia_eigenvalues(
        phi), iterations=cfg.alternations + 2, runtime_s=time.perf_counter() - t0)


_SLACK = 1e-6  # relative tolerance of the closest-to-nominal step on the bounds


def _link_constraints(obs: Observations, phi: cp.Expression, cfg: ConsistentConfig,
                      links: range | None = None, margin_factor: float = 1.0,
                      slack: float = 0.0) -> list[cp.Constraint]:
    """Pseudo-inertia ⪰ margin and the optional bounds, per link.

    ``slack`` widens every bound outward by slack·(link scale). The closest-to-nominal step uses
    a tiny slack (and half the PSD margin of the inner problem), so a solution that the solver
    left on an active bound within its tolerance stays feasible for the second step.
    """
    n = obs.robot.n
    phi_nom = obs.x_nominal[: 10 * n]
    out: list[cp.Constraint] = []
    for k in links if links is not None else range(n):
        link_scale = max(float(np.max(np.abs(phi_nom[10 * k:10 * k + 10]))), 1e-3)
        margin = margin_factor * cfg.margin
        p = [phi[10 * k + i] for i in range(10)]
        m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = p
        half = 0.5 * (ixx + iyy + izz)
        J = cp.bmat([[half - ixx, -ixy, -ixz, hx], [-ixy, half - iyy, -iyz, hy],
                     [-ixz, -iyz, half - izz, hz], [hx, hy, hz, m]]) / link_scale
        out.append(0.5 * (J + J.T) >> margin * np.eye(4))  # scaled: well-conditioned LMIs
        if cfg.bound is not None:
            b = link_bounds(phi_nom[10 * k:10 * k + 10], cfg.bound)
            h = cp.hstack([hx, hy, hz])
            inertia = cp.hstack([ixx, ixy, iyy, ixz, iyz, izz])
            e = slack * link_scale
            w = 1.0 / link_scale
            out += [w * m >= w * (b.mass[0] - e), w * m <= w * (b.mass[1] + e),
                    w * h >= w * (m * b.com_lower - e), w * h <= w * (m * b.com_upper + e),
                    w * inertia >= w * (b.inertia_lower - e),
                    w * inertia <= w * (b.inertia_upper + e)]
    return out


def _solve(problem: cp.Problem, what: str) -> None:
    try:
        with warnings.catch_warnings():
            # "optimal_inaccurate" is not trusted blindly: callers verify the solution.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL)
    except cp.SolverError as e:
        raise SolverError(f"Clarabel failed on the {what}: {e}", field="solver",
                          expected="a solvable problem (check the bounds and the data)") from e


def _verify(obs: Observations, phi: Array, rotor: Array, cfg: ConsistentConfig, status: str,
            what: str) -> None:
    """Check a solution really is physically consistent and within the bounds.

    Raises:
        SolverError: Naming the first link that violates its constraints.
    """
    n = obs.robot.n
    phi_nom = obs.x_nominal[: 10 * n]
    eig = min_pseudo_inertia_eigenvalues(phi)
    for k in range(n):
        name = obs.robot.joint_names[k]
        scale = max(float(np.max(np.abs(phi_nom[10 * k:10 * k + 10]))), 1e-3)
        bad = eig[k] < 0.0
        if cfg.bound is not None and not bad:
            b = link_bounds(phi_nom[10 * k:10 * k + 10], cfg.bound)
            p = phi[10 * k:10 * k + 10]
            tol = 10.0 * _SLACK * scale
            bad = bool(p[0] < b.mass[0] - tol or p[0] > b.mass[1] + tol
                       or np.any(p[1:4] < p[0] * b.com_lower - tol)
                       or np.any(p[1:4] > p[0] * b.com_upper + tol)
                       or np.any(p[4:] < b.inertia_lower - tol)
                       or np.any(p[4:] > b.inertia_upper + tol))
        if bad:
            raise SolverError(f"the {what} returned an invalid solution for link '{name}' "
                              f"(status '{status}', min pseudo-inertia eigenvalue {eig[k]:.3g})",
                              field=f"links.{name}", value=status,
                              expected="a physically consistent solution within the bounds")
    if np.any(rotor < -1e-9 * max(1.0, float(np.max(np.abs(rotor))))):
        raise SolverError(f"the {what} returned a negative rotor inertia (status '{status}')",
                          field="rotor_inertia", value=rotor.tolist(), expected=">= 0")


def _diagnose(obs: Observations, cfg: ConsistentConfig, status: str, what: str) -> SolverError:
    """Find which link's constraints alone are infeasible, to name the cause."""
    n = obs.robot.n
    for k in range(n):
        v = cp.Variable(10 * n)
        prob = cp.Problem(cp.Minimize(0), _link_constraints(obs, v, cfg, range(k, k + 1)))
        try:
            prob.solve(solver=cp.CLARABEL)
        except cp.SolverError:
            continue
        if prob.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            return SolverError(
                f"link '{obs.robot.joint_names[k]}': its bounds (±{100 * (cfg.bound or 0):.0f} % "
                "around nominal) exclude every physically consistent inertia (pseudo-inertia "
                f"⪰ {cfg.margin:g} relative)", field=f"links.{obs.robot.joint_names[k]}",
                value=status, expected="wider bounds (--bound) or a corrected URDF")
    return SolverError(f"the {what} ended with status '{status}'", field="solver", value=status,
                       expected="'optimal'; try --bound none or check the data")


def _inner_problem(obs: Observations, joints: list[_Joint], cols: list[Array], layout: _Layout,
                   z_nom: Array, scale: Array, cfg: ConsistentConfig) -> Array:
    """The convex problem for fixed Stribeck velocities, on QR-compressed data."""
    n = obs.robot.n
    u = cp.Variable(layout.size)
    z = z_nom + cp.multiply(scale, u)
    terms = []
    for j, (jt, A) in enumerate(zip(joints, cols, strict=True)):
        idx = layout.joint(j)
        As = A * scale[idx]
        r0 = jt.b - A @ z_nom[idx]               # residual = r0 − As·u_j
        mean_a, mean_r = As.mean(axis=0), float(r0.mean())
        if cfg.objective == "J":
            Rf = np.linalg.qr(np.column_stack([As - mean_a, r0 - mean_r]), mode="r")
            Rf = Rf / np.sqrt(jt.N)
            mean = mean_r - mean_a @ u[idx]
            std = cp.norm(Rf @ cp.hstack([-u[idx], np.ones(1)]), 2)
            terms.append(cp.abs(mean) + cfg.k_omega * std)
        else:
            Rf = np.linalg.qr(np.column_stack([As, r0]), mode="r")
            terms.append(cp.sum_squares(Rf @ cp.hstack([-u[idx], np.ones(1)])) / jt.N)
    cons = [*_link_constraints(obs, z[: 10 * n], cfg, margin_factor=2.0),
            z[10 * n:15 * n] >= 0]
    prob = cp.Problem(cp.Minimize(cp.sum(cp.hstack(terms))), cons)
    _solve(prob, "inner problem")
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or u.value is None:
        raise _diagnose(obs, cfg, str(prob.status), "inner problem")
    out = np.asarray(z_nom + scale * u.value)
    _verify(obs, out[: 10 * n], out[10 * n:11 * n], cfg, str(prob.status), "inner problem")
    return out


def _closest_to_nominal(obs: Observations, z: Array, z_nom: Array, scale: Array,
                        cfg: ConsistentConfig) -> tuple[Array, Array]:
    """Consistent standard parameters and rotor inertias closest to nominal with the same base
    parameters as ``z``."""
    n = obs.robot.n
    C = obs.base_aug.combination
    x_star = z[: 11 * n]
    s = scale[: 11 * n]
    # Parameter sets with the same base parameters: x = x* + S·N·w, N spanning null(C·S).
    # Searching w alone satisfies C·x = C·x* exactly, with no ill-conditioned equality rows.
    N = scipy.linalg.null_space(C * s)
    w = cp.Variable(N.shape[1])
    x = x_star + cp.multiply(s, N @ w)
    cons = [*_link_constraints(obs, x[: 10 * n], cfg, slack=_SLACK),
            x[10 * n:] >= -_SLACK * s[10 * n:]]
    # The (equivalent) norm objective is numerically better behaved in Clarabel than its square.
    prob = cp.Problem(cp.Minimize(cp.norm((x_star - z_nom[: 11 * n]) / s + N @ w)), cons)
    _solve(prob, "closest-to-nominal problem")
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or w.value is None:
        raise _diagnose(obs, cfg, str(prob.status), "closest-to-nominal problem")
    out = np.asarray(x_star + s * (N @ w.value))
    _verify(obs, out[: 10 * n], out[10 * n:], cfg, str(prob.status), "closest-to-nominal problem")
    return out[: 10 * n], out[10 * n:]
