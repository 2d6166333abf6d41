"""The regressors of processed data, shared by every identification method.

Also the excitation checks that turn rank-deficient data into a clear error (a joint that never
moves, a parameter nothing in the data excites), and the mapping from base parameters back to
standard parameters closest to nominal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from leadthrough.data.preprocess import ProcessedData
from leadthrough.dynamics.base_parameters import (
    BaseParameters,
    compute_base_parameters,
    rotor_columns,
)
from leadthrough.dynamics.regressor import link_regressor_batch, standard_parameters
from leadthrough.errors import DataError
from leadthrough.robot.description import Robot

__all__ = ["MIN_MOVING_FRACTION", "Observations", "build_observations", "solve_least_squares"]

Array = NDArray[np.float64]
MIN_MOVING_FRACTION = 0.05


@dataclass(frozen=True, eq=False)
class Observations:
    """Regressors evaluated on processed data.

    Attributes:
        robot: The robot.
        data: The processed samples.
        K: Link regressor, shape (N, n, 10·n).
        K_rotor: Rotor-inertia columns, shape (N, n, n).
        base_link: Base parameters of the links alone.
        base_aug: Base parameters of links + rotor inertias.
        x_nominal: Nominal [φ; M_j] (CAD links, datasheet rotor inertia), shape (11·n,).
    """

    robot: Robot
    data: ProcessedData
    K: Array
    K_rotor: Array
    base_link: BaseParameters
    base_aug: BaseParameters
    x_nominal: Array

    @property
    def used(self) -> NDArray[np.bool_]:
        """Joint equations used for identification (moving), shape (N, n)."""
        return self.data.moving

    def standard_from_base(self, beta: Array, aug: bool) -> tuple[Array, Array]:
        """Standard link parameters φ and rotor inertias M closest to nominal with C·x = β.

        Args:
            beta: Base parameters, of ``base_aug`` if ``aug`` else of ``base_link``.
            aug: Whether ``beta`` includes the rotor inertias.

        Returns:
            φ, shape (10·n,), and M, shape (n,); M is zero when not ``aug`` (a model
            without rotor inertia, whose M_1, M_2 effects are then merged into φ).
        """
        n = self.robot.n
        if aug:
            C = self.base_aug.combination
            x0 = self.x_nominal
        else:
            C = self.base_link.combination
            x0 = self.x_nominal[: 10 * n]
        x = x0 + np.linalg.pinv(C) @ (beta - C @ x0)
        if aug:
            return x[: 10 * n], x[10 * n:]
        return x, np.zeros(n)


def build_observations(robot: Robot, data: ProcessedData) -> Observations:
    """Evaluate the regressors and check the data excite every joint.

    Raises:
        DataError: A joint barely moves (its friction cannot be identified).
    """
    n = robot.n
    if data.q.shape[1] != n:
        raise DataError("joint count does not match the robot", source=data.source, field="q",
                        value=data.q.shape[1], expected=f"{n} joints for '{robot.name}'")
    frac = data.moving.mean(axis=0)
    for j in range(n):
        if frac[j] < MIN_MOVING_FRACTION:
            raise DataError(
                f"joint '{robot.joint_names[j]}' barely moves (|q̇| above the standstill "
                f"threshold in {100 * frac[j]:.1f} % of samples): its parameters cannot be "
                "identified", source=data.source, field=f"q[{robot.joint_names[j]}]",
                expected=f">= {100 * MIN_MOVING_FRACTION:.0f} % moving samples; record an "
                         "excitation trajectory that moves every joint")
    K = link_regressor_batch(robot.model, data.q, data.qd, data.qdd)
    x_nom = np.concatenate([standard_parameters(robot.model), robot.reflected_rotor_inertia])
    return Observations(
        robot=robot, data=data, K=K, K_rotor=rotor_columns(data.qdd),
        base_link=compute_base_parameters(robot.model),
        base_aug=compute_base_parameters(robot.model, include_rotor=True),
        x_nominal=x_nom,
    )


def solve_least_squares(
    Y: Array, tau: Array, used: NDArray[np.bool_], names: list[str], source: str | None,
    bounds: tuple[Array, Array] | None = None,
) -> Array:
    """Ordinary least squares over the used joint equations (pseudo-inverse, paper eq. 10).

    Args:
        Y: Observation matrix per sample, shape (N, n, p).
        tau: Measured torque, shape (N, n).
        used: Equations to use, shape (N, n).
        names: Parameter names, length p (for error messages).
        source: Data source (for error messages).
        bounds: Lower and upper bound of each parameter, shapes (p,) (±inf: free), or None.
            Where the unconstrained solution violates one, the bounded least-squares problem is
            solved exactly (SciPy's ``lsq_linear``, bounded-variable least squares).

    Returns:
        The estimate, shape (p,).

    Raises:
        DataError: The data do not excite some parameter (rank deficiency), naming it.
    """
    A = Y[used]
    b = tau[used]
    norms = np.linalg.norm(A, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    An = A / scale
    _, s, Vt = np.linalg.svd(An, full_matrices=False)
    if s[-1] < 1e-8 * s[0]:
        worst = np.argsort(-np.abs(Vt[-1]))[:3]
        culprits = ", ".join(names[k] for k in worst)
        raise DataError(f"the data do not excite all parameters (condition {s[0] / s[-1]:.1e});"
                        f" least excited: {culprits}", source=source, field="excitation",
                        expected="a recording that moves every joint over its range "
                                 "(leadthrough excite)")
    sol, *_ = np.linalg.lstsq(An, b, rcond=None)
    if bounds is not None and np.any((sol / scale < bounds[0]) | (sol / scale > bounds[1])):
        sol = scipy.optimize.lsq_linear(An, b, bounds=(bounds[0] * scale, bounds[1] * scale),
                                        method="bvls").x
    return np.asarray(sol / scale)
