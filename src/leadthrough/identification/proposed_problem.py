"""The search problem of the paper's calibration (Section III-A.3): the decision vector, its
bounds (eq. 37) and the objective J of eq. 26 on the full model of eq. 21, for a whole
population at once.

Decision vector X = {φ, f1, f2, q̇sm, f3, q̇sg, f4, M_j}. The link part is searched in physical
coordinates per link (mass m, CoM c, inertia about the CoM I_c), where the paper's bounds are
boxes:

* mass within ±30 % of nominal, CoM within ±30 % of max|c_nominal|, each inertia entry within
  ±30 % of max|I_c,nominal| (eq. 37);
* I_c positive definite (Step 5), enforced as a penalty;
* parameters with no effect on the joint torques (zero regressor columns, e.g. all of link 1 but
  its Izz) are held at nominal (Step 2);
* f1..f4 > 0 and 0 < q̇s < max (the motor speed limit for q̇sm, the joint speed limit for q̇sg);
* M_j >= 0. Eq. 24 prints "(M_j)_ii = 0", which reads as a typo for a non-negativity bound; we
  treat it so.

The search (:func:`~leadthrough.identification.proposed.identify_proposed`) runs in the unit
coordinates of :meth:`ProposedProblem.from_unit`; the polish uses the smoothed J and its exact
gradient (:meth:`ProposedProblem.unit_value_and_gradient`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import StribeckParameters, stribeck_decay
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.errors import check_fields
from leadthrough.identification.observations import Observations

__all__ = ["ProposedConfig", "ProposedProblem"]

Array = NDArray[np.float64]
_FRICTION = ("f1", "f2", "qd_sm", "f3", "qd_sg", "f4", "M")


@dataclass(frozen=True)
class ProposedConfig:
    """Settings of the paper's method.

    Attributes:
        bound: Relative bound around nominal of eq. 37 (0.3 = ±30 %).
        k_omega: Weight K_ω of the std term in J.
        max_rate_hz: Data are subsampled to at most this rate for the search [Hz].
        population: Population size of the global search.
        generations: Generations of the global search.
        polish_iterations: L-BFGS-B iterations after the search (0: none).
        max_friction: Upper bound of f1, f2, f3 as a fraction of the joint's max torque.
        seed: Seed of the search.
    """

    bound: float = 0.3
    k_omega: float = 1.0
    max_rate_hz: float = 100.0
    population: int = 60
    generations: int = 150
    polish_iterations: int = 300
    max_friction: float = 0.2
    seed: int = 0

    def __post_init__(self) -> None:
        checks = [
            ("bound", 0 < self.bound < 1, "0 < bound < 1"),
            ("k_omega", self.k_omega >= 0, ">= 0"),
            ("max_rate_hz", self.max_rate_hz > 0, "> 0 Hz"),
            ("population", self.population >= 5, ">= 5"),
            ("generations", self.generations >= 1, ">= 1"),
            ("polish_iterations", self.polish_iterations >= 0, ">= 0"),
            ("max_friction", 0 < self.max_friction <= 1, "in (0, 1]"),
            ("seed", self.seed >= 0, ">= 0"),
        ]
        check_fields("proposed", self, checks)


def _physical(phi_link: Array) -> tuple[float, Array, Array]:
    m = float(phi_link[0])
    c = phi_link[1:4] / m
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz = phi_link[4:]
    I_o = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
    I_c = I_o - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return m, c, I_c


class ProposedProblem:
    """Vectorised J for a population of decision vectors.

    Args:
        obs: Regressors of the processed identification data.
        cfg: Settings of the paper's method.
    """

    def __init__(self, obs: Observations, cfg: ProposedConfig) -> None:
        robot = obs.robot
        self.n = n = robot.n
        self.cfg = cfg
        data = obs.data
        step = max(1, round(data.rate_hz / cfg.max_rate_hz))
        sel = slice(None, None, step)
        self.used = data.moving[sel]
        self.w = self.used.astype(float)
        self.cnt = np.maximum(self.w.sum(axis=0), 1.0)
        self.tau = data.torque[sel]
        self.qd = data.qd[sel]
        self.qdd = data.qdd[sel]
        self.sgn = np.sign(self.qd)
        self.R = robot.gear_ratio
        self.Kb = obs.base_link.regressor(obs.K[sel])         # (N, n, r)
        self.C = obs.base_link.combination                  # (r, 10n)
        # Nominal physical parameters and bounds (eq. 37).
        phi_nom = obs.x_nominal[: 10 * n]
        lo: list[float] = []
        hi: list[float] = []
        x0: list[float] = []
        self.link_free: list[NDArray[np.intp]] = []
        self.phys_nom = np.zeros((n, 10))
        col_norm = np.linalg.norm(obs.K[sel].reshape(-1, 10 * n), axis=0)
        b = cfg.bound
        for k in range(n):
            m, c, I_c = _physical(phi_nom[10 * k: 10 * k + 10])
            vec = np.array([m, *c, I_c[0, 0], I_c[0, 1], I_c[1, 1], I_c[0, 2], I_c[1, 2],
                            I_c[2, 2]])
            self.phys_nom[k] = vec
            half = np.concatenate([[b * m], np.full(3, b * np.max(np.abs(c))),
                                   np.full(6, b * np.max(np.abs(I_c)))])
            free = np.flatnonzero((col_norm[10 * k: 10 * k + 10] > 1e-9 * col_norm.max())
                                  & (half > 0))
            self.link_free.append(free)
            lo += list(vec[free] - half[free])
            hi += list(vec[free] + half[free])
            x0 += list(vec[free])
        self.n_link = len(x0)
        tmax, vmax = robot.max_torque, robot.velocity_limit
        M_nom = robot.reflected_rotor_inertia
        fr_lo = {"f1": 1e-6 * tmax, "f2": 1e-6 * tmax, "qd_sm": np.full(n, 0.1),
                 "f3": 1e-6 * tmax, "qd_sg": 1e-3 * vmax, "f4": 1e-9 * tmax / vmax,
                 "M": np.zeros(n)}
        fr_hi = {"f1": cfg.max_friction * tmax, "f2": cfg.max_friction * tmax,
                 "qd_sm": self.R * vmax, "f3": cfg.max_friction * tmax, "qd_sg": vmax,
                 "f4": 0.5 * tmax / vmax,
                 "M": np.where(M_nom > 0, 3.0 * M_nom, 1e-2 * tmax / robot.acceleration_limit)}
        fr_x0 = {"f1": 0.02 * tmax, "f2": 0.01 * tmax, "qd_sm": 0.1 * self.R * vmax,
                 "f3": 0.01 * tmax, "qd_sg": 0.1 * vmax, "f4": 0.02 * tmax / vmax, "M": M_nom}
        for name in _FRICTION:
            lo += list(fr_lo[name])
            hi += list(fr_hi[name])
            x0 += list(np.clip(fr_x0[name], fr_lo[name], fr_hi[name]))
        self.lo, self.hi, self.x0 = np.array(lo), np.array(hi), np.array(x0)
        # Search coordinates u ∈ [0, 1]^d: linear in the box, logarithmic for the Stribeck
        # velocities (they span decades).
        self.log = np.zeros(self.lo.size, dtype=bool)
        for name in ("qd_sm", "qd_sg"):
            k = self.n_link + _FRICTION.index(name) * n
            self.log[k: k + n] = True
        self._a = self.lo.copy()
        self._a[self.log] = np.log(self.lo[self.log])
        top = self.hi.copy()
        top[self.log] = np.log(self.hi[self.log])
        self._b = top - self._a
        self.i_scale = np.array([np.max(np.abs(self.phys_nom[k, 4:])) for k in range(n)])
        self.evaluations = 0

    # ------------------------------------------------------------------------- conversions
    def from_unit(self, U: Array) -> Array:
        """Decision vectors from search coordinates, (P, d) → (P, d)."""
        V = self._a + self._b * U
        V[..., self.log] = np.exp(V[..., self.log])
        return V

    def to_unit(self, X: Array) -> Array:
        """Search coordinates of decision vectors."""
        V = np.array(X, dtype=float)
        V[..., self.log] = np.log(V[..., self.log])
        return np.clip((V - self._a) / self._b, 0.0, 1.0)

    def unit_value_and_gradient(self, u: Array) -> tuple[float, Array]:
        """Smoothed J and its gradient in search coordinates."""
        x = self.from_unit(u[None, :])[0]
        value, grad = self.smooth_value_and_gradient(x)
        dxdu = np.where(self.log, x * self._b, self._b)
        return value, grad * dxdu

    def link_physical(self, X: Array) -> Array:
        """(P, n, 10) physical link parameters from decision vectors X (P, d)."""
        P = X.shape[0]
        phys = np.broadcast_to(self.phys_nom, (P, self.n, 10)).copy()
        pos = 0
        for k, free in enumerate(self.link_free):
            phys[:, k, free] = X[:, pos: pos + free.size]
            pos += free.size
        return phys

    @staticmethod
    def to_phi(phys: Array) -> Array:
        """(P, n, 10) physical → (P, 10n) standard parameters."""
        m = phys[..., 0]
        c = phys[..., 1:4]
        Ixx, Ixy, Iyy, Ixz, Iyz, Izz = (phys[..., 4 + i] for i in range(6))
        cx, cy, cz = c[..., 0], c[..., 1], c[..., 2]
        phi = np.stack([
            m, m * cx, m * cy, m * cz,
            Ixx + m * (cy**2 + cz**2), Ixy - m * cx * cy, Iyy + m * (cx**2 + cz**2),
            Ixz - m * cx * cz, Iyz - m * cy * cz, Izz + m * (cx**2 + cy**2),
        ], axis=-1)
        return phi.reshape(phys.shape[0], -1)

    def friction(self, X: Array) -> dict[str, Array]:
        """Friction and rotor parameters, each (P, n)."""
        out = {}
        pos = self.n_link
        for name in _FRICTION:
            out[name] = X[:, pos: pos + self.n]
            pos += self.n
        return out

    # ---------------------------------------------------------------------------- objective
    def objective(self, X: Array) -> Array:
        """Objective for a population X (P, d) → (P,)."""
        X = np.atleast_2d(X)
        self.evaluations += X.shape[0]
        phys = self.link_physical(X)
        beta = self.to_phi(phys) @ self.C.T                      # (P, r)
        tau = np.einsum("knr,pr->pkn", self.Kb, beta, optimize=True)
        fr = self.friction(X)
        s, qd = self.sgn, self.qd
        gm = stribeck_decay(self.R * qd / fr["qd_sm"][:, None, :]) * s
        gg = stribeck_decay(qd / fr["qd_sg"][:, None, :]) * s
        tau += (fr["f1"][:, None, :] * s + fr["f2"][:, None, :] * gm
                + fr["f3"][:, None, :] * gg + fr["f4"][:, None, :] * qd
                + fr["M"][:, None, :] * self.qdd)
        r = self.tau - tau                                       # (P, N, n)
        r *= self.w
        mean = r.sum(axis=1) / self.cnt
        sq = (r * r).sum(axis=1) / self.cnt
        std = np.sqrt(np.maximum(sq - mean**2, 0.0))
        J = np.abs(mean).sum(axis=1) + self.cfg.k_omega * std.sum(axis=1)
        # Step 5: inertia about the CoM positive definite (penalty, scaled per link).
        inertia = np.empty((X.shape[0], self.n, 3, 3))
        inertia[..., 0, 0] = phys[..., 4]
        inertia[..., 1, 1] = phys[..., 6]
        inertia[..., 2, 2] = phys[..., 9]
        inertia[..., 0, 1] = inertia[..., 1, 0] = phys[..., 5]
        inertia[..., 0, 2] = inertia[..., 2, 0] = phys[..., 7]
        inertia[..., 1, 2] = inertia[..., 2, 1] = phys[..., 8]
        lam = np.linalg.eigvalsh(inertia)[..., 0] / self.i_scale
        violation = np.maximum(1e-4 - lam, 0.0).sum(axis=1)
        return np.asarray(J + 1e3 * J.max() * violation)

    @staticmethod
    def phi_jacobian(phys: Array) -> Array:
        """∂φ/∂(m, c, I_c) per link, shape (n, 10, 10)."""
        n = phys.shape[0]
        Jc = np.zeros((n, 10, 10))
        m = phys[:, 0]
        cx, cy, cz = phys[:, 1], phys[:, 2], phys[:, 3]
        Jc[:, 0, 0] = 1.0
        for i, ci in enumerate((cx, cy, cz)):
            Jc[:, 1 + i, 0] = ci
            Jc[:, 1 + i, 1 + i] = m
        for row in range(4, 10):
            Jc[:, row, row] = 1.0
        # Ixx + m(cy²+cz²), Ixy − m cx cy, Iyy + m(cx²+cz²), Ixz − m cx cz, Iyz − m cy cz,
        # Izz + m(cx²+cy²)
        Jc[:, 4, 0], Jc[:, 4, 2], Jc[:, 4, 3] = cy**2 + cz**2, 2 * m * cy, 2 * m * cz
        Jc[:, 5, 0], Jc[:, 5, 1], Jc[:, 5, 2] = -cx * cy, -m * cy, -m * cx
        Jc[:, 6, 0], Jc[:, 6, 1], Jc[:, 6, 3] = cx**2 + cz**2, 2 * m * cx, 2 * m * cz
        Jc[:, 7, 0], Jc[:, 7, 1], Jc[:, 7, 3] = -cx * cz, -m * cz, -m * cx
        Jc[:, 8, 0], Jc[:, 8, 2], Jc[:, 8, 3] = -cy * cz, -m * cz, -m * cy
        Jc[:, 9, 0], Jc[:, 9, 1], Jc[:, 9, 2] = cx**2 + cy**2, 2 * m * cx, 2 * m * cy
        return Jc

    def smooth_value_and_gradient(self, x: Array, eps: float = 1e-6) -> tuple[float, Array]:
        """J with |mean| and std smoothed by ε [N·m], and its exact gradient (for the polish).

        With G_kj = −w_kj/cnt_j·(sgn(mean_j) + K_ω·(r_kj − mean_j)/std_j), ∂J/∂θ =
        Σ_kj G_kj·∂τ_model,kj/∂θ; the link part is chained through β = C·φ(m, c, I_c).
        """
        X = x[None, :]
        phys = self.link_physical(X)[0]
        beta = self.to_phi(phys[None])[0] @ self.C.T
        fr = {k: v[0] for k, v in self.friction(X).items()}
        s, qd, R = self.sgn, self.qd, self.R
        um = R * qd / fr["qd_sm"]
        ug = qd / fr["qd_sg"]
        gm = np.exp(-um**2) * s
        gg = np.exp(-ug**2) * s
        tau = (self.Kb @ beta + fr["f1"] * s + fr["f2"] * gm + fr["f3"] * gg
               + fr["f4"] * qd + fr["M"] * self.qdd)
        r = (self.tau - tau) * self.w
        mean = r.sum(axis=0) / self.cnt
        var = np.maximum((r * r).sum(axis=0) / self.cnt - mean**2, 0.0)
        abs_mean = np.sqrt(mean**2 + eps**2)
        std = np.sqrt(var + eps**2)
        value = float(abs_mean.sum() + self.cfg.k_omega * std.sum())
        G = -(self.w / self.cnt) * (mean / abs_mean + self.cfg.k_omega * (r - mean * self.w)
                                    / std)
        grad_beta = np.einsum("kn,knr->r", G, self.Kb, optimize=True)
        grad_phi = (self.C.T @ grad_beta).reshape(self.n, 10)
        grad_phys = np.einsum("lij,li->lj", self.phi_jacobian(phys), grad_phi)
        grads: list[Array] = [grad_phys[k, free] for k, free in enumerate(self.link_free)]
        grads += [
            (G * s).sum(axis=0),
            (G * gm).sum(axis=0),
            (G * fr["f2"] * gm * 2.0 * um**2 / fr["qd_sm"]).sum(axis=0),
            (G * gg).sum(axis=0),
            (G * fr["f3"] * gg * 2.0 * ug**2 / fr["qd_sg"]).sum(axis=0),
            (G * qd).sum(axis=0),
            (G * self.qdd).sum(axis=0),
        ]
        grad = np.concatenate(grads)
        # Step 5 penalty (positive-definite inertia about the CoM), differentiated through
        # the smallest eigenvalue: ∂λ/∂I = v·vᵀ.
        pen_w = 1e3 * value
        pos = 0
        for k, free in enumerate(self.link_free):
            p = phys[k]
            inertia_k = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
            lam, vec = np.linalg.eigh(inertia_k)
            viol = 1e-4 - lam[0] / self.i_scale[k]
            if viol > 0:
                value += pen_w * viol
                v = vec[:, 0]
                dI = -np.outer(v, v) / self.i_scale[k] * pen_w
                full = np.zeros(10)
                full[4:] = [dI[0, 0], 2 * dI[0, 1], dI[1, 1], 2 * dI[0, 2], 2 * dI[1, 2],
                            dI[2, 2]]
                grad[pos: pos + free.size] += full[free]
            pos += free.size
        return value, grad

    def params(self, x: Array) -> DriveModelParameters:
        X = x[None, :]
        phi = self.to_phi(self.link_physical(X))[0]
        fr = {k: v[0].copy() for k, v in self.friction(X).items()}
        return DriveModelParameters(
            phi=phi, friction_model=FrictionModel.STRIBECK, rotor_inertia=fr["M"],
            stribeck=StribeckParameters(f1=fr["f1"], f2=fr["f2"], qd_sm=fr["qd_sm"],
                                        f3=fr["f3"], qd_sg=fr["qd_sg"], f4=fr["f4"]))
