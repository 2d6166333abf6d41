"""Presliding length z₀ of each drive's friction, from a presliding test (no link model).

Input: a recording of out-and-back moves between rests at one configuration, with no external
force (:func:`leadthrough.excitation.presliding.design_presliding_test`, but any recording with
such moves works). Per joint:

1. **Rests.** A rest is a stretch where every joint stays within ``still_band_counts`` encoder
   counts for ``still_window_s``; its last ``still_window_s`` are averaged. Two consecutive
   rests at the same configuration (within ``same_configuration``) form a *pair*: gravity and
   the drives' offset are the same in both, so the change of joint torque is the change of the
   friction (the small gravity change of a drive that did not return exactly is removed with
   the nominal model).
2. **Model.** The friction at rest is a Dahl state: F = g·s, with s ∈ [−1, 1] driven by the
   joint's displacement, ds = (sgn(dq) − s)·|dq|/z₀ (:func:`dahl_states`, the estimator's
   friction at rest,
   :func:`leadthrough.dynamics.presliding.presliding_friction_step`). The encoder
   goes through a play operator of ``play_counts`` counts first, as in the estimator:
   quantisation chatter at rest would otherwise wear the state down.
3. **Fit.** ΔF = g·Δs(z₀) over all pairs: for each z₀ of a log grid, g is linear least squares
   (≥ 0); the best grid point is polished by a bounded scalar search on log z₀. The standard
   errors come from the Jacobian at the optimum.

The fit needs excursions on both sides of z₀: much smaller ones spring back, much larger ones
turn the friction over twice, and both read ΔF ≈ 0 whatever z₀ is.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.optimize
from numba import njit
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.dynamics.presliding import dahl_step, play_step
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
        min_pairs: Fewest pairs the fit accepts.
    """

    still_window_s: float = 0.25
    still_band_counts: float = 20.0
    same_configuration: float = 2e-4
    play_counts: float = 2.5
    z0_range: tuple[float, float] = (5e-6, 5e-3)
    grid: int = 48
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
    """z₀ and the friction level at rest, per joint.

    Attributes:
        presliding: z₀ [rad], shape (n,).
        level: g, the friction level at rest [N·m], shape (n,) (compare with the static level
            f1 + f2 + f3 of eq. 15).
        presliding_std: Standard error of z₀ [rad], shape (n,).
        level_std: Standard error of g [N·m], shape (n,).
        rms: RMS residual of ΔF per joint [N·m], shape (n,).
        pairs: The pairs fitted.
    """

    presliding: Array
    level: Array
    presliding_std: Array
    level_std: Array
    rms: Array
    pairs: RestPairs


@njit(cache=True)
def dahl_states(q: Array, half_width: Array, presliding: Array) -> Array:
    """The normalised Dahl friction state s of every sample (F = g·s), from rest at s = 0.

    The estimator's friction at rest, replayed: the same play operator
    (:func:`~leadthrough.dynamics.presliding.play_step`) and step
    (:func:`~leadthrough.dynamics.presliding.dahl_step`).

    Args:
        q: Joint positions [rad], shape (N, n).
        half_width: Half width of the play operator per joint [rad], shape (n,).
        presliding: z₀ per joint [rad], shape (n,).

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


def _state_changes(q: Array, half_width: Array, z0: Array, pairs: RestPairs) -> Array:
    """Δs over each pair (the state averaged over each rest's window), shape (P, n)."""
    s = dahl_states(q, half_width, z0)
    cum = np.vstack([np.zeros((1, s.shape[1])), np.cumsum(s, axis=0)])
    a, b = pairs.windows[:, 0], pairs.windows[:, 1]
    mean_s = (cum[b] - cum[a]) / (b - a)[:, None]
    return mean_s[pairs.first + 1] - mean_s[pairs.first]


def _level(ds: Array, df: Array) -> Array:
    """Least-squares g ≥ 0 of df ≈ g·ds per column."""
    den = np.sum(ds * ds, axis=0)
    return np.maximum(np.sum(ds * df, axis=0) / np.where(den > 0, den, 1.0), 0.0)


def fit_presliding(recording: Recording, robot: Robot,
                   config: PreslidingAnalysisConfig | None = None) -> PreslidingFit:
    """Fit z₀ and g per joint to a presliding test (module docstring).

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
    q = np.ascontiguousarray(recording.q, dtype=float)
    half = 0.5 * cfg.play_counts * robot.encoder_resolution
    df = pairs.torque_change
    lo, hi = (math.log(v) for v in cfg.z0_range)
    grid = np.linspace(lo, hi, cfg.grid)
    cost = np.zeros((cfg.grid, n))
    for k, lz in enumerate(grid):
        ds = _state_changes(q, half, np.full(n, math.exp(lz)), pairs)
        cost[k] = np.sum((df - _level(ds, df) * ds) ** 2, axis=0)
    best = np.argmin(cost, axis=0)
    z0 = np.exp(grid[best])
    step = grid[1] - grid[0]
    for j in range(n):
        # the joints are independent: replay this joint's column only
        qj, hj, dfj = np.ascontiguousarray(q[:, j:j + 1]), half[j:j + 1], df[:, j:j + 1]

        def joint_cost(lz: float, qj: Array = qj, hj: Array = hj, dfj: Array = dfj) -> float:
            ds = _state_changes(qj, hj, np.array([math.exp(lz)]), pairs)
            return float(np.sum((dfj - _level(ds, dfj) * ds) ** 2))
        bracket = (max(lo, grid[best[j]] - step), min(hi, grid[best[j]] + step))
        sol = scipy.optimize.minimize_scalar(joint_cost, bounds=bracket, method="bounded",
                                             options={"xatol": 1e-4})
        if sol.fun <= cost[best[j], j]:
            z0[j] = math.exp(float(sol.x))
    ds = _state_changes(q, half, z0, pairs)
    g = _level(ds, df)
    resid = df - g * ds
    rms = np.sqrt(np.mean(resid ** 2, axis=0))
    # standard errors from the Jacobian [∂r/∂g, ∂r/∂ln z₀] (central difference in ln z₀)
    h = 1e-3
    d_plus = _state_changes(q, half, z0 * math.exp(h), pairs)
    d_minus = _state_changes(q, half, z0 * math.exp(-h), pairs)
    dof = max(1, df.shape[0] - 2)
    z_std, g_std = np.zeros(n), np.zeros(n)
    for j in range(n):
        jac = np.column_stack([ds[:, j], g[j] * (d_plus[:, j] - d_minus[:, j]) / (2 * h)])
        sigma2 = float(np.sum(resid[:, j] ** 2)) / dof
        cov = sigma2 * np.linalg.pinv(jac.T @ jac)
        g_std[j] = math.sqrt(max(cov[0, 0], 0.0))
        z_std[j] = z0[j] * math.sqrt(max(cov[1, 1], 0.0))
    return PreslidingFit(presliding=z0, level=g, presliding_std=z_std, level_std=g_std,
                         rms=rms, pairs=pairs)
