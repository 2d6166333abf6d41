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
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import (
    StribeckParameters,
    load_friction_column,
    stribeck_decay,
    stribeck_shapes,
)
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.errors import DataError
from leadthrough.identification.consistency import min_pseudo_inertia_eigenvalues
from leadthrough.identification.consistent_convex import (
    ConsistentConfig,
    DecisionLayout,
    FrictionBand,
    SolverError,
    closest_to_nominal,
    inner_problem,
)
from leadthrough.identification.friction_sweep import SweepFit
from leadthrough.identification.load_friction import LoadTerm
from leadthrough.identification.observations import Observations

__all__ = ["ConsistentConfig", "ConsistentOutcome", "SolverError", "identify_consistent"]

Array = NDArray[np.float64]


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
    """One joint's used equations (and its load-friction column |τ_load|·sgn(q̇), if given)."""

    def __init__(self, obs: Observations, j: int, load: LoadTerm | None) -> None:
        used = obs.used[:, j]
        self.K = obs.K[used, j, :]
        self.qdd = obs.data.qdd[used, j]
        self.qd = obs.data.qd[used, j]
        self.s = np.sign(self.qd)
        self.b = obs.data.torque[used, j]
        self.N = int(used.sum())
        self.R = float(obs.robot.gear_ratio[j])
        self.load = (None if load is None
                     else load_friction_column(self.qd, load.torque[used, j])
                     if load.upper[j] > 0 else np.zeros(self.N))

    def drive_target(self, z: Array, layout: DecisionLayout, j: int) -> Array:
        """The torque left for the drive's M_j, Stribeck and offset terms: b − K·φ (− f_cL·load
        column), the link (and load-friction) part held at ``z``."""
        r = self.b - self.K @ z[: 10 * layout.n]
        if self.load is not None:
            r = r - z[16 * layout.n + j] * self.load
        return r

    def stribeck(self, qd_sm: Array, qd_sg: Array) -> tuple[Array, Array]:
        """Columns exp(−(R q̇/q̇sm)²)·sgn and exp(−(q̇/q̇sg)²)·sgn, shapes (G, N)."""
        gm = stribeck_decay(self.R * self.qd[None, :] / np.atleast_1d(qd_sm)[:, None])
        gg = stribeck_decay(self.qd[None, :] / np.atleast_1d(qd_sg)[:, None])
        return gm * self.s, gg * self.s

    def columns(self, qd_sm: float, qd_sg: float) -> Array:
        """[K, q̈, sgn, g_m, g_g, q̇, 1] (and the load column), shape (N, 10n + 6 (+ 1))."""
        gm, gg = self.stribeck(np.array([qd_sm]), np.array([qd_sg]))
        cols = [self.K, self.qdd, self.s, gm[0], gg[0], self.qd, np.ones(self.N)]
        if self.load is not None:
            cols.append(self.load)
        return np.column_stack(cols)


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


def _least_squares(joints: list[_Joint], cols: list[Array], layout: DecisionLayout, z_nom: Array,
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


def _nominal_and_scale(obs: Observations, layout: DecisionLayout) -> tuple[Array, Array]:
    """z at nominal (CAD links, datasheet rotor inertia, no friction, no offset) and the scale
    of each entry of z (the inner problem's variables are (z − z_nom)/scale)."""
    robot, n = obs.robot, layout.n
    tmax, vmax = robot.max_torque, robot.velocity_limit
    phi_nom = obs.x_nominal[: 10 * n]
    extra = 0 if layout.load is None else n
    z_nom = np.concatenate([phi_nom, robot.reflected_rotor_inertia, np.zeros(5 * n + extra)])
    phi_scale = np.concatenate([np.full(10, max(float(np.max(np.abs(phi_nom[10 * k:10 * k + 10]))),
                                                1e-3)) for k in range(n)])
    scale = np.concatenate([phi_scale, np.maximum(robot.reflected_rotor_inertia, 1e-3 * tmax / 10),
                            np.tile(0.01 * tmax, 3), 0.01 * tmax / vmax, 0.01 * tmax,
                            np.full(extra, _LOAD_FRICTION_SCALE)])
    return z_nom, scale


#: Scale of f_cL in the inner problem's variables [-] (published values are a few percent).
_LOAD_FRICTION_SCALE = 0.01


def identify_consistent(obs: Observations, config: ConsistentConfig | None = None,
                        sweep: SweepFit | None = None, load: LoadTerm | None = None
                        ) -> ConsistentOutcome:
    """Calibrate with variable projection and a physically consistent convex inner problem.

    Args:
        obs: Observations of the excitation recording.
        config: Settings.
        sweep: Steady friction measured by a constant-velocity sweep (see
            :mod:`leadthrough.identification.friction_sweep`), or None. When given, the Stribeck
            velocities are the sweep's (no grid) and the friction curve must stay within
            ``config.sweep_tolerance`` of the sweep's fitted curve at every measured speed;
            within that band the excitation data decide. The excitation hardly visits low
            speeds, and where it does (reversals) the friction is not on its steady curve: the
            sweep is what hand guiding needs.
        load: τ_load at the samples and the bound of f_cL, to fit the load-dependent Coulomb
            friction 0 <= f_cL <= bound too (its column |τ_load|·sgn(q̇),
            :mod:`leadthrough.identification.load_friction`); None: none. Not with a sweep.

    Raises:
        SolverError: The inner problem is infeasible (naming the link whose bounds cannot be met)
            or the solver fails. There is no silent fallback.
        DataError: A load torque together with a sweep.
    """
    cfg = config if config is not None else ConsistentConfig()
    t0 = time.perf_counter()
    robot = obs.robot
    n = robot.n
    if sweep is not None and load is not None:
        raise DataError("the load-dependent friction is not fitted with a friction sweep",
                        field="load", expected="None when a sweep is given")
    layout = DecisionLayout(n, load=None if load is None else load.upper)
    joints = [_Joint(obs, j, load) for j in range(n)]
    vmax, R = robot.velocity_limit, robot.gear_ratio
    z_nom, scale = _nominal_and_scale(obs, layout)
    if sweep is not None:
        return _with_measured_friction(obs, joints, layout, z_nom, scale, cfg, sweep, t0)
    grids_m = [np.geomspace(0.5, R[j] * vmax[j], cfg.grid) for j in range(n)]
    grids_g = [np.geomspace(1e-3 * vmax[j], vmax[j], cfg.grid) for j in range(n)]
    vel = [(float(np.sqrt(gm[0] * gm[-1])), float(np.sqrt(gg[0] * gg[-1])))
           for gm, gg in zip(grids_m, grids_g, strict=True)]
    # Warm start: alternate the per-joint grids with unconstrained least squares (cheap).
    z = z_nom
    for _ in range(cfg.alternations):
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = _least_squares(joints, cols, layout, z_nom, scale)
        vel = [_best_stribeck(jt, jt.drive_target(z, layout, j), grids_m[j], grids_g[j])
               for j, jt in enumerate(joints)]
    # Then alternate with the constrained inner problem: the link torque the grids see is a
    # physically consistent one, so friction does not compensate unphysical link parameters.
    solves = 0
    for _ in range(cfg.constrained_alternations):
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = inner_problem(obs, [jt.b for jt in joints], cols, layout, z_nom, scale, cfg)
        solves += 1
        new_vel = [_best_stribeck(jt, jt.drive_target(z, layout, j), grids_m[j], grids_g[j])
                   for j, jt in enumerate(joints)]
        if new_vel == vel:
            break
        vel = new_vel
    else:
        cols = [jt.columns(*vel[j]) for j, jt in enumerate(joints)]
        z = inner_problem(obs, [jt.b for jt in joints], cols, layout, z_nom, scale, cfg)
        solves += 1
    f = z[11 * n:15 * n].reshape(4, n)
    stribeck = StribeckParameters(f1=f[0], f2=f[1], qd_sm=np.array([v[0] for v in vel]),
                                  f3=f[2], qd_sg=np.array([v[1] for v in vel]), f4=f[3])
    return _outcome(obs, z, z_nom, scale, cfg, stribeck, cfg.alternations + solves, t0,
                    layout)


def _outcome(obs: Observations, z: Array, z_nom: Array, scale: Array, cfg: ConsistentConfig,
             stribeck: StribeckParameters, iterations: int, t0: float, layout: DecisionLayout
             ) -> ConsistentOutcome:
    """Standard parameters closest to nominal, packed with the friction and offsets (and f_cL,
    clipped to its bounds against the solver's tolerance)."""
    n = obs.robot.n
    phi, M = closest_to_nominal(obs, z, z_nom, scale, cfg)
    fl = (np.clip(z[16 * n:17 * n], 0.0, layout.load) if layout.load is not None
          else np.zeros(0))
    params = DriveModelParameters(
        phi=phi, friction_model=FrictionModel.STRIBECK, rotor_inertia=M, stribeck=stribeck,
        offset=z[15 * n:16 * n].copy(), load_friction=fl)
    return ConsistentOutcome(params=params, min_pseudo_inertia_eig=min_pseudo_inertia_eigenvalues(
        phi), iterations=iterations, runtime_s=time.perf_counter() - t0)


def _with_measured_friction(obs: Observations, joints: list[_Joint], layout: DecisionLayout,
                            z_nom: Array, scale: Array, cfg: ConsistentConfig, sweep: SweepFit,
                            t0: float) -> ConsistentOutcome:
    """One inner problem with the Stribeck velocities of the sweep and the friction curve held
    within ``cfg.sweep_tolerance`` of the sweep's fitted curve at every measured speed."""
    n = obs.robot.n
    st = sweep.params
    R = obs.robot.gear_ratio
    bands = []
    for j in range(n):
        v = sweep.points.speed[j][:, None]                   # > 0: every sign is +1
        sgn, motor, gear = stribeck_shapes(v, R[j:j + 1], st.qd_sm[j:j + 1], st.qd_sg[j:j + 1])
        G = np.column_stack([sgn, motor, gear, v])
        f = G @ np.array([st.f1[j], st.f2[j], st.f3[j], st.f4[j]])
        bands.append(FrictionBand(G, f, cfg.sweep_tolerance * np.abs(f)))
    cols = [jt.columns(float(st.qd_sm[j]), float(st.qd_sg[j])) for j, jt in enumerate(joints)]
    z = inner_problem(obs, [jt.b for jt in joints], cols, layout, z_nom, scale, cfg,
                      friction_bands=bands)
    f = z[11 * n:15 * n].reshape(4, n)
    stribeck = StribeckParameters(f1=f[0], f2=f[1], qd_sm=st.qd_sm.copy(), f3=f[2],
                                  qd_sg=st.qd_sg.copy(), f4=f[3])
    return _outcome(obs, z, z_nom, scale, cfg, stribeck, 1, t0, layout)
