"""The convex problems of the consistent method (see :mod:`leadthrough.identification.consistent`).

* :func:`inner_problem`: for fixed Stribeck velocities, the paper's J (an SOCP) or least squares on
  QR-compressed data, under full physical consistency (pseudo-inertia LMIs), optional bounds
  around nominal, friction ≥ 0 (the load-dependent f_cL too, when fitted) and M_j ≥ 0.
* :func:`closest_to_nominal`: among all consistent parameter sets with the same base parameters,
  the one closest to nominal.

Both are solved with cvxpy + Clarabel. Failures raise :class:`SolverError` naming the link or the
constraint; "inaccurate" solutions are accepted only after :func:`verify` checks them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from leadthrough.errors import LeadthroughError, check_fields
from leadthrough.identification.consistency import link_bounds, min_pseudo_inertia_eigenvalues
from leadthrough.identification.observations import Observations

__all__ = [
    "ConsistentConfig",
    "DecisionLayout",
    "FrictionBand",
    "SolverError",
    "closest_to_nominal",
    "inner_problem",
]

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
        sweep_tolerance: With a friction sweep, the identified curve stays within this
            fraction of every measured point [-].
    """

    bound: float | None = 0.3
    objective: str = "J"
    k_omega: float = 1.0
    margin: float = 1e-5
    grid: int = 16
    alternations: int = 3
    constrained_alternations: int = 4
    sweep_tolerance: float = 0.03

    def __post_init__(self) -> None:
        checks = [
            ("bound", self.bound is None or 0 < self.bound < 1, "None or 0 < bound < 1"),
            ("objective", self.objective in ("J", "ls"), "'J' or 'ls'"),
            ("k_omega", self.k_omega >= 0, ">= 0"),
            ("margin", self.margin >= 0, ">= 0"),
            ("grid", self.grid >= 2, ">= 2"),
            ("alternations", self.alternations >= 1, ">= 1"),
            ("constrained_alternations", self.constrained_alternations >= 1, ">= 1"),
            ("sweep_tolerance", 0 <= self.sweep_tolerance < 1, "0 <= tolerance < 1"),
        ]
        check_fields("consistent", self, checks)


@dataclass(frozen=True)
class FrictionBand:
    """Measured steady friction of one joint that the identified curve must pass near.

    Attributes:
        G: Eq. 15 columns [1, e_m, e_g, q̇] at the measured speeds, shape (K, 4).
        friction: Measured friction [N·m], shape (K,).
        tolerance: Allowed |curve − measured| [N·m], shape (K,).
    """

    G: Array
    friction: Array
    tolerance: Array


class DecisionLayout:
    """Index layout of z = [φ (10n), M (n), f1 (n), f2 (n), f3 (n), f4 (n), τ_0 (n)], and
    f_cL (n) of the load-dependent Coulomb friction when ``load`` (its upper bound per joint,
    shape (n,)) is given."""

    def __init__(self, n: int, load: NDArray[np.float64] | None = None) -> None:
        self.n = n
        self.load = load
        self.size = (16 if load is None else 17) * n

    def joint(self, j: int) -> NDArray[np.intp]:
        n = self.n
        drive = 6 if self.load is None else 7
        return np.r_[np.arange(10 * n), 10 * n + j + n * np.arange(drive)].astype(np.intp)

    def bounds(self, z: cp.Expression) -> list[cp.Constraint]:
        """M_j, f1..f4 >= 0 (and 0 <= f_cL <= its bound)."""
        n = self.n
        if self.load is None:
            return [z[10 * n:15 * n] >= 0]
        return [z[10 * n:15 * n] >= 0, z[16 * n:17 * n] >= 0, z[16 * n:17 * n] <= self.load]


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
            what: str, rotor_scale: Array) -> None:
    """Check a solution really is physically consistent and within the bounds (rotor inertias
    >= 0 to the problem's tolerance, 10·_SLACK of each one's variable scale ``rotor_scale``).

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
    if np.any(rotor < -10.0 * _SLACK * np.abs(rotor_scale)):
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


def inner_problem(obs: Observations, targets: list[Array], cols: list[Array],
                  layout: DecisionLayout, z_nom: Array, scale: Array, cfg: ConsistentConfig,
                  friction_bands: list[FrictionBand] | None = None) -> Array:
    """The convex problem for fixed Stribeck velocities, on QR-compressed data.

    ``friction_bands`` (one per joint) keep each joint's friction curve near measured points.
    """
    n = obs.robot.n
    u = cp.Variable(layout.size)
    z = z_nom + cp.multiply(scale, u)
    terms = []
    for j, (b, A) in enumerate(zip(targets, cols, strict=True)):
        idx = layout.joint(j)
        As = A * scale[idx]
        r0 = b - A @ z_nom[idx]               # residual = r0 − As·u_j
        mean_a, mean_r = As.mean(axis=0), float(r0.mean())
        if cfg.objective == "J":
            Rf = np.linalg.qr(np.column_stack([As - mean_a, r0 - mean_r]), mode="r")
            Rf = Rf / np.sqrt(b.size)
            mean = mean_r - mean_a @ u[idx]
            std = cp.norm(Rf @ cp.hstack([-u[idx], np.ones(1)]), 2)
            terms.append(cp.abs(mean) + cfg.k_omega * std)
        else:
            Rf = np.linalg.qr(np.column_stack([As, r0]), mode="r")
            terms.append(cp.sum_squares(Rf @ cp.hstack([-u[idx], np.ones(1)])) / b.size)
    cons = [*_link_constraints(obs, z[: 10 * n], cfg, margin_factor=2.0),
            *layout.bounds(z)]
    for j, band in enumerate(friction_bands or []):
        f = z[11 * n + j + n * np.arange(4)]
        cons += [band.G @ f <= band.friction + band.tolerance,
                 band.G @ f >= band.friction - band.tolerance]
    prob = cp.Problem(cp.Minimize(cp.sum(cp.hstack(terms))), cons)
    _solve(prob, "inner problem")
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or u.value is None:
        raise _diagnose(obs, cfg, str(prob.status), "inner problem")
    out = np.asarray(z_nom + scale * u.value)
    _verify(obs, out[: 10 * n], out[10 * n:11 * n], cfg, str(prob.status), "inner problem",
            scale[10 * n:11 * n])
    out[10 * n:11 * n] = np.maximum(out[10 * n:11 * n], 0.0)  # solver tolerance, verified above
    return out


def closest_to_nominal(obs: Observations, z: Array, z_nom: Array, scale: Array,
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
    _verify(obs, out[: 10 * n], out[10 * n:], cfg, str(prob.status), "closest-to-nominal problem",
            s[10 * n:])
    return out[: 10 * n], np.maximum(out[10 * n:], 0.0)  # solver tolerance, verified above
