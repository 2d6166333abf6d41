"""Presliding length z₀ of each drive's friction, and how fast the friction carried at rest
relaxes, from a presliding test (no link model).

Input: a recording of out-and-back moves between rests at one configuration, with no external
force (:func:`leadthrough.excitation.presliding.design_presliding_test`, but any recording with
such moves, no faster than the estimator's ``slow_command_velocity``, works). Per joint:

1. **Rests.** A rest is a stretch where every joint stays within ``still_band_counts`` encoder
   counts for ``still_window_s``; its last ``still_window_s`` are averaged. Two consecutive
   rests at the same configuration (within ``same_configuration``) form a *pair*: gravity and
   the drives' offset are the same in both, so the change of joint torque is the change of the
   friction (the small gravity change of a drive that did not return exactly is removed with
   the nominal model).
2. **Model.** The friction at rest is a Dahl state: F = g·s, with s ∈ [−1, 1] driven by the
   joint's displacement, ds = (sgn(dq) − s)·|dq|/z₀, and relaxing toward zero at the rate r,
   ds = −r·s·dt (:func:`dahl_states`, the estimator's friction at rest or creeping,
   :func:`leadthrough.dynamics.presliding.presliding_friction_step`). The encoder
   goes through a play operator of ``play_counts`` counts first, as in the estimator:
   quantisation chatter at rest would otherwise wear the state down.
3. **Why r.** A servo that holds a joint still dithers it, far below one encoder count, and
   every tiny reversal wears the friction state a little (LuGre's drift under vibration,
   Dupont et al., "Single state elastoplastic friction models", IEEE TAC 47(5), 2002; dither
   lowers friction on real drives for the same reason). The encoder cannot see that motion,
   but the torque at rest shows it: it decays over seconds. On the simulated er20 (the
   default realistic plant, tuning instances 1–2; README, "The friction held at rest
   relaxes") the wrists relax at 0.08–0.14 /s (time constants 7–13 s); without r their z₀
   read 19–29 % short (the fit made up for the unseen wear by a faster turnover) and the
   residual was 2–5× larger.
4. **Fit.** ΔF = g·Δs(z₀, r) over all pairs: for each (z₀, r) of a grid (log z₀, r from 0),
   g is linear least squares (≥ 0); the best grid point is polished by a bounded
   Nelder–Mead search on (log z₀, r). The standard errors come from the Jacobian at the
   optimum.

The fit needs excursions on both sides of z₀: much smaller ones spring back, much larger ones
turn the friction over twice, and both read ΔF ≈ 0 whatever z₀ is. r shows where the state
was large: between the rest after a precondition and the next, it loses a share r·Δt that no
displacement explains.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
import scipy.optimize
from numba import njit
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_PRESLIDING_RELAXATION, DriveModelParameters
from leadthrough.dynamics.presliding import dahl_step, play_step, relaxation_factor
from leadthrough.errors import DataError, check_fields
from leadthrough.robot.description import Robot

__all__ = ["PreslidingAnalysisConfig", "PreslidingFit", "RestPairs", "dahl_states",
           "fit_presliding", "rest_pairs"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class PreslidingAnalysisConfig:
    """How rests are found and z₀ is fitted.

    Attributes:
        still_window_s: A rest holds every joint still this long; the torque is averaged over
            its last ``still_window_s`` [s].
        still_band_counts: Still: the position stays within this many encoder counts [-].
        same_configuration: Two consecutive rests further apart than this (any joint) are not
            paired [rad].
        play_counts: Width of the play operator on the encoder [counts] (the estimator's
            ``presliding_play_counts``).
        z0_range: Search interval of z₀ [rad].
        grid: Log-spaced grid points over ``z0_range``.
        max_relaxation: Largest relaxation rate r searched [1/s] (0: fit z₀ alone, with no
            relaxation, as before the rate was modelled).
        relaxation_grid: Grid points of r over [0, ``max_relaxation``] (0 and log-spaced from
            ``max_relaxation``/300).
        min_pairs: Fewest pairs the fit accepts.
    """

    still_window_s: float = 0.25
    still_band_counts: float = 20.0
    same_configuration: float = 2e-4
    play_counts: float = 2.5
    z0_range: tuple[float, float] = (5e-6, 5e-3)
    grid: int = 48
    max_relaxation: float = 2.0
    relaxation_grid: int = 12
    min_pairs: int = 6

    def __post_init__(self) -> None:
        lo, hi = self.z0_range
        check_fields("presliding_analysis", self, [
            ("still_window_s", math.isfinite(self.still_window_s) and self.still_window_s > 0,
             "> 0 s"),
            ("still_band_counts", math.isfinite(self.still_band_counts)
             and self.still_band_counts > 0, "> 0 counts"),
            ("same_configuration", math.isfinite(self.same_configuration)
             and self.same_configuration > 0, "> 0 rad"),
            ("play_counts", math.isfinite(self.play_counts) and self.play_counts >= 0,
             ">= 0 counts"),
            ("z0_range", math.isfinite(hi) and 0 < lo < hi, "0 < low < high, finite [rad]"),
            ("grid", self.grid >= 3, ">= 3"),
            ("max_relaxation", math.isfinite(self.max_relaxation)
             and 0 <= self.max_relaxation <= MAX_PRESLIDING_RELAXATION,
             f"0 to {MAX_PRESLIDING_RELAXATION:g} 1/s"),
            ("relaxation_grid", self.relaxation_grid >= 2, ">= 2"),
            ("min_pairs", self.min_pairs >= 2, ">= 2"),
        ])


@dataclass(frozen=True)
class RestPairs:
    """Consecutive rests at the same configuration.

    Attributes:
        windows: Averaging window of each rest [start, stop) [samples], shape (K, 2).
        first: Index of the first rest of each pair into ``windows``, shape (P,) (the second
            is ``first + 1``).
        torque_change: Joint torque change over each pair, gravity change removed [N·m],
            shape (P, n).
        unpaired: Consecutive rests not paired because the configuration differed.
    """

    windows: NDArray[np.intp]
    first: NDArray[np.intp]
    torque_change: Array
    unpaired: int


@dataclass(frozen=True)
class PreslidingFit:
    """z₀, the relaxation rate and the friction level at rest, per joint.

    Attributes:
        presliding: z₀ [rad], shape (n,).
        relaxation: r, the rate at which the friction carried at rest relaxes [1/s], shape
            (n,) (zeros when not fitted).
        level: g, the friction level at rest [N·m], shape (n,) (compare with the static level
            f1 + f2 + f3 of eq. 15).
        presliding_std: Standard error of z₀ [rad], shape (n,).
        level_std: Standard error of g [N·m], shape (n,).
        relaxation_std: Standard error of r [1/s], shape (n,).
        rms: RMS residual of ΔF per joint [N·m], shape (n,).
        pairs: The pairs fitted.
    """

    presliding: Array
    relaxation: Array
    level: Array
    presliding_std: Array
    level_std: Array
    relaxation_std: Array
    rms: Array
    pairs: RestPairs

    def applied_to(self, params: DriveModelParameters) -> DriveModelParameters:
        """``params`` with this test's z₀ and relaxation rates (what the estimator uses)."""
        return replace(params, presliding=self.presliding, presliding_relaxation=self.relaxation)


@njit(cache=True)
def dahl_states(q: Array, half_width: Array, presliding: Array, decay: Array) -> Array:
    """The normalised Dahl friction state s of every sample (F = g·s), from rest at s = 0.

    The estimator's friction at rest or creeping, replayed: the same play operator
    (:func:`~leadthrough.dynamics.presliding.play_step`), step
    (:func:`~leadthrough.dynamics.presliding.dahl_step`) and relaxation.

    Args:
        q: Joint positions [rad], shape (N, n).
        half_width: Half width of the play operator per joint [rad], shape (n,).
        presliding: z₀ per joint [rad], shape (n,).
        decay: Per joint, the factor s is multiplied by every sample [-], shape (n,)
            (:func:`~leadthrough.dynamics.presliding.relaxation_factor`; 1: no relaxation).

    Returns:
        s ∈ [−1, 1], shape (N, n).
    """
    N, n = q.shape
    out = np.zeros((N, n))
    play = q[0].copy()
    increment = np.zeros(n)
    s = np.zeros(n)
    for i in range(N):
        play_step(q[i], half_width, play, increment)
        for j in range(n):
            if increment[j] != 0.0:
                s[j] = dahl_step(s[j], increment[j], 1.0, presliding[j])
            s[j] *= decay[j]
        out[i] = s
    return out


def rest_pairs(recording: Recording, robot: Robot,
               config: PreslidingAnalysisConfig | None = None) -> RestPairs:
    """The pairs of consecutive rests at one configuration (module docstring, step 1).

    Args:
        recording: The test, no external force.
        robot: The robot (encoder resolution, current → torque, nominal gravity).
        config: Analysis settings.

    Returns:
        The pairs (possibly none).

    Raises:
        DataError: Not uniformly sampled, or shorter than a still window.
    """
    cfg = config if config is not None else PreslidingAnalysisConfig()
    rate = recording.uniform_rate("the presliding test")
    tau = recording.joint_torque(robot)
    q = recording.q
    w = max(2, round(cfg.still_window_s * rate))
    if w >= q.shape[0]:
        raise DataError("the presliding test is shorter than a still window",
                        source=recording.source, field="time", value=recording.duration,
                        expected=f"> {cfg.still_window_s} s")
    view = sliding_window_view(q, w, axis=0)             # (N − w + 1, n, w), trailing windows
    band = cfg.still_band_counts * robot.encoder_resolution
    still = np.all(view.max(axis=2) - view.min(axis=2) <= band, axis=1)
    edges = np.flatnonzero(np.diff(np.r_[0, still.astype(np.int8), 0]))
    # A slow drift can make the stillness flicker: a still stretch whose window overlaps the
    # previous one's is the same rest, continued.
    kept: list[int] = []
    for end in (edges[1::2] - 1 + (w - 1)).tolist():     # last sample of each still stretch
        if kept and end - w + 1 < kept[-1] + 1:
            kept[-1] = end
        else:
            kept.append(end)
    ends = np.array(kept, dtype=np.intp)
    windows = np.column_stack([ends - w + 1, ends + 1]).astype(np.intp)
    model, data = robot.model, robot.model.createData()
    mean_q = np.array([q[a:b].mean(axis=0) for a, b in windows]).reshape(-1, robot.n)
    mean_tau = np.array([tau[a:b].mean(axis=0) for a, b in windows]).reshape(-1, robot.n)
    first, change = [], []
    unpaired = 0
    for k, (qa, qb) in enumerate(itertools.pairwise(mean_q)):
        if np.max(np.abs(qb - qa)) > cfg.same_configuration:
            unpaired += 1
            continue
        dg = (pin.computeGeneralizedGravity(model, data, qb)
              - pin.computeGeneralizedGravity(model, data, qa))
        first.append(k)
        change.append(mean_tau[k + 1] - mean_tau[k] - dg)
    return RestPairs(windows=windows, first=np.array(first, dtype=np.intp),
                     torque_change=np.array(change).reshape(-1, robot.n), unpaired=unpaired)


def _state_changes(q: Array, half_width: Array, z0: Array, decay: Array, pairs: RestPairs
                   ) -> Array:
    """Δs over each pair (the state averaged over each rest's window), shape (P, n)."""
    s = dahl_states(q, half_width, z0, decay)
    cum = np.vstack([np.zeros((1, s.shape[1])), np.cumsum(s, axis=0)])
    a, b = pairs.windows[:, 0], pairs.windows[:, 1]
    mean_s = (cum[b] - cum[a]) / (b - a)[:, None]
    return mean_s[pairs.first + 1] - mean_s[pairs.first]


def _level(ds: Array, df: Array) -> Array:
    """Least-squares g ≥ 0 of df ≈ g·ds per column."""
    den = np.sum(ds * ds, axis=0)
    return np.maximum(np.sum(ds * df, axis=0) / np.where(den > 0, den, 1.0), 0.0)


def _relaxation_grid(cfg: PreslidingAnalysisConfig) -> Array:
    """The rates r searched [1/s]: 0, then log-spaced up to ``max_relaxation``."""
    if cfg.max_relaxation == 0.0:
        return np.zeros(1)
    return np.r_[0.0, np.geomspace(cfg.max_relaxation / 300.0, cfg.max_relaxation,
                                   cfg.relaxation_grid - 1)]


def fit_presliding(recording: Recording, robot: Robot,
                   config: PreslidingAnalysisConfig | None = None) -> PreslidingFit:
    """Fit z₀, r and g per joint to a presliding test (module docstring).

    Args:
        recording: The test, no external force.
        robot: The robot.
        config: Analysis settings.

    Returns:
        The fit.

    Raises:
        DataError: Fewer than ``min_pairs`` pairs of rests at one configuration (not a
            presliding test, or the robot never came to rest), or not uniformly sampled.
    """
    cfg = config if config is not None else PreslidingAnalysisConfig()
    pairs = rest_pairs(recording, robot, cfg)
    if pairs.first.size < cfg.min_pairs:
        raise DataError("too few out-and-back moves between rests at one configuration",
                        source=recording.source, field="q", value=int(pairs.first.size),
                        expected=f">= {cfg.min_pairs} pairs of rests (a presliding test: "
                                 "leadthrough excite --presliding, then record)")
    n = robot.n
    dt = 1.0 / recording.uniform_rate("the presliding test")
    q = np.ascontiguousarray(recording.q, dtype=float)
    half = 0.5 * cfg.play_counts * robot.encoder_resolution
    df = pairs.torque_change

    def changes(qj: Array, hj: Array, z0: Array, rate: Array) -> Array:
        return _state_changes(qj, hj, z0, relaxation_factor(rate, dt), pairs)

    # grid over (log z₀, r), every joint at once
    lo, hi = (math.log(v) for v in cfg.z0_range)
    grid = np.linspace(lo, hi, cfg.grid)
    rates = _relaxation_grid(cfg)
    cost = np.zeros((cfg.grid, rates.size, n))
    for k, lz in enumerate(grid):
        for m, r in enumerate(rates):
            ds = changes(q, half, np.full(n, math.exp(lz)), np.full(n, r))
            cost[k, m] = np.sum((df - _level(ds, df) * ds) ** 2, axis=0)
    z0, rate = np.zeros(n), np.zeros(n)
    for j in range(n):
        kj, mj = (int(i) for i in np.unravel_index(np.argmin(cost[:, :, j]), cost.shape[:2]))
        z0[j], rate[j] = math.exp(grid[kj]), rates[mj]
        # the joints are independent: polish on this joint's column only
        qj, hj, dfj = np.ascontiguousarray(q[:, j:j + 1]), half[j:j + 1], df[:, j:j + 1]

        def joint_cost(x: Array, qj: Array = qj, hj: Array = hj, dfj: Array = dfj) -> float:
            ds = changes(qj, hj, np.array([math.exp(x[0])]), np.array([x[1]]))
            return float(np.sum((dfj - _level(ds, dfj) * ds) ** 2))
        sol = scipy.optimize.minimize(
            joint_cost, np.array([grid[kj], rates[mj]]), method="Nelder-Mead",
            bounds=[(lo, hi), (0.0, cfg.max_relaxation)],
            options={"xatol": 1e-4, "fatol": 1e-12 * max(1.0, float(cost[kj, mj, j]))})
        if sol.fun <= cost[kj, mj, j]:
            z0[j], rate[j] = math.exp(float(sol.x[0])), float(sol.x[1])
    return _with_errors(changes, q, half, df, z0, rate, pairs, cfg)


def _with_errors(changes: Callable[[Array, Array, Array, Array], Array], q: Array,
                 half: Array, df: Array, z0: Array, rate: Array, pairs: RestPairs,
                 cfg: PreslidingAnalysisConfig) -> PreslidingFit:
    """The fit at (z₀, r), with g, the residual and the standard errors from the Jacobian
    [∂res/∂g, ∂res/∂ln z₀, ∂res/∂r] (central differences)."""
    n = z0.size
    ds = changes(q, half, z0, rate)
    g = _level(ds, df)
    resid = df - g * ds
    rms = np.sqrt(np.mean(resid ** 2, axis=0))
    h, hr = 1e-3, 1e-3 * max(cfg.max_relaxation, 1e-3)
    dz = (changes(q, half, z0 * math.exp(h), rate)
          - changes(q, half, z0 * math.exp(-h), rate)) / (2 * h)
    fitted_rate = cfg.max_relaxation > 0
    dr = (changes(q, half, z0, rate + hr) - changes(q, half, z0, np.maximum(rate - hr, 0.0))) \
        / (hr + np.minimum(rate, hr)) if fitted_rate else np.zeros_like(ds)
    columns = 3 if fitted_rate else 2
    dof = max(1, df.shape[0] - columns)
    z_std, g_std, r_std = np.zeros(n), np.zeros(n), np.zeros(n)
    for j in range(n):
        jac = np.column_stack([ds[:, j], g[j] * dz[:, j], g[j] * dr[:, j]][:columns])
        sigma2 = float(np.sum(resid[:, j] ** 2)) / dof
        cov = sigma2 * np.linalg.pinv(jac.T @ jac)
        g_std[j] = math.sqrt(max(cov[0, 0], 0.0))
        z_std[j] = z0[j] * math.sqrt(max(cov[1, 1], 0.0))
        if fitted_rate:
            r_std[j] = math.sqrt(max(cov[2, 2], 0.0))
    return PreslidingFit(presliding=z0, relaxation=rate, level=g, presliding_std=z_std,
                         level_std=g_std, relaxation_std=r_std, rms=rms, pairs=pairs)
