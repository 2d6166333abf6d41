"""The payload's linear system in a recording: the last link's regressor and the residual of
the identified unloaded model, in motion or at rest, alone or against an unloaded run.

A payload rigidly attached to the last link adds its inertial parameters φ_p to that link, so
the joint torque grows by y = K_last(q, q̇, q̈)·φ_p (the last link's 10 regressor columns). The
residual r = τ_measured − τ̂_d of the unloaded model τ̂_d holds y, and the part of the model's
own error that correlates with those columns (:mod:`leadthrough.estimation.payload`).

Against an unloaded run of the same trajectory the residual is r_loaded(t) − r_unloaded(t + s),
at the same point of the path; s aligns the two runs' positions (:func:`reference_shift`),
since real runs seldom start at the same instant of the program.

What the currents read of the payload's torque is not y itself:

* **drive gains**: the current → torque factor R·Kt of the drive file differs from the drive's
  own by a few per cent (motor tolerances), so a joint reads y / c_j, c_j the true torque per
  drive-file torque (:mod:`leadthrough.estimation.drive_gains` measures c with a known mass);
* **the payload's own friction**: a gear's Coulomb level grows with the torque it transmits,
  f_c0 + f_cL·|τ_load|, and the payload adds y to τ_load, so the friction grows by
  f_cL·sgn(q̇)·(|τ_load + y| − |τ_load|).

:func:`payload_regressor` folds both into the payload's columns, given φ_p (the friction's part
is not linear in φ_p: :func:`leadthrough.estimation.payload.estimate_payload` iterates).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.align import interp_columns
from leadthrough.data.preprocess import ProcessedData
from leadthrough.dynamics.friction import StribeckParameters
from leadthrough.dynamics.model import (
    DriveModelParameters,
    model_torque,
    model_torque_from_links,
)
from leadthrough.dynamics.regressor import link_regressor_batch, link_torque
from leadthrough.errors import DataError
from leadthrough.robot.description import Robot

__all__ = ["MIN_OVERLAP", "SAME_PATH_RAD", "PayloadSystem", "against_reference",
           "correlation_factor", "motion_system", "payload_regressor", "reference_shift",
           "static_system"]

Array = NDArray[np.float64]

#: A reference run (module docstring) follows the same path if, once aligned in time
#: (:func:`reference_shift`), every joint's position stays within this of the loaded run's
#: [rad]; the two runs must have at least this fraction of the shorter one in common.
SAME_PATH_RAD, MIN_OVERLAP = 0.02, 0.5

#: The alignment's coarse search rate [Hz], and the RMS position difference [rad] within
#: which two shifts count as equally good (a periodic trajectory repeats).
SHIFT_SEARCH_HZ, SHIFT_TIE_RAD = 10.0, 1e-3

#: Number of payload columns (the last link's m, m·c, inertia).
PAYLOAD_COLUMNS = 10


class PayloadSystem(NamedTuple):
    """The payload's linear system.

    Attributes:
        regressor: (samples, n, columns): the last link's 10 columns, then re-fitted Coulomb
            terms (one per joint) where asked.
        residual: Residual torque of the unloaded model (samples, n) [N·m].
        used: Which entries are used (samples, n).
        columns: Which columns are fitted.
        load_torque: The unloaded model's link torque τ_load at the recording's states
            (samples, n) [N·m]: what the payload's torque adds to in the gears' friction.
        velocity_sign: sgn(q̇) (samples, n); 0 at rest.
    """

    regressor: Array
    residual: Array
    used: NDArray[np.bool_]
    columns: NDArray[np.int64]
    load_torque: Array
    velocity_sign: Array


def motion_system(data: ProcessedData, robot: Robot, params: DriveModelParameters,
                  refit_friction: bool) -> PayloadSystem:
    """In motion: the last link's 10 parameters (and, refitted, a change of each joint's
    Coulomb level) from the moving samples."""
    n, model = robot.n, robot.model
    last = n  # joint index of the last link in the Pinocchio model
    K = link_regressor_batch(model, data.q, data.qd, data.qdd)[:, :, 10 * (last - 1):]
    links = link_torque(model, params.phi, data.q, data.qd, data.qdd)
    residual = data.torque - model_torque_from_links(robot, params, links, data.qd, data.qdd)
    sign = np.sign(data.qd)
    cols = np.arange(PAYLOAD_COLUMNS + n)
    if refit_friction:
        # gear friction grows with the transmitted load: re-fit each joint's Coulomb term
        coulomb = np.zeros((data.samples, n, n))
        coulomb[:, np.arange(n), np.arange(n)] = sign
        K = np.concatenate([K, coulomb], axis=2)
    else:
        cols = np.arange(PAYLOAD_COLUMNS)
    return PayloadSystem(K, residual, data.moving, cols, links, sign)


def static_system(data: ProcessedData, robot: Robot, params: DriveModelParameters,
                  static_velocity: float, settle_s: float) -> PayloadSystem:
    """At rest (after ``settle_s`` of it): the last link's m and m·c from gravity alone."""
    still = np.all(np.abs(data.qd) < static_velocity, axis=1)
    # keep only samples preceded by settle_s of rest: samples since the last moving one
    idx = np.arange(still.size)
    last_moving = np.maximum.accumulate(np.where(still, -1, idx))
    still &= idx - last_moving >= round(settle_s * data.rate_hz)
    if still.sum() < 10:
        raise DataError("too few static samples", source=data.source, field="q̇",
                        value=int(still.sum()),
                        expected=f">= 10 samples with all |q̇| < {static_velocity} rad/s")
    # at rest: no friction and no inertial terms; the model's static torque is gravity
    zero = 0 * data.qd[still]
    K = link_regressor_batch(robot.model, data.q[still], zero, zero)[:, :, 10 * (robot.n - 1):]
    links = link_torque(robot.model, params.phi, data.q[still], zero, zero)
    static_model = model_torque_from_links(robot, _without_friction(params), links, zero, zero)
    residual = data.torque[still] - static_model
    return PayloadSystem(K, residual, np.ones(residual.shape, dtype=bool), np.arange(4),
                         links, zero)


def payload_regressor(system: PayloadSystem, phi_p: Array, gain: Array,
                      load_friction: Array) -> Array:
    """The system's regressor with the payload's columns as the currents read them (module
    docstring): joint j's row scaled by (1 + f_cL,j·sgn(q̇_j)·s_j)/c_j, where
    s_j = (|τ_load + y| − |τ_load|)/y for the payload's torque y = K·φ_p (its limit sgn(τ_load)
    at y = 0). With the true φ_p this is exact: its product with φ_p is the torque read.

    Args:
        system: The payload's system.
        phi_p: The payload's parameters so far (10,) (zeros for a first pass).
        gain: c per joint, shape (n,) (ones: the drive file's).
        load_friction: f_cL per joint, shape (n,) (zeros: none).

    Returns:
        The regressor, shape as ``system.regressor`` (a copy).
    """
    regressor = system.regressor.copy()
    payload = regressor[:, :, :PAYLOAD_COLUMNS]
    scale = np.broadcast_to(1.0 / gain, system.load_torque.shape).copy()
    if np.any(load_friction > 0.0):
        y = payload @ phi_p
        tau = system.load_torque
        safe = np.where(y == 0.0, 1.0, y)
        secant = np.where(y == 0.0, np.sign(tau), (np.abs(tau + y) - np.abs(tau)) / safe)
        scale *= 1.0 + load_friction * system.velocity_sign * secant
    payload *= scale[:, :, None]
    return regressor


def correlation_factor(residual: Array) -> float:
    """(1 + ρ)/(1 − ρ) for the lag-1 autocorrelation ρ of a residual series, ρ clipped to
    [0, 1 − 1/size]: the factor by which a smooth residual's variance counts for fewer
    independent samples; 1 for fewer than 3 samples or a zero residual.

    Args:
        residual: The residual in time order, shape (N,).
    """
    if residual.size < 3 or not np.any(residual):
        return 1.0
    rho = float(np.dot(residual[:-1], residual[1:]) / np.dot(residual, residual))
    rho = min(max(rho, 0.0), 1.0 - 1.0 / residual.size)
    return (1.0 + rho) / (1.0 - rho)


def reference_shift(t: Array, q: Array, t_ref: Array, q_ref: Array) -> tuple[float, float]:
    """The time shift s [s] that puts a reference run on a recording's path: q_ref(t + s)
    closest to q(t), RMS over the overlap, which must cover at least :data:`MIN_OVERLAP` of
    the shorter run. Both runs' times count from their start. A periodic trajectory fits
    equally well at every period: of the shifts within :data:`SHIFT_TIE_RAD` of the best, the
    one with the longest overlap is taken.

    Searched on a grid of 1/:data:`SHIFT_SEARCH_HZ`, then refined to 1 ms around the best.

    Args:
        t: The recording's times since its start [s], shape (N,).
        q: Its positions [rad], shape (N, n).
        t_ref: The reference's times since its start [s], shape (M,).
        q_ref: Its positions [rad], shape (M, n).

    Returns:
        s [s] and the RMS position difference there [rad] (inf if no shift overlaps enough).
    """
    step = 1.0 / SHIFT_SEARCH_HZ
    grid = np.arange(0.0, t[-1] + 0.5 * step, step)
    grid_ref = np.arange(0.0, t_ref[-1] + 0.5 * step, step)
    a, b = interp_columns(grid, t, q), interp_columns(grid_ref, t_ref, q_ref)
    need = max(2, int(MIN_OVERLAP * min(grid.size, grid_ref.size)))
    shifts, costs, spans = [], [], []
    for m in range(-(grid.size - need), grid_ref.size - need + 1):
        lo, hi = max(0, -m), min(grid.size, grid_ref.size - m)   # a[i] against b[i + m]
        d = a[lo:hi] - b[lo + m:hi + m]
        shifts.append(m * step)
        costs.append(float(np.sqrt(np.mean(d * d))))
        spans.append(hi - lo)
    if not costs:
        return 0.0, math.inf
    c, spans_a = np.array(costs), np.array(spans)
    tied = np.flatnonzero(c <= c.min() + SHIFT_TIE_RAD)
    coarse = shifts[int(tied[np.argmax(spans_a[tied])])]

    def rms(shift: float) -> float:
        tt = t[(t + shift >= 0.0) & (t + shift <= t_ref[-1])]
        d = interp_columns(tt, t, q) - interp_columns(tt + shift, t_ref, q_ref)
        return float(np.sqrt(np.mean(d * d)))

    fine = np.round(coarse + np.arange(-step, step + 5e-4, 1e-3), 9)
    best = min(fine, key=rms)
    return float(best), rms(float(best))


def against_reference(system: PayloadSystem, data: ProcessedData, ref: ProcessedData,
                      robot: Robot, params: DriveModelParameters) -> tuple[PayloadSystem, float]:
    """``system`` with the unloaded run ``ref``'s residual subtracted, at the same point of
    the path (:func:`reference_shift`), on the loaded run's samples that ``ref`` covers and
    where both move; and the shift [s].

    Raises:
        DataError: ``ref`` of another joint count, not overlapping the recording or on
            another path (more than :data:`SAME_PATH_RAD` apart).
    """
    if ref.q.shape[1] != robot.n:
        raise DataError("the reference run has another number of joints", source=ref.source,
                        field="q", value=ref.q.shape[1], expected=f"{robot.n} ({robot.name})")
    t, t_ref = data.time - data.time[0], ref.time - ref.time[0]
    shift, _ = reference_shift(t, data.q, t_ref, ref.q)
    inside = (t + shift >= 0.0) & (t + shift <= t_ref[-1])
    if inside.sum() < 2:
        raise DataError("the reference run does not overlap the recording",
                        source=ref.source, field="time", value=float(t_ref[-1]),
                        expected="a run of the same trajectory, at least "
                                 f"{MIN_OVERLAP:.0%} of the shorter run in common")
    at = t[inside] + shift
    apart = np.abs(interp_columns(at, t_ref, ref.q) - data.q[inside]).max(axis=0)
    if apart.max() > SAME_PATH_RAD:
        j = int(np.argmax(apart))
        raise DataError("the reference run follows another path", source=ref.source,
                        field=f"q{j + 1}", value=float(apart[j]),
                        expected=f"within {SAME_PATH_RAD} rad of the recording all along "
                                 "(the same trajectory, unloaded)")
    residual_ref = ref.torque - model_torque(robot, params, ref.q, ref.qd, ref.qdd)
    moving_ref = interp_columns(at, t_ref, ref.moving.astype(float)) == 1.0
    residual = system.residual[inside] - interp_columns(at, t_ref, residual_ref)
    return PayloadSystem(system.regressor[inside], residual, system.used[inside] & moving_ref,
                         system.columns, system.load_torque[inside],
                         system.velocity_sign[inside]), shift


def _without_friction(params: DriveModelParameters) -> DriveModelParameters:
    """The same parameters with all friction set to zero (static torque at rest)."""
    z = np.zeros_like(params.rotor_inertia)
    st = None if params.stribeck is None else StribeckParameters(
        f1=z, f2=z, qd_sm=params.stribeck.qd_sm, f3=z, qd_sg=params.stribeck.qd_sg, f4=z)
    return replace(params, stribeck=st, coulomb=np.zeros(0) if not params.coulomb.size else z,
                   viscous=np.zeros(0) if not params.viscous.size else z,
                   cbrt=np.zeros(0) if not params.cbrt.size else z, load_friction=np.zeros(0))
