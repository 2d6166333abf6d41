"""The paper's calibration (Section III-A.3): full model of eq. 21, objective J of eq. 26,
population-based global optimisation within the bounds of eq. 37.

The decision vector, its bounds and J, evaluated for a whole population at once, are
:class:`~leadthrough.identification.proposed_problem.ProposedProblem`'s (the paper's Steps 2
and 5, eq. 24 and 37 are documented there).

The global search is SciPy's differential evolution (a population-based optimiser like the
paper's particle swarm), with the whole population evaluated at once (vectorised), seeded with
the nominal model. It is followed by a bounded quasi-Newton polish (L-BFGS-B, on J with |mean|
and std smoothed, and its exact gradient), kept only if it lowers J.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.identification.observations import Observations
from leadthrough.identification.proposed_problem import ProposedConfig, ProposedProblem

__all__ = ["ProposedConfig", "ProposedOutcome", "identify_proposed"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ProposedOutcome:
    """Result of the search.

    Attributes:
        params: Identified parameters.
        J: Objective on the search data [N·m].
        generations: Generations of the global search run.
        polish_iterations: L-BFGS-B iterations run.
        evaluations: Objective evaluations.
        runtime_s: Wall time [s].
    """

    params: DriveModelParameters
    J: float
    generations: int
    polish_iterations: int
    evaluations: int
    runtime_s: float


def identify_proposed(
    obs: Observations,
    config: ProposedConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ProposedOutcome:
    """Calibrate with the paper's method.

    Args:
        obs: Regressors of the processed identification data.
        config: Settings.
        progress: Called as ``progress(done, total)`` with generations + polish iterations.

    Returns:
        Parameters, J and search statistics.
    """
    cfg = config if config is not None else ProposedConfig()
    t0 = time.perf_counter()
    prob = ProposedProblem(obs, cfg)
    d = prob.x0.size
    rng = np.random.default_rng(cfg.seed)
    init = rng.random((cfg.population, d))
    init[0] = prob.to_unit(prob.x0[None, :])[0]
    total = cfg.generations + cfg.polish_iterations
    gen = [0]

    def callback(*_: object) -> None:
        gen[0] += 1
        if progress is not None:
            progress(gen[0], total)

    unit_bounds = [(0.0, 1.0)] * d
    de = scipy.optimize.differential_evolution(
        lambda U: prob.objective(prob.from_unit(U.T)), bounds=unit_bounds,
        maxiter=cfg.generations, init=init, vectorized=True, updating="deferred",
        polish=False, tol=0.0, seed=cfg.seed, mutation=(0.5, 1.0), recombination=0.9,
        callback=callback)
    u = np.asarray(de.x)
    polish_it = 0
    if cfg.polish_iterations:
        it = [0]

        def cb(_: Array) -> None:
            it[0] += 1
            if progress is not None:
                progress(gen[0] + it[0], total)

        res = scipy.optimize.minimize(
            prob.unit_value_and_gradient, u, jac=True, method="L-BFGS-B", bounds=unit_bounds,
            callback=cb, options={"maxiter": cfg.polish_iterations, "ftol": 1e-12,
                                  "gtol": 1e-10})
        before = prob.objective(prob.from_unit(u[None, :]))[0]
        if prob.objective(prob.from_unit(res.x[None, :]))[0] <= before:
            u = np.asarray(res.x)
        polish_it = int(res.nit)
    x = prob.from_unit(u[None, :])[0]
    if progress is not None:
        progress(total, total)
    return ProposedOutcome(
        params=prob.params(x), J=float(prob.objective(x[None, :])[0]), generations=int(de.nit),
        polish_iterations=polish_it, evaluations=prob.evaluations,
        runtime_s=time.perf_counter() - t0)
