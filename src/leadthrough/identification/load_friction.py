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

f_cL is a few percent, so φ, and with it τ_load, moves little from one pass to the next: the
iteration contracts in two to three passes on the real logs and the simulated robot.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.identification.observations import Observations

__all__ = ["LoadFrictionFit", "LoadTerm", "identify_load_friction", "load_torque"]

Array = NDArray[np.float64]


class LoadTerm(NamedTuple):
    """What one identification needs to fit f_cL.

    Attributes:
        torque: τ_load at the samples [N·m], shape (N, n).
        upper: Largest f_cL to accept [-] (the fit's bound; f_cL >= 0 always).
    """

    torque: Array
    upper: float


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
    """

    params: DriveModelParameters
    passes: int
    iterations: int
    change: float
    converged: bool


def load_torque(obs: Observations, phi: Array) -> Array:
    """τ_load = K·φ, the link torque of links ``phi`` at the observations' samples.

    Args:
        obs: The observations (their link regressor K, shape (N, n, 10·n)).
        phi: Standard link parameters, shape (10·n,).

    Returns:
        τ_load [N·m], shape (N, n).
    """
    return np.asarray(np.einsum("tjk,k->tj", obs.K, phi))


def identify_load_friction(obs: Observations, solve: Solve, iterations: int = 6,
                           tolerance: float = 1e-4, upper: float = 0.5) -> LoadFrictionFit:
    """Identify a method's parameters with the load-dependent friction, by iteration.

    Args:
        obs: The observations.
        solve: The method, run with the load term (or None for the first pass).
        iterations: Most re-identifications with the load term (>= 1).
        tolerance: Relative RMS change of τ_load at which the iteration stops [-].
        upper: Largest f_cL accepted [-].

    Returns:
        The last pass's parameters and the iteration's figures.
    """
    params, its = solve(None)
    total, passes = its, 1
    used = obs.used
    tau = load_torque(obs, params.phi)
    change = np.inf
    for _ in range(iterations):
        params, its = solve(LoadTerm(tau, upper))
        total += its
        passes += 1
        new = load_torque(obs, params.phi)
        change = float(np.linalg.norm((new - tau)[used])
                       / max(float(np.linalg.norm(new[used])), 1e-12))
        tau = new
        if change <= tolerance:
            break
    return LoadFrictionFit(params=params, passes=passes, iterations=total, change=change,
                           converged=change <= tolerance)
