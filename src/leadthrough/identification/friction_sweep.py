"""Friction from a constant-velocity sweep: the steady Stribeck curve of eq. 15, per joint.

Input: a recording of out-and-back constant-velocity passes with no external force (for example
:func:`leadthrough.excitation.friction_sweep.design_friction_sweep`, but any recording with
such passes works). Per joint:

1. **Passes.** The joint velocity is estimated offline (Savitzky–Golay, zero lag); a pass is a
   run of one sign whose speed holds within ``speed_tolerance`` of its median; its first
   ``settle_displacement`` is dropped (the friction's presliding transient and the servo's lag).
2. **Pairs.** A positive pass and the following negative pass at the same speed that cover the
   same positions. On the overlap, the negative pass's torque is interpolated at the positive
   pass's positions. Where the whole configuration recurs (it does for the designed sweep: the
   backward pass is the forward one in reverse time), gravity, the drives' offset and the
   Coriolis/centrifugal torque (quadratic in q̇) cancel in the half difference, which is the
   friction alone: F(v) = mean(τ(q, +v) − τ(q, −v)) / 2. The drives' lags differ by joint, so
   the two configurations differ by a few mrad; that gravity difference is removed with the
   nominal (CAD) model, whose ±30 % error then matters only on a few mrad. The mismatch of each
   pair is reported; pairs above ``max_configuration_mismatch`` are dropped.
3. **Fit.** Eq. 15 through the points (v_k, F_k): for a log-spaced grid of the two Stribeck
   velocities the four amplitudes (f1, f2, f3, f4 ≥ 0) are non-negative least squares with
   relative weights; the best grid point is polished with bounded least squares.

The result feeds :func:`leadthrough.identification.api.identify` (``friction=``), which then
identifies the link parameters, rotor inertias and offsets with this friction held fixed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin
import scipy.optimize
import scipy.signal
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.dynamics.friction import StribeckParameters, stribeck_friction, stribeck_shapes
from leadthrough.errors import DataError, check_fields
from leadthrough.robot.description import Robot

__all__ = ["SweepAnalysisConfig", "SweepFit", "SweepPoints", "fit_sweep_friction",
           "sweep_points"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SweepAnalysisConfig:
    """How passes are found and the curve is fitted.

    Attributes:
        smoothing_s: Window of the offline velocity estimate [s].
        min_speed: Passes slower than this are ignored [rad/s].
        speed_tolerance: A pass holds its speed within this fraction of its median [-].
        settle_displacement: Displacement dropped at the start of each pass [rad].
        min_pass_s: Shortest usable pass after settling [s].
        max_configuration_mismatch: Largest joint-position mismatch between the two passes of a
            pair [rad] (the drives lag differently); the gravity difference it causes is removed
            with the nominal model, and pairs above this are dropped.
        grid: Grid points per Stribeck velocity.
    """

    smoothing_s: float = 0.1
    min_speed: float = 0.002
    speed_tolerance: float = 0.15
    settle_displacement: float = 0.004
    min_pass_s: float = 0.2
    max_configuration_mismatch: float = 0.02
    grid: int = 40

    def __post_init__(self) -> None:
        check_fields("sweep_analysis", self, [
            ("smoothing_s", math.isfinite(self.smoothing_s) and self.smoothing_s > 0, "> 0 s"),
            ("min_speed", math.isfinite(self.min_speed) and self.min_speed > 0, "> 0 rad/s"),
            ("speed_tolerance", 0 < self.speed_tolerance < 1, "0 < tolerance < 1"),
            ("settle_displacement", math.isfinite(self.settle_displacement)
             and self.settle_displacement >= 0, ">= 0 rad"),
            ("min_pass_s", math.isfinite(self.min_pass_s) and self.min_pass_s > 0, "> 0 s"),
            ("max_configuration_mismatch", self.max_configuration_mismatch > 0, "> 0 rad"),
            ("grid", self.grid >= 2, ">= 2"),
        ])


@dataclass(frozen=True)
class SweepPoints:
    """Measured steady friction, one list per joint.

    Attributes:
        speed: Per joint, pass speeds [rad/s] (> 0), shape (K_j,).
        friction: Per joint, F(v) = half the torque difference of the pair [N·m], shape (K_j,).
        spread: Per joint, standard deviation of the half difference over the pair (ripple and
            noise) [N·m], shape (K_j,).
        mismatch: Per joint, largest configuration mismatch of the pair [rad], shape (K_j,).
        dropped: Pairs dropped for configuration mismatch, per joint.
    """

    speed: list[Array]
    friction: list[Array]
    spread: list[Array]
    mismatch: list[Array]
    dropped: list[int]


@dataclass(frozen=True)
class SweepFit:
    """Eq. 15 fitted to the sweep.

    Attributes:
        params: The friction parameters, shape (n,) each.
        points: The measured points.
        rms: RMS of the fit residual per joint [N·m], shape (n,).
        max_relative_error: Largest |fit − point| / point per joint [-], shape (n,).
    """

    params: StribeckParameters
    points: SweepPoints
    rms: Array
    max_relative_error: Array


class _Pass(NamedTuple):
    idx: NDArray[np.intp]
    speed: float


def _passes(q: Array, qd: Array, rate: float, cfg: SweepAnalysisConfig) -> list[_Pass]:
    """Steady constant-velocity passes of one joint, in time order."""
    s = np.where(np.abs(qd) > cfg.min_speed, np.sign(qd), 0.0)
    edges = np.flatnonzero(np.diff(s) != 0) + 1
    out: list[_Pass] = []
    for a, b in zip(np.r_[0, edges], np.r_[edges, s.size], strict=True):
        if s[a] == 0.0 or b - a < 2:
            continue
        v = float(np.median(qd[a:b]))
        steady = np.flatnonzero(np.abs(qd[a:b] - v) <= cfg.speed_tolerance * abs(v)) + a
        if steady.size == 0:
            continue
        lo, hi = int(steady[0]), int(steady[-1]) + 1
        travelled = np.abs(q[lo:hi] - q[lo])
        settled = travelled >= cfg.settle_displacement
        start = lo + int(np.argmax(settled)) if settled.any() else hi
        if hi - start < cfg.min_pass_s * rate:
            continue
        out.append(_Pass(np.arange(start, hi), v))
    return out


def sweep_points(recording: Recording, robot: Robot,
                 config: SweepAnalysisConfig | None = None) -> SweepPoints:
    """Steady friction points of every joint from a sweep recording.

    Args:
        recording: Out-and-back constant-velocity passes, no external force.
        robot: The robot (current → torque).
        config: Analysis settings.

    Returns:
        The points (joints with no usable pair have empty arrays).

    Raises:
        DataError: The recording is not uniformly sampled or too short to differentiate.
    """
    cfg = config if config is not None else SweepAnalysisConfig()
    tau = recording.joint_torque(robot)
    q, t = recording.q, recording.time
    rate = recording.uniform_rate("the sweep")
    win = max(5, round(cfg.smoothing_s * rate) | 1)
    if win >= t.size:
        raise DataError("the sweep is shorter than the smoothing window", source=recording.source,
                        field="time", value=float(t[-1] - t[0]),
                        expected=f"> {cfg.smoothing_s} s")
    qd = scipy.signal.savgol_filter(q, win, 2, deriv=1, delta=1.0 / rate, axis=0)
    model, data = robot.model, robot.model.createData()

    def gravity(qi: Array) -> Array:
        return np.asarray(pin.computeGeneralizedGravity(model, data, qi))

    speeds, frictions, spreads, mismatches, dropped = [], [], [], [], []
    for j in range(robot.n):
        ps = _passes(q[:, j], qd[:, j], rate, cfg)
        pts: list[tuple[float, float, float, float]] = []
        bad = 0
        for a, b in itertools.pairwise(ps):
            if a.speed * b.speed >= 0 or abs(abs(a.speed) - abs(b.speed)) > \
                    cfg.speed_tolerance * max(abs(a.speed), abs(b.speed)):
                continue
            pos, neg = (a, b) if a.speed > 0 else (b, a)
            qp, qn = q[pos.idx, j], q[neg.idx, j]
            lo, hi = max(qp.min(), qn.min()), min(qp.max(), qn.max())
            sel = pos.idx[(qp >= lo) & (qp <= hi)]
            if sel.size < cfg.min_pass_s * rate:
                continue
            order = np.argsort(qn)
            qn_sorted = qn[order]
            at = q[sel, j]
            tau_neg = np.interp(at, qn_sorted, tau[neg.idx[order], j])
            q_neg = np.column_stack([np.interp(at, qn_sorted, q[neg.idx[order], k])
                                     for k in range(robot.n)])
            mis = float(np.max(np.abs(q_neg - q[sel])))
            if mis > cfg.max_configuration_mismatch:
                bad += 1
                continue
            # The drives lag differently (friction, servo), so the configurations of the two
            # passes differ by a few mrad: remove that gravity difference with the nominal model.
            dg = np.array([gravity(q[i])[j] - gravity(qn_i)[j]
                           for i, qn_i in zip(sel, q_neg, strict=True)])
            half = 0.5 * (tau[sel, j] - tau_neg - dg)
            v = 0.5 * (float(np.mean(qd[sel, j])) - float(np.mean(qd[neg.idx, j])))
            pts.append((v, float(np.mean(half)), float(np.std(half)), mis))
        arr = np.array(sorted(pts)).reshape(-1, 4)
        speeds.append(arr[:, 0])
        frictions.append(arr[:, 1])
        spreads.append(arr[:, 2])
        mismatches.append(arr[:, 3])
        dropped.append(bad)
    return SweepPoints(speed=speeds, friction=frictions, spread=spreads, mismatch=mismatches,
                       dropped=dropped)


def _fit_joint(v: Array, f: Array, R: float, vmax: float, grid: int) -> Array:
    """[f1, f2, q̇sm, f3, q̇sg, f4] of one joint through its points (relative weights)."""
    w = 1.0 / np.maximum(np.abs(f), 1e-3 * max(float(np.max(np.abs(f))), 1e-9))
    grid_m = np.geomspace(0.5, R * vmax, grid)
    grid_g = np.geomspace(1e-3 * vmax, vmax, grid)
    speeds, ratio = v[:, None], np.array([R])

    def columns(sm: float, sg: float) -> Array:
        """Eq. 15's columns [sgn, e_m, e_g, q̇] at the (positive) speeds, shape (K, 4)."""
        sgn, motor, gear = stribeck_shapes(speeds, ratio, np.array([sm]), np.array([sg]))
        return np.column_stack([sgn, motor, gear, v])

    best = (math.inf, np.zeros(6))
    for sm in grid_m:
        for sg in grid_g:
            x, res = scipy.optimize.nnls(columns(sm, sg) * w[:, None], f * w)
            if res < best[0]:
                best = (res, np.array([x[0], x[1], sm, x[2], sg, x[3]]))
    x0 = best[1]
    lo = np.array([0.0, 0.0, math.log(grid_m[0]), 0.0, math.log(grid_g[0]), 0.0])
    hi = np.array([np.inf, np.inf, math.log(grid_m[-1]), np.inf, math.log(grid_g[-1]), np.inf])

    def resid(p: Array) -> Array:
        c = columns(math.exp(p[2]), math.exp(p[4]))
        return (p[0] * c[:, 0] + p[1] * c[:, 1] + p[3] * c[:, 2] + p[5] * c[:, 3] - f) * w

    start = np.array([x0[0], x0[1], math.log(x0[2]), x0[3], math.log(x0[4]), x0[5]])
    sol = scipy.optimize.least_squares(resid, np.clip(start, lo, hi), bounds=(lo, hi))
    p = sol.x if sol.cost <= 0.5 * best[0] ** 2 else start
    return np.array([p[0], p[1], math.exp(p[2]), p[3], math.exp(p[4]), p[5]])


def fit_sweep_friction(points: SweepPoints, robot: Robot,
                       config: SweepAnalysisConfig | None = None,
                       source: str | None = None) -> SweepFit:
    """Fit eq. 15 to the sweep's points, per joint.

    Args:
        points: From :func:`sweep_points`.
        robot: The robot (gear ratios, velocity limits).
        config: Grid size.
        source: Name of the recording, for errors.

    Returns:
        The fit.

    Raises:
        DataError: A joint has fewer than 4 points (the sweep did not move it at enough
            speeds).
    """
    cfg = config if config is not None else SweepAnalysisConfig()
    n = robot.n
    rows = np.zeros((6, n))
    for j in range(n):
        v, f = points.speed[j], points.friction[j]
        if v.size < 4:
            raise DataError("too few constant-velocity pairs for the friction curve",
                            source=source, field=f"joint '{robot.joint_names[j]}'",
                            value=int(v.size),
                            expected=">= 4 out-and-back passes at different speeds")
        rows[:, j] = _fit_joint(v, f, float(robot.gear_ratio[j]), float(robot.velocity_limit[j]),
                                cfg.grid)
    params = StribeckParameters(f1=rows[0], f2=rows[1], qd_sm=rows[2], f3=rows[3],
                                qd_sg=rows[4], f4=rows[5])
    rms, rel = np.zeros(n), np.zeros(n)
    for j in range(n):
        v = points.speed[j]
        qd = np.zeros((v.size, n))
        qd[:, j] = v
        model = stribeck_friction(qd, robot.gear_ratio, params)[:, j]
        err = model - points.friction[j]
        rms[j] = float(np.sqrt(np.mean(err ** 2)))
        rel[j] = float(np.max(np.abs(err) / np.maximum(np.abs(points.friction[j]), 1e-9)))
    return SweepFit(params=params, points=points, rms=rms, max_relative_error=rel)
