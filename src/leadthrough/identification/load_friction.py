"""Identification of the load-dependent Coulomb friction f_cL, by fixed-point iteration.

The Coulomb level of every friction model may grow with the torque the gear transmits,
f_c0 + f_cL·|τ_load| (Bittencourt, Wernholt, Sander-Tavallaey and Brogårdh, "An extended
friction model to capture load and temperature effects in robot joints", IROS 2010; Bittencourt
and Axelsson, "Modeling and experiment design for identification of wear in a robot joint under
load and temperature uncertainties based on friction data", IEEE/ASME Trans. Mechatronics,
2014; :func:`leadthrough.dynamics.friction.coulomb_level`).

**Which τ_load.** Here τ_load is the link torque K(q, q̇, q̈)·φ of the identified links at the
processed (zero-phase filtered) state, the torque the gear passes to the link when no external
force acts, which is what a calibration run records. The alternative, the measured drive
torque minus friction and rotor inertia, is the same torque plus the measurement's noise; as a
regressor column that noise would correlate with the torque being fitted (errors in variables)
and bias f_cL upward, since |τ + noise| > |τ| on average. The link model's torque is a function
of the state and the parameters only, and it is also what :func:`leadthrough.dynamics.model.
model_torque` uses, so the identification and the offline model agree. (The real-time estimator
uses the measured torque instead: there the operator's push is part of what the gear carries,
see :mod:`leadthrough.estimation.estimator_step`.)

**How.** Once τ_load is known the model is linear in f_cL (the column |τ_load|·sgn(q̇), with
the same sign as the Coulomb column), but τ_load depends on the link parameters being
identified. So the methods alternate:

1. identify without the load term;
2. τ_load = K·φ of the identified links;
3. identify again with the column f_cL·|τ_load|·sgn(q̇), f_cL >= 0;
4. repeat 2–3 until τ_load changes by less than ``tolerance`` (RMS, relative) or after
   ``iterations`` re-identifications.

f_cL is a few percent, so φ, and with it τ_load, moves little from one pass to the next: τ_load
changes by 1–3 % in the first re-identification and 3–30 times less in each one after (UR10e,
KR300, UR5 logs), so the default tolerance of 1e-4 takes three to four.

**Which joints.** A joint whose gear hardly carries a varying load (a wrist without a tool) has a
load column that the Coulomb, viscous and offset columns nearly explain: its f_cL is not
identifiable, and on the real UR5 such joints drive it to the bound (wrist 3 at 50 %) while
making the held-out force estimate worse. So f_cL is fitted only where its largest admissible
value changes the torque, beyond those columns, by more than the joint's residual noise:
``upper`` · RMS(load column ⊥ [sgn(q̇), q̇, 1]) > σ_j (σ_j the residual's standard deviation of the
pass without the load term; :func:`load_excitation`). Elsewhere f_cL stays 0: the calibration
cannot see it, and an unidentified f_cL would scale the estimator's view of a push.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.friction import load_friction_column
from leadthrough.dynamics.model import DriveModelParameters, model_torque
from leadthrough.identification.observations import Observations

__all__ = ["LoadFrictionFit", "LoadTerm", "identify_load_friction", "load_excitation",
           "load_torque"]

Array = NDArray[np.float64]


class LoadTerm(NamedTuple):
    """What one identification needs to fit f_cL.

    Attributes:
        torque: τ_load at the samples [N·m], shape (N, n).
        upper: Largest f_cL to accept per joint [-], shape (n,) (the fit's bound; f_cL >= 0
            always; 0: the joint's f_cL is not fitted and stays 0).
    """

    torque: Array
    upper: Array


#: A method run with a given load term (None: without): its parameters and its own iteration
#: count.
Solve = Callable[[LoadTerm | None], tuple[DriveModelParameters, int]]


@dataclass(frozen=True)
class LoadFrictionFit:
    """The outcome of the iteration.

    Attributes:
        params: The parameters of the last pass (with ``load_friction``).
        passes: Identifications run, the first (without the load term) included.
        iterations: The methods' own iterations, summed over the passes.
        change: Relative RMS change of τ_load over the used equations before the last pass
            [-] (``converged`` when <= the tolerance).
        converged: Whether τ_load settled within the tolerance.
        fitted: Joints whose f_cL was fitted (:func:`load_excitation`), shape (n,).
    """

    params: DriveModelParameters
    passes: int
    iterations: int
    change: float
    converged: bool
    fitted: NDArray[np.bool_]


def load_torque(obs: Observations, phi: Array) -> Array:
    """τ_load = K·φ, the link torque of links ``phi`` at the observations' samples.

    Args:
        obs: The observations (their link regressor K, shape (N, n, 10·n)).
        phi: Standard link parameters, shape (10·n,).

    Returns:
        τ_load [N·m], shape (N, n).
    """
    return np.asarray(np.einsum("tjk,k->tj", obs.K, phi))


def load_excitation(obs: Observations, load: Array, params: DriveModelParameters
                    ) -> tuple[Array, Array]:
    """How well each joint's data can tell its f_cL: the load column's RMS beyond the Coulomb,
    viscous and offset columns, and the residual noise it has to stand out of.

    Args:
        obs: The observations.
        load: τ_load at the samples [N·m], shape (N, n).
        params: The parameters without the load term (their residual gives σ_j).

    Returns:
        RMS of |τ_load|·sgn(q̇) orthogonal to [sgn(q̇), q̇, 1] over the joint's used equations
        [N·m], and σ_j of the residual [N·m], each shape (n,).
    """
    data = obs.data
    residual = data.torque - model_torque(obs.robot, params, data.q, data.qd, data.qdd)
    excitation, sigma = np.zeros(obs.robot.n), np.zeros(obs.robot.n)
    for j in range(obs.robot.n):
        u = obs.used[:, j]
        qd = data.qd[u, j]
        column = load_friction_column(qd, load[u, j])
        others = np.column_stack([np.sign(qd), qd, np.ones(qd.size)])
        beyond = column - others @ np.linalg.lstsq(others, column, rcond=None)[0]
        excitation[j] = float(np.sqrt(np.mean(beyond**2)))
        sigma[j] = float(np.std(residual[u, j]))
    return excitation, sigma


def identify_load_friction(obs: Observations, solve: Solve, iterations: int = 6,
                           tolerance: float = 1e-4, upper: float = 0.5) -> LoadFrictionFit:
    """Identify a method's parameters with the load-dependent friction, by iteration.

    Args:
        obs: The observations.
        solve: The method, run with the load term (or None for the first pass).
        iterations: Most re-identifications with the load term (>= 1).
        tolerance: Relative RMS change of τ_load at which the iteration stops [-].
        upper: Largest f_cL accepted [-]; also sets which joints are fitted (module
            docstring).

    Returns:
        The last pass's parameters and the iteration's figures.
    """
    params, its = solve(None)
    total, passes = its, 1
    used = obs.used
    tau = load_torque(obs, params.phi)
    excitation, sigma = load_excitation(obs, tau, params)
    fitted = upper * excitation > sigma
    if not fitted.any():
        return LoadFrictionFit(params=replace(params, load_friction=np.zeros(obs.robot.n)),
                               passes=passes, iterations=total, change=0.0, converged=True,
                               fitted=fitted)
    bound = np.where(fitted, upper, 0.0)
    change = np.inf
    for _ in range(iterations):
        params, its = solve(LoadTerm(tau, bound))
        total += its
        passes += 1
        new = load_torque(obs, params.phi)
        change = float(np.linalg.norm((new - tau)[used])
                       / max(float(np.linalg.norm(new[used])), 1e-12))
        tau = new
        if change <= tolerance:
            break
    return LoadFrictionFit(params=params, passes=passes, iterations=total, change=change,
                           converged=change <= tolerance, fitted=fitted)
