"""Payload identification with the identified model of the unloaded robot (paper Table III).

A payload rigidly attached to the last link adds its inertial parameters φ_p to that link, so
the joint torque grows by K_last(q, q̇, q̈)·φ_p (the last link's 10 regressor columns). With the
unloaded model τ̂_d identified beforehand, φ_p is the least-squares fit of the residual
r = τ_measured − τ̂_d over the recording (the system: :mod:`leadthrough.estimation.payload_system`):

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
payload has the same error: with it, the fit takes the difference of the two runs' residuals
at the same point of the path, and the model's error along the path cancels; the model still
accounts for the small difference between the two runs' states (the loaded robot follows the
trajectory a little differently). Both runs must follow the same path.

**What the payload itself changes** cannot cancel: a drive whose torque constant differs from
the drive file's reads the payload's torque scaled (``drive_gains``, measured with a known mass:
:mod:`leadthrough.estimation.drive_gains`), and a gear's friction grows with the load it
carries. Where the drive gains give the gears' load coefficients f_cL (measured under the known
mass's load), the payload's share of that growth is part of its columns; since it depends on the
payload's torque (|τ_load + y| − |τ_load|), the fit is repeated with the columns of the last
estimate until the mass settles (:data:`MAX_ITERATIONS`). The constant part of the friction's
change is fitted anyway (``refit_friction``). The f_cL identified from the unloaded robot's own
load variation (``params.load_friction``) is not used for this: tried on the simulated er20's
held-out instances 3 and 4, it made the payload 0.4 % heavier, further off (README, Table III).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.preprocess import PreprocessConfig, ProcessedData, preprocess
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.errors import DataError, DataWarning
from leadthrough.estimation.drive_gains import DriveGains
from leadthrough.estimation.payload_system import (
    PAYLOAD_COLUMNS,
    PayloadSystem,
    against_reference,
    correlation_factor,
    motion_system,
    payload_regressor,
    reference_shift,
    static_system,
)
from leadthrough.robot.description import Robot

__all__ = ["PayloadEstimate", "estimate_payload", "reference_shift"]

Array = NDArray[np.float64]


#: A mass this many standard errors from zero is significant: only then is the CoM reported
#: (for a positive mass) or a negative mass warned about.
SIGNIFICANT_SIGMAS = 5.0

#: The fit with the payload's own load friction is repeated at most this often, until the mass
#: changes by less than :data:`SETTLED_KG`.
MAX_ITERATIONS, SETTLED_KG = 10, 1e-9


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
        iterations: Fits made (more than one where the payload's own load friction is
            modelled: module docstring).
    """

    method: str
    mass_kg: float
    mass_std_kg: float
    weight_n: float
    com_tcp: Array | None
    samples: int
    residual_rms: Array
    reference_shift_s: float | None = None
    iterations: int = 1


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
    drive_gains: DriveGains | None = None,
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
        drive_gains: The drives' gains and load friction measured with a known mass
            (:func:`leadthrough.estimation.drive_gains.estimate_drive_gains`); None: the drive
            file's gains, and the payload's own load friction not modelled.

    Returns:
        The estimate.

    Raises:
        DataError: Unknown method, too little motion or too few static samples; a
            ``reference`` with ``static``, for another robot, not overlapping the recording
            in time or on another path; ``drive_gains`` of another robot.

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
    gain, load_friction = _drive_terms(robot, drive_gains)
    data = rec if isinstance(rec, ProcessedData) else preprocess(rec, robot, preprocess_config)
    shift = None
    if method == "static":
        system = static_system(data, robot, params, static_velocity, settle_s)
    else:
        system = motion_system(data, robot, params, refit_friction)
    if reference is not None:
        ref = reference if isinstance(reference, ProcessedData) else preprocess(
            reference, robot, preprocess_config)
        system, shift = against_reference(system, data, ref, robot, params)
    A, norms, sol, keep, mass_std, iterations = _settled_fit(system, gain, load_friction,
                                                             data.source)
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
                           samples=int(used.sum()), residual_rms=rms, reference_shift_s=shift,
                           iterations=iterations)


def _drive_terms(robot: Robot, drive_gains: DriveGains | None) -> tuple[Array, Array]:
    """The drives' gains c and the gears' load coefficients f_cL the payload's columns take
    (:func:`leadthrough.estimation.payload_system.payload_regressor`), each shape (n,): the
    measured ones where applied, else the drive file's gain and no load friction."""
    if drive_gains is None:
        return np.ones(robot.n), np.zeros(robot.n)
    if drive_gains.robot != robot.name or drive_gains.gain.shape != (robot.n,):
        raise DataError("drive gains of another robot", field="drive_gains.robot",
                        value=drive_gains.robot, expected=f"{robot.name} ({robot.n} joints)")
    applied = drive_gains.applied
    return (np.where(applied, drive_gains.gain, 1.0),
            np.where(applied, drive_gains.load_friction, 0.0))


def _settled_fit(system: PayloadSystem, gain: Array, load_friction: Array, source: str | None
                 ) -> tuple[Array, Array, Array, NDArray[np.bool_], float, int]:
    """The fit of the payload's columns as the currents read them, repeated with the last
    estimate's columns while the payload's own load friction moves the mass (module
    docstring): the fitted matrix, its column norms, the solution, the kept columns, the mass's
    standard error and the number of fits."""
    phi = np.zeros(PAYLOAD_COLUMNS)
    b = system.residual[system.used]
    fits = 0
    while True:
        fits += 1
        regressor = payload_regressor(system, phi, gain, load_friction)
        A = regressor[system.used][:, system.columns]
        norms = np.linalg.norm(A, axis=0)
        if norms[0] <= 0:
            raise DataError("the payload mass is not observable in this recording",
                            source=source, field="q", expected="motion or poses under gravity")
        sol, keep, mass_std = _fit(A, b, norms, system.used)
        payload = min(PAYLOAD_COLUMNS, system.columns.size)
        settled = abs(sol[0] - phi[0]) <= SETTLED_KG
        phi = np.zeros(PAYLOAD_COLUMNS)
        phi[:payload] = sol[:payload]
        if not np.any(load_friction > 0.0) or settled or fits == MAX_ITERATIONS:
            return A, norms, sol, keep, mass_std, fits


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
    """max over the joints of :func:`correlation_factor` of the joint's residual
    (``residual`` stacked sample-major as ``used``'s True entries), in [1, samples]."""
    full = np.zeros(used.shape)
    full[used] = residual
    return max([1.0, *(correlation_factor(full[used[:, j], j]) for j in range(used.shape[1]))])
