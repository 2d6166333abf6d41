"""One interface for every calibration method.

    result = identify(recording, robot, "proposed")
    report = evaluate(result.params, robot, held_out_recording)

Methods: ``ols-cv`` (ref. [7]), ``ols-cbrt`` (ref. [22]), ``proposed`` (the paper's) and
``consistent`` (ours: variable projection + physically consistent convex inner problem).
All return an :class:`IdentificationResult` with named parameters and units, the per-joint
residual statistics, J, the runtime and the iteration count.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.preprocess import PreprocessConfig, ProcessedData, preprocess
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import (
    MAX_LOAD_FRICTION,
    DriveModelParameters,
    FrictionModel,
    model_torque,
)
from leadthrough.dynamics.regressor import LINK_PARAMETER_NAMES, LINK_PARAMETER_UNITS
from leadthrough.errors import DataError, check_fields
from leadthrough.identification.consistency import min_pseudo_inertia_eigenvalues
from leadthrough.identification.consistent import ConsistentConfig, identify_consistent
from leadthrough.identification.friction_sweep import SweepFit, fit_sweep_friction, sweep_points
from leadthrough.identification.load_friction import LoadTerm, identify_load_friction
from leadthrough.identification.metrics import ResidualStats, residual_stats
from leadthrough.identification.observations import Observations, build_observations
from leadthrough.identification.ols import identify_ols_cbrt, identify_ols_cv
from leadthrough.identification.proposed import ProposedConfig, identify_proposed
from leadthrough.robot.description import Robot

__all__ = [
    "METHODS",
    "IdentificationResult",
    "IdentifyConfig",
    "NamedParameter",
    "SweepCalibration",
    "evaluate",
    "identify",
    "identify_with_sweep",
    "named_parameters",
]

METHODS: tuple[str, ...] = ("ols-cv", "ols-cbrt", "proposed", "consistent")


class NamedParameter(NamedTuple):
    """One identified parameter."""

    name: str
    value: float
    unit: str


@dataclass(frozen=True)
class IdentifyConfig:
    """Settings shared by all methods.

    Attributes:
        preprocess: Filtering, differentiation and standstill removal.
        k_omega: K_ω of J (eq. 26).
        proposed: Settings of the paper's method.
        consistent: Settings of the consistent method.
        load_friction: Also identify the load-dependent Coulomb friction f_cL (Coulomb level
            f_c0 + f_cL·|τ_load|, :mod:`leadthrough.identification.load_friction`), by
            iteration: ``ols-cv``, ``ols-cbrt`` and ``consistent`` without a sweep. ``proposed``
            keeps f_cL = 0 (its global search has no column to add), and so does ``consistent``
            with a friction sweep (the sweep's measured curve already holds the load friction at
            the sweep's poses, and its points carry no load torque to separate it).
        load_friction_iterations: Most re-identifications with the load term (>= 1).
        load_friction_tolerance: The iteration stops once τ_load changes by at most this
            fraction (RMS) from one pass to the next [-]. A joint whose load torque is small
            (a wrist) has a weakly excited f_cL, which a loose tolerance leaves inexact.
        max_load_friction: Upper bound of the identified f_cL [-]. 0.5 is a gear whose
            load-dependent losses alone bring its efficiency down to 2/3, below any robot
            reducer's rating (harmonic drives are rated about 70–85 %, cycloidal ones higher);
            a joint whose load torque hardly varies can otherwise drive f_cL far past that.
    """

    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    k_omega: float = 1.0
    proposed: ProposedConfig = field(default_factory=ProposedConfig)
    consistent: ConsistentConfig = field(default_factory=ConsistentConfig)
    load_friction: bool = True
    load_friction_iterations: int = 6
    load_friction_tolerance: float = 1e-4
    max_load_friction: float = 0.5

    def __post_init__(self) -> None:
        check_fields("identify", self, [
            ("load_friction_iterations", self.load_friction_iterations >= 1, ">= 1"),
            ("load_friction_tolerance", 0 < self.load_friction_tolerance < 1, "in (0, 1)"),
            ("max_load_friction", 0 < self.max_load_friction < MAX_LOAD_FRICTION,
             f"in (0, {MAX_LOAD_FRICTION:g})"),
        ])


@dataclass(frozen=True)
class IdentificationResult:
    """What every method returns.

    Attributes:
        robot: Robot name.
        method: Method name.
        params: Identified model parameters.
        stats: Residual statistics on the identification data (τ_ω = τ_measured − τ_model).
        runtime_s: Wall time of the identification, pre-processing included [s].
        iterations: Iterations of the solver (1 for least squares).
        samples: Samples used after pre-processing.
        load_passes: Identifications run to fit the load-dependent friction (the first,
            without the load term, included; :mod:`leadthrough.identification.load_friction`);
            0 when it was not fitted.
    """

    robot: str
    method: str
    params: DriveModelParameters
    stats: ResidualStats
    runtime_s: float
    iterations: int
    samples: int
    load_passes: int = 0

    @property
    def J(self) -> float:  # noqa: N802 (the paper's symbol)
        """The objective J on the identification data [N·m]."""
        return self.stats.J

    @property
    def min_pseudo_inertia_eig(self) -> NDArray[np.float64]:
        """Smallest pseudo-inertia eigenvalue per link [kg·m²] (< 0: not physical)."""
        return min_pseudo_inertia_eigenvalues(self.params.phi)

    def named_parameters(self, robot: Robot) -> list[NamedParameter]:
        """All parameters with names and units."""
        return named_parameters(robot, self.params)


def named_parameters(robot: Robot, params: DriveModelParameters) -> list[NamedParameter]:
    """Named parameters with units of a model (links, rotor inertia, friction)."""
    out: list[NamedParameter] = []
    for k, jn in enumerate(robot.joint_names):
        for i, (p, u) in enumerate(zip(LINK_PARAMETER_NAMES, LINK_PARAMETER_UNITS, strict=True)):
            out.append(NamedParameter(f"{jn}.{p}", float(params.phi[10 * k + i]), u))
    for k, jn in enumerate(robot.joint_names):
        out.append(NamedParameter(f"{jn}.rotor_inertia", float(params.rotor_inertia[k]),
                                  "kg·m²"))
        if params.offset.size:
            out.append(NamedParameter(f"{jn}.offset", float(params.offset[k]), "N·m"))
        if params.load_friction.size:
            out.append(NamedParameter(f"{jn}.load_friction", float(params.load_friction[k]),
                                      "N·m/N·m"))
        if params.friction_model is FrictionModel.STRIBECK and params.stribeck is not None:
            st = params.stribeck
            for name, arr, unit in (("f1", st.f1, "N·m"), ("f2", st.f2, "N·m"),
                                    ("qd_sm", st.qd_sm, "rad/s (motor)"), ("f3", st.f3, "N·m"),
                                    ("qd_sg", st.qd_sg, "rad/s"), ("f4", st.f4, "N·m·s/rad")):
                out.append(NamedParameter(f"{jn}.{name}", float(arr[k]), unit))
        else:
            out.append(NamedParameter(f"{jn}.coulomb", float(params.coulomb[k]), "N·m"))
            out.append(NamedParameter(f"{jn}.viscous", float(params.viscous[k]), "N·m·s/rad"))
            if params.friction_model is FrictionModel.CBRT:
                out.append(NamedParameter(f"{jn}.cbrt", float(params.cbrt[k]),
                                          "N·m·(s/rad)^(1/3)"))
    return out


def _processed(data: Recording | ProcessedData, robot: Robot, cfg: IdentifyConfig
               ) -> ProcessedData:
    if isinstance(data, ProcessedData):
        return data
    data.check_robot(robot)
    return preprocess(data, robot, cfg.preprocess)


def identify(
    data: Recording | ProcessedData,
    robot: Robot,
    method: str,
    config: IdentifyConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    sweep: SweepFit | None = None,
) -> IdentificationResult:
    """Calibrate the robot's model from a recording with no external force.

    Args:
        data: The excitation recording (or already processed data).
        robot: The robot.
        method: ``ols-cv``, ``ols-cbrt``, ``proposed`` or ``consistent``.
        config: Settings.
        progress: Progress callback for long methods, ``progress(done, total)``.
        sweep: Steady friction measured by a constant-velocity sweep
            (:func:`leadthrough.identification.friction_sweep.fit_sweep_friction`): the
            identified friction curve then passes within ``consistent.sweep_tolerance`` of it;
            ``consistent`` only.

    Returns:
        The identified model and its figures on the identification data.

    Raises:
        DataError: Unknown method, data that do not fit the robot, or data that do not excite
            every parameter.
    """
    if method not in METHODS:
        raise DataError("unknown method", field="method", value=method,
                        expected=f"one of {', '.join(METHODS)}")
    if sweep is not None and method != "consistent":
        raise DataError("a measured friction curve is used by the consistent method only",
                        field="method", value=method, expected="'consistent' with a sweep")
    cfg = config if config is not None else IdentifyConfig()
    t0 = time.perf_counter()
    processed = _processed(data, robot, cfg)
    obs = build_observations(robot, processed)

    def solve(load: LoadTerm | None) -> tuple[DriveModelParameters, int]:
        return _run_method(method, obs, cfg, progress, sweep, load)

    if cfg.load_friction and method != "proposed" and sweep is None:
        fit = identify_load_friction(obs, solve, cfg.load_friction_iterations,
                                     cfg.load_friction_tolerance, cfg.max_load_friction)
        params, iterations, passes = fit.params, fit.iterations, fit.passes
    else:
        (params, iterations), passes = solve(None), 0
    stats = _stats(robot, params, processed, cfg.k_omega)
    return IdentificationResult(
        robot=robot.name, method=method, params=params, stats=stats,
        runtime_s=time.perf_counter() - t0, iterations=iterations, samples=processed.samples,
        load_passes=passes)


def _run_method(method: str, obs: Observations, cfg: IdentifyConfig,
                progress: Callable[[int, int], None] | None, sweep: SweepFit | None,
                load: LoadTerm | None) -> tuple[DriveModelParameters, int]:
    """One identification by ``method`` (with the load column when ``load`` is given): the
    parameters and the method's iterations."""
    if method == "ols-cv":
        return identify_ols_cv(obs, load), 1
    if method == "ols-cbrt":
        return identify_ols_cbrt(obs, load), 1
    if method == "consistent":
        ccfg = cfg.consistent
        if ccfg.k_omega != cfg.k_omega:
            ccfg = replace(ccfg, k_omega=cfg.k_omega)
        cons = identify_consistent(obs, ccfg, sweep, load)
        return cons.params, cons.iterations
    pcfg = cfg.proposed
    if pcfg.k_omega != cfg.k_omega:
        pcfg = replace(pcfg, k_omega=cfg.k_omega)
    outcome = identify_proposed(obs, pcfg, progress)
    return outcome.params, outcome.generations + outcome.polish_iterations


def _stats(robot: Robot, params: DriveModelParameters, data: ProcessedData, k_omega: float
           ) -> ResidualStats:
    tau_model = model_torque(robot, params, data.q, data.qd, data.qdd)
    return residual_stats(data.torque, tau_model, data.moving, robot.max_torque, k_omega)


def evaluate(
    params: DriveModelParameters,
    robot: Robot,
    data: Recording | ProcessedData,
    config: IdentifyConfig | None = None,
) -> ResidualStats:
    """Residual statistics of identified parameters on (held-out) data.

    Args:
        params: Identified parameters.
        robot: The robot.
        data: Recording or processed data.
        config: Pre-processing and K_ω.

    Returns:
        Per-joint mean/std, std as % of max torque, relative error and J.
    """
    cfg = config if config is not None else IdentifyConfig()
    processed = _processed(data, robot, cfg)
    if not np.all(processed.moving.any(axis=0)):
        raise DataError("some joint never moves in the validation data", source=processed.source,
                        field="q", expected="a recording that moves every joint")
    return _stats(robot, params, processed, cfg.k_omega)


@dataclass(frozen=True)
class SweepCalibration:
    """The consistent method with a friction sweep.

    Attributes:
        result: Identified on the excitation recording, friction held near the sweep's curve.
        sweep: The sweep's measured points and eq. 15 fit.
    """

    result: IdentificationResult
    sweep: SweepFit


def identify_with_sweep(
    excitation: Recording | ProcessedData,
    sweep: Recording,
    robot: Robot,
    config: IdentifyConfig | None = None,
) -> SweepCalibration:
    """Calibrate for hand guiding: friction from a constant-velocity sweep, the rest from an
    excitation recording (``consistent`` method).

    Args:
        excitation: The excitation recording (or processed data).
        sweep: A friction-sweep recording
            (:func:`leadthrough.excitation.friction_sweep.design_friction_sweep`).
        robot: The robot.
        config: Settings.

    Returns:
        The identification and the sweep's fit.

    Raises:
        DataError: As :func:`identify`, or a sweep with too few usable passes.
    """
    sweep.check_robot(robot)
    fit = fit_sweep_friction(sweep_points(sweep, robot), robot, source=sweep.source)
    return SweepCalibration(result=identify(excitation, robot, "consistent", config, sweep=fit),
                            sweep=fit)
