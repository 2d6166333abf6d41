"""Payload identification with the identified model of the unloaded robot (paper Table III).

A payload rigidly attached to the last link adds its inertial parameters φ_p to that link, so
the joint torque grows by K_last(q, q̇, q̈)·φ_p (the last link's 10 regressor columns). With the
unloaded model τ̂_d identified beforehand, φ_p is the least-squares fit of the residual
r = τ_measured − τ̂_d over the recording:

* ``motion`` (the paper's "during motion, inertial force considered"): all moving joint
  equations, full regressor; mass, CoM and (where excited) inertia. Gear friction grows with the
  transmitted load, so by default a change of each joint's Coulomb friction is fitted too;
* ``static``: samples where the whole robot has rested for a while; gravity columns only (m and
  m·c). Needs several distinct poses for the CoM. Caution: at rest, stiction holds an unknown,
  direction-dependent share of the load (why the paper drops standstill samples), so on geared
  robots this method is biased; it suits direct-drive or low-friction arms.

The mass gives the weight m·|g|; the CoM is reported in the TCP frame where it is identifiable.

**Against an unloaded run** (``reference``, ``motion`` only). Whatever the unloaded model gets
wrong along the recording's path (links outside its bounds, friction it lacks) is in the
residual r = τ_measured − τ̂_d too, and the part of it that correlates with the payload's
columns reads as payload: on the simulated er20's realistic plant a bias of 1.5–6 N, 2–8 % of
the paper's lightest payload (README, Table III). A run of the same trajectory without the
payload has the same error: with it, the fit takes the difference of the two runs' residuals,
r_loaded(t) − r_unloaded(t + s), at the same point of the path (s aligns the two runs'
positions: :func:`reference_shift`; real runs seldom start at the same instant of the program).
The model's error along the path cancels; the model still accounts for the small difference
between the two runs' states (the loaded robot follows the trajectory a little differently). The
drive-gain identification of Gautier and Briot (IROS 2011) likewise records the robot on a
trajectory without and with a payload. Both runs must follow the same path: a reference whose
positions differ by more than :data:`SAME_PATH_RAD` is refused. What the difference cannot
cancel is what the payload itself changes: an error of a drive's torque constant scales the
payload's torque, and a gear's friction grows with the load it carries (the constant part of
that growth is fitted, above).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.align import interp_columns
from leadthrough.data.preprocess import PreprocessConfig, ProcessedData, preprocess
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import DriveModelParameters, model_torque
from leadthrough.dynamics.regressor import link_regressor_batch
from leadthrough.errors import DataError, DataWarning
from leadthrough.robot.description import Robot

__all__ = ["PayloadEstimate", "estimate_payload", "reference_shift"]

Array = NDArray[np.float64]


#: A mass this many standard errors from zero is significant: only then is the CoM reported
#: (for a positive mass) or a negative mass warned about.
SIGNIFICANT_SIGMAS = 5.0

#: A reference run (module docstring) follows the same path if, once aligned in time
#: (:func:`reference_shift`), every joint's position stays within this of the loaded run's
#: [rad]; the two runs must have at least this fraction of the shorter one in common.
SAME_PATH_RAD, MIN_OVERLAP = 0.02, 0.5

#: The alignment's coarse search rate [Hz], and the RMS position difference [rad] within
#: which two shifts count as equally good (a periodic trajectory repeats).
SHIFT_SEARCH_HZ, SHIFT_TIE_RAD = 10.0, 1e-3


@dataclass(frozen=True)
class PayloadEstimate:
    """Identified payload.

    Attributes:
        method: ``"motion"`` or ``"static"``.
        mass_kg: Mass [kg].
        mass_std_kg: Its standard error from the fit's residual [kg], allowing for the
            residual's correlation in time (the noise's share only, not the model's bias;
            conservative for densely sampled, smooth residuals: measured ±0.03 kg on the real
            UR10e's 2.8 kg, ±0.6 kg on the simulator's 10 kg at 1 kHz for an error of 0.05 kg).
        weight_n: Weight m·|g| [N].
        com_tcp: Centre of mass in the TCP frame [m], shape (3,), or None where not identifiable
            (the motion does not excite it, or the mass is within
            :data:`SIGNIFICANT_SIGMAS` standard errors of zero).
        samples: Joint equations used.
        residual_rms: RMS of the fit residual per joint [N·m], shape (n,).
        reference_shift_s: With an unloaded reference run, the time [s] by which the
            reference was shifted onto the recording's path (:func:`reference_shift`); else
            None.
    """

    method: str
    mass_kg: float
    mass_std_kg: float
    weight_n: float
    com_tcp: Array | None
    samples: int
    residual_rms: Array
    reference_shift_s: float | None = None


def estimate_payload(
    rec: Recording | ProcessedData,
    robot: Robot,
    params: DriveModelParameters,
    method: str = "motion",
    preprocess_config: PreprocessConfig | None = None,
    static_velocity: float = 0.01,
    settle_s: float = 1.0,
    refit_friction: bool = True,
    reference: Recording | ProcessedData | None = None,
) -> PayloadEstimate:
    """Estimate the payload at the flange from a recording made with it attached.

    Args:
        rec: Recording with the payload (currents or torques).
        robot: The robot.
        params: Identified parameters of the unloaded robot.
        method: ``"motion"`` or ``"static"``.
        preprocess_config: Filtering settings (default: as calibration; for ``static`` no sample
            is dropped for standstill).
        static_velocity: Max |q̇| of all joints for a sample to count as static [rad/s].
        settle_s: A sample counts as static only after the robot has rested this long [s].
        refit_friction: ``motion`` only: fit a change of each joint's Coulomb friction along
            with the payload (gear friction grows with the transmitted torque).
        reference: ``motion`` only: a run of the same trajectory without the payload, whose
            residual is subtracted (module docstring).

    Returns:
        The estimate.

    Raises:
        DataError: Unknown method, too little motion or too few static samples; a
            ``reference`` with ``static``, for another robot, not overlapping the recording
            in time or on another path.

    Warns:
        DataWarning: A mass significantly below zero (no payload, or a model that does not
            fit).
    """
    if method not in ("motion", "static"):
        raise DataError("unknown method", field="method", value=method,
                        expected="'motion' or 'static'")
    if method == "static" and reference is not None:
        raise DataError("an unloaded reference run is used only from motion", field="method",
                        value=method, expected="'motion' with a reference")
    data = rec if isinstance(rec, ProcessedData) else preprocess(rec, robot, preprocess_config)
    shift = None
    if method == "static":
        system = _static_system(data, robot, params, static_velocity, settle_s)
    else:
        system = _motion_system(data, robot, params, refit_friction)
    if reference is not None:
        ref = reference if isinstance(reference, ProcessedData) else preprocess(
            reference, robot, preprocess_config)
        system, shift = _against_reference(system, data, ref, robot, params)
    A = system.regressor[system.used][:, system.columns]
    b = system.residual[system.used]
    norms = np.linalg.norm(A, axis=0)
    if norms[0] <= 0:
        raise DataError("the payload mass is not observable in this recording",
                        source=data.source, field="q", expected="motion or poses under gravity")
    sol, keep, mass_std = _fit(A, b, norms, system.used)
    mass = float(sol[0])
    if mass < -SIGNIFICANT_SIGMAS * mass_std:
        where = f"{data.source}: " if data.source else ""
        warnings.warn(f"{where}the estimated payload mass is negative ({mass:.3f} ± "
                      f"{mass_std:.3f} kg): no payload is attached, or the unloaded model does "
                      "not fit this recording", DataWarning, stacklevel=2)
    used, residual = system.used, system.residual
    fitted = np.zeros_like(residual)
    fitted[used] = A @ sol
    err = np.where(used, residual - fitted, 0.0)
    rms = np.sqrt((err**2).sum(axis=0) / np.maximum(used.sum(axis=0), 1))
    g = float(np.linalg.norm(robot.model.gravity.linear))
    return PayloadEstimate(method=method, mass_kg=mass, mass_std_kg=mass_std,
                           weight_n=mass * g, com_tcp=_com(robot, A, norms, sol, keep, mass_std),
                           samples=int(used.sum()), residual_rms=rms, reference_shift_s=shift)


def _com(robot: Robot, A: Array, norms: Array, sol: Array, keep: NDArray[np.bool_],
         mass_std: float) -> Array | None:
    """The payload's CoM in the TCP frame [m], or None where the motion does not excite the
    first moments or the mass is within :data:`SIGNIFICANT_SIGMAS` of zero."""
    # identifiability of the CoM: the three first-moment columns must be well conditioned
    sv = np.linalg.svd(A[:, 1:4] / np.maximum(norms[1:4], 1e-300), compute_uv=False)
    mass = float(sol[0])
    # the CoM is a first moment divided by the mass: only where the mass is clearly nonzero
    if mass > SIGNIFICANT_SIGMAS * mass_std and sv[-1] > 1e-3 * sv[0] and np.all(keep[1:4]):
        frame = robot.model.frames[robot.tcp_frame_id]
        return np.asarray(frame.placement.actInv(sol[1:4] / mass))
    return None


class _PayloadSystem(NamedTuple):
    """The payload's linear system: regressor (samples, n, columns), residual torque of the
    unloaded model (samples, n), which entries are used, which columns are fitted (the last
    link's m, m·c, inertia, and re-fitted Coulomb terms)."""

    regressor: Array
    residual: Array
    used: NDArray[np.bool_]
    columns: NDArray[np.int64]


def _motion_system(data: ProcessedData, robot: Robot, params: DriveModelParameters,
                   refit_friction: bool) -> _PayloadSystem:
    """In motion: the last link's 10 parameters (and, refitted, each joint's Coulomb term) from
    the moving samples."""
    n, model = robot.n, robot.model
    last = n  # joint index of the last link in the Pinocchio model
    K = link_regressor_batch(model, data.q, data.qd, data.qdd)[:, :, 10 * (last - 1):]
    residual = data.torque - model_torque(robot, params, data.q, data.qd, data.qdd)
    cols = np.arange(10 + n)
    if refit_friction:
        # gear friction grows with the transmitted load: re-fit each joint's Coulomb term
        coulomb = np.zeros((data.samples, n, n))
        coulomb[:, np.arange(n), np.arange(n)] = np.sign(data.qd)
        K = np.concatenate([K, coulomb], axis=2)
    else:
        cols = np.arange(10)
    return _PayloadSystem(K, residual, data.moving, cols)


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


def _against_reference(system: _PayloadSystem, data: ProcessedData, ref: ProcessedData,
                       robot: Robot, params: DriveModelParameters
                       ) -> tuple[_PayloadSystem, float]:
    """``system`` with the unloaded run ``ref``'s residual subtracted, at the same point of
    the path (:func:`reference_shift`), on the loaded run's samples that ``ref`` covers and
    where both move; and the shift [s]."""
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
    return _PayloadSystem(system.regressor[inside], residual, system.used[inside] & moving_ref,
                          system.columns), shift


def _static_system(data: ProcessedData, robot: Robot, params: DriveModelParameters,
                   static_velocity: float, settle_s: float) -> _PayloadSystem:
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
    static_model = model_torque(robot, _without_friction(params), data.q[still], zero, zero)
    residual = data.torque[still] - static_model
    return _PayloadSystem(K, residual, np.ones(residual.shape, dtype=bool), np.arange(4))


def _fit(A: Array, b: Array, norms: Array, used: NDArray[np.bool_]
         ) -> tuple[Array, NDArray[np.bool_], float]:
    """Least squares on the columns scaled to unit norm (columns of no norm dropped): the
    solution, the kept columns and the mass's standard error.

    For residuals correlated in time the standard error is that of independent samples times
    the largest (1 + ρ)/(1 − ρ) over the joints (ρ the lag-1 autocorrelation of a joint's
    residual); column 0 (the mass) is always kept (its norm is > 0)."""
    keep = norms > 1e-9 * norms.max()
    sol = np.zeros(A.shape[1])
    An = A[:, keep] / norms[keep]
    fit, *_ = np.linalg.lstsq(An, b, rcond=None)
    sol[keep] = fit / norms[keep]
    r = b - An @ fit
    dof = max(b.size - An.shape[1], 1)
    sigma2 = float(np.sum(r**2)) / dof * _correlation_factor(r, used)
    mass_std = float(np.sqrt(sigma2 * np.linalg.pinv(An.T @ An)[0, 0])) / norms[0]
    return sol, keep, mass_std


def _correlation_factor(residual: Array, used: NDArray[np.bool_]) -> float:
    """max over the joints of (1 + ρ)/(1 − ρ), ρ the lag-1 autocorrelation of the joint's
    residual (``residual`` stacked sample-major as ``used``'s True entries), in [1, samples]."""
    full = np.zeros(used.shape)
    full[used] = residual
    worst = 1.0
    for j in range(used.shape[1]):
        e = full[used[:, j], j]
        if e.size < 3 or not np.any(e):
            continue
        rho = float(np.dot(e[:-1], e[1:]) / np.dot(e, e))
        rho = min(max(rho, 0.0), 1.0 - 1.0 / e.size)
        worst = max(worst, (1.0 + rho) / (1.0 - rho))
    return worst


def _without_friction(params: DriveModelParameters) -> DriveModelParameters:
    """The same parameters with all friction set to zero (static torque at rest)."""
    from dataclasses import replace

    from leadthrough.dynamics.friction import StribeckParameters

    z = np.zeros_like(params.rotor_inertia)
    st = None if params.stribeck is None else StribeckParameters(
        f1=z, f2=z, qd_sm=params.stribeck.qd_sm, f3=z, qd_sg=params.stribeck.qd_sg, f4=z)
    return replace(params, stribeck=st, coulomb=np.zeros(0) if not params.coulomb.size else z,
                   viscous=np.zeros(0) if not params.viscous.size else z,
                   cbrt=np.zeros(0) if not params.cbrt.size else z, load_friction=np.zeros(0))
