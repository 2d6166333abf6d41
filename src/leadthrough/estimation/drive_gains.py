"""The drives' gains and the gears' load friction, measured with a known mass.

The identification reads torque from the currents through the drive file's R·Kt. A drive's true
torque constant differs from its datasheet by a few per cent (motor tolerances, magnet
temperature), and nothing in currents alone gives that scale: a model identified from them is
in the drive file's units and still fits them exactly. It shows where a torque of known size
is read: a known payload. Following Gautier and Briot ("New method for global identification
of the joint drive gains of robots using a known inertial payload", IROS 2011), the robot runs
one trajectory without and with a known mass; the difference of the two runs' torques at the
same point of the path (:mod:`leadthrough.estimation.payload_system`) is the known payload's
torque y = K_last·φ_known, read through each joint's gain and grown by the gear's load friction:

    d_j = y_j / c_j + f_cL,j·sgn(q̇_j)·(|τ_load,j + y_j| − |τ_load,j|) / c_j + Δf_j·sgn(q̇_j)

with c_j the true torque per drive-file torque, f_cL,j the gear's Coulomb friction per N·m
transmitted, Δf_j a change of its Coulomb level between the runs (warm-up), and τ_load the
identified model's link torque. Per joint that is linear in (1/c_j, f_cL,j/c_j, Δf_j). Unlike
f_cL identified from the unloaded robot's own load variation, this measures the gear under the
payload's load, as a payload estimate needs it.

A joint's gain is **applied** (used by :func:`leadthrough.estimation.payload.estimate_payload`)
only where the known payload loads it enough to give the gain to :data:`MAX_RELATIVE_STD`: a
payload's weight loads the shoulder and elbow; a vertical first axis sees only its inertia.

Not used by the force estimator (a scale error there is small beside its other errors: README).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.data.preprocess import PreprocessConfig, ProcessedData, preprocess
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_LOAD_FRICTION, DriveModelParameters
from leadthrough.errors import DataError
from leadthrough.estimation.payload_system import (
    PAYLOAD_COLUMNS,
    PayloadSystem,
    against_reference,
    correlation_factor,
    motion_system,
)
from leadthrough.robot.description import Robot

__all__ = ["MAX_RELATIVE_STD", "DriveGains", "KnownPayload", "estimate_drive_gains"]

Array = NDArray[np.float64]

#: A gain is applied only where its standard error is at most this fraction of it: a gain known
#: less well would not make a payload estimate better than the per cent it aims for.
MAX_RELATIVE_STD = 0.01

#: A joint's equations used in the fit must be at least this many.
MIN_SAMPLES = 50


@dataclass(frozen=True)
class KnownPayload:
    """A payload of known inertia, rigidly attached at the TCP.

    Attributes:
        mass_kg: Mass [kg], > 0.
        com_tcp: Centre of mass in the TCP frame [m], shape (3,).
        inertia_com: Rotational inertia about the CoM in the TCP frame [kg·m²], shape (3, 3),
            symmetric positive semidefinite; None for a point mass (a compact test weight's
            own inertia is small beside its mass's at the arm's reach).
    """

    mass_kg: float
    com_tcp: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_com: tuple[tuple[float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass_kg) and self.mass_kg > 0.0):
            raise DataError("the known payload's mass must be positive",
                            field="known_payload.mass_kg", value=self.mass_kg,
                            expected="a finite mass > 0 kg")
        com = np.asarray(self.com_tcp, dtype=float)
        if com.shape != (3,) or not np.all(np.isfinite(com)):
            raise DataError("the known payload's CoM must be 3 finite numbers",
                            field="known_payload.com_tcp", value=self.com_tcp,
                            expected="(x, y, z) in metres, in the TCP frame")
        inertia = self.inertia()
        if (inertia.shape != (3, 3) or not np.all(np.isfinite(inertia))
                or not np.allclose(inertia, inertia.T, atol=1e-12)
                or np.diag(inertia).min() < 0.0
                or np.linalg.eigvalsh(0.5 * (inertia + inertia.T)).min() < -1e-12):
            raise DataError("the known payload's inertia must be a symmetric positive "
                            "semidefinite 3×3 matrix", field="known_payload.inertia_com",
                            value=self.inertia_com, expected="kg·m² about the CoM, or none")

    def inertia(self) -> Array:
        """Rotational inertia about the CoM [kg·m²], shape (3, 3) (zeros for a point mass)."""
        if self.inertia_com is None:
            return np.zeros((3, 3))
        return np.asarray(self.inertia_com, dtype=float)

    def parameters(self, robot: Robot) -> Array:
        """Its 10 inertial parameters in the last joint's frame (eq. 2's order), shape (10,)."""
        tcp = robot.model.frames[robot.tcp_frame_id].placement
        inertia = pin.Inertia(self.mass_kg, np.asarray(self.com_tcp, dtype=float),
                              self.inertia())
        return np.asarray(tcp.act(inertia).toDynamicParameters(), dtype=float)


@dataclass(frozen=True)
class DriveGains:
    """The drives' gains and the gears' load friction, measured with a known payload.

    Attributes:
        robot: Name of the robot.
        gain: c per joint, the true torque per torque read through the drive file's R·Kt [-],
            shape (n,); 1 where the known payload does not load the joint.
        gain_std: Standard error of each gain [-], shape (n,) (allowing for the residual's
            correlation in time); inf where the joint is not loaded.
        load_friction: f_cL per joint [-], shape (n,), >= 0 (0 where not applied).
        applied: Which joints' gains and load friction a payload estimate uses (relative
            standard error at most :data:`MAX_RELATIVE_STD`), shape (n,).
        known: The known payload.
        reference_shift_s: The time [s] by which the unloaded run was shifted onto the loaded
            run's path.
        samples: Joint equations used.
    """

    robot: str
    gain: Array
    gain_std: Array
    load_friction: Array
    applied: NDArray[np.bool_]
    known: KnownPayload = field(repr=False)
    reference_shift_s: float = 0.0
    samples: int = 0


def estimate_drive_gains(
    loaded: Recording | ProcessedData,
    unloaded: Recording | ProcessedData,
    robot: Robot,
    params: DriveModelParameters,
    known: KnownPayload,
    preprocess_config: PreprocessConfig | None = None,
) -> DriveGains:
    """Measure the drives' gains from a run with a known payload and one without.

    Args:
        loaded: A run of a trajectory with ``known`` attached (currents or torques).
        unloaded: A run of the same trajectory without it.
        robot: The robot.
        params: Identified parameters of the unloaded robot (for the link torque the gears
            carry and for the two runs' small difference of states).
        known: The known payload.
        preprocess_config: Filtering settings (default: as calibration).

    Returns:
        The gains.

    Raises:
        DataError: The runs do not overlap or follow different paths (another trajectory,
            or a mass that takes a drive to its limit), or the known payload loads no joint
            enough to measure its gain.
    """
    data = loaded if isinstance(loaded, ProcessedData) else preprocess(
        loaded, robot, preprocess_config)
    ref = unloaded if isinstance(unloaded, ProcessedData) else preprocess(
        unloaded, robot, preprocess_config)
    try:
        system, shift = against_reference(motion_system(data, robot, params, True), data, ref,
                                          robot, params)
    except DataError as e:
        if e.message != "the reference run follows another path":
            raise
        raise DataError("the runs with and without the known mass follow different paths",
                        source=data.source, field=e.field, value=e.value,
                        expected=f"{e.expected}; the same trajectory both times, with a mass "
                                 "its drives carry without reaching their limits") from e
    y = system.regressor[:, :, :PAYLOAD_COLUMNS] @ known.parameters(robot)
    n = robot.n
    gain, std, load = np.ones(n), np.full(n, np.inf), np.zeros(n)
    for j in range(n):
        gain[j], std[j], load[j] = _joint_gain(system, y, j)
    applied = np.isfinite(std) & (std <= MAX_RELATIVE_STD * gain)
    if not applied.any():
        j = int(np.argmin(std / gain))
        raise DataError("the known payload loads no joint enough to measure its drive gain",
                        source=data.source, field=f"gain_std[{j}]", value=float(std[j]),
                        expected=f"<= {MAX_RELATIVE_STD:.0%} of the gain on some joint "
                                 "(a heavier known mass, or a trajectory that moves it "
                                 "against gravity)")
    return DriveGains(robot=robot.name, gain=gain, gain_std=std,
                      load_friction=np.where(applied, load, 0.0), applied=applied, known=known,
                      reference_shift_s=shift, samples=int(system.used.sum()))


def _joint_gain(system: PayloadSystem, y: Array, j: int) -> tuple[float, float, float]:
    """Joint j's gain c, its standard error and f_cL (module docstring's equation, least
    squares; f_cL held at 0 where it would fit negative); (1, inf, 0) where the joint's
    equations cannot give it."""
    used = system.used[:, j]
    if used.sum() < MIN_SAMPLES or not np.any(y[used, j]):
        return 1.0, float("inf"), 0.0
    yj, sign, tau = y[used, j], system.velocity_sign[used, j], system.load_torque[used, j]
    load = sign * (np.abs(tau + yj) - np.abs(tau))
    b = system.residual[used, j]
    A = np.stack([yj, sign, load], axis=1)
    sol, cov = _least_squares(A, b)
    if sol[2] < 0.0:                        # no negative friction: refit without the term
        sol, cov = _least_squares(A[:, :2], b)
        sol, cov = np.append(sol, 0.0), np.pad(cov, (0, 1))
    inverse = float(sol[0])                 # 1/c
    if inverse <= 0.0:
        return 1.0, float("inf"), 0.0
    mu = float(sol[2]) / inverse
    if mu >= MAX_LOAD_FRICTION:
        return 1.0, float("inf"), 0.0
    return 1.0 / inverse, float(np.sqrt(cov[0, 0])) / inverse**2, mu


def _least_squares(A: Array, b: Array) -> tuple[Array, Array]:
    """The solution and its covariance, with the residual's variance inflated by its
    :func:`~leadthrough.estimation.payload_system.correlation_factor` (a smooth residual is
    worth fewer independent samples)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    An = A / scale
    sol, *_ = np.linalg.lstsq(An, b, rcond=None)
    r = b - An @ sol
    dof = max(b.size - A.shape[1], 1)
    sigma2 = float(r @ r) / dof * correlation_factor(r)
    cov = sigma2 * np.linalg.pinv(An.T @ An) / np.outer(scale, scale)
    return sol / scale, cov
