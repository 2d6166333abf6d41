"""Shared fixtures."""
# ruff: noqa: E402  (the environment is set before numpy is imported)

from __future__ import annotations

import os

# One BLAS/LAPACK thread for the tests and the processes they start (set before numpy loads
# OpenBLAS; a value the caller set is kept). The suite's linear algebra is small matrices: on a
# 2-core machine shared with the processes the tests spawn, OpenBLAS's worker threads spin
# against them, and one excitation design took 113 s instead of 2.4 s single-threaded
# (2026-11-28, under load). The tests' assertions are unchanged; only the summation order of
# the BLAS kernels differs (the design's condition number 43.10893 vs 43.10960).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import pytest

from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import identify_with_sweep
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import (
    CalibrationSet,
    record_calibration_set,
    record_friction_sweep,
)


@pytest.fixture(scope="session")
def er20() -> Robot:
    """The built-in ER20-class robot."""
    return load_robot("er20")


@pytest.fixture(scope="session")
def nominal_params(er20: Robot) -> ParamsFile:
    """Nominal (CAD) parameters with the noise level of a calibration: enough to run the loop.

    The loop's contract (zero motion at rest, faults, recording) must hold for any parameters;
    the accuracy of calibrated parameters is covered by the benchmarks.
    """
    n = er20.n
    return ParamsFile(robot="er20", method="nominal", params=nominal_drive_parameters(er20),
                      noise_mean=np.zeros(n), noise_std=np.full(n, 1.0), J=0.0)


#: The calibration sets' excitation design (short: one start, 60 iterations).
CAL_EXCITATION = ExcitationConfig(starts=1, max_iterations=60)


@pytest.fixture(scope="session")
def ideal_calibration_set(er20: Robot) -> CalibrationSet:
    """The simulated er20 (seed 1) on the ideal plant (the paper's model class): the
    calibration set of 2 × 30 s, recorded once for the modules that only read it (Table II's
    ordering, the friction sweep's bounds)."""
    return record_calibration_set(er20, seed=1, duration=30.0, excitation_config=CAL_EXCITATION,
                                  plant="ideal")


@pytest.fixture(scope="session")
def sweep_calibration(er20: Robot) -> tuple[object, object, object]:
    """The simulated er20 (seed 1) calibrated with the friction sweep: the calibration set,
    the sweep, and the consistent identification (shared by the test modules that need a robot
    that follows a hand)."""
    cal = record_calibration_set(er20, seed=1, duration=30.0, excitation_config=CAL_EXCITATION)
    sweep = record_friction_sweep(er20, seed=1, run=2, q_start=guide_start_pose(er20))
    return cal, sweep, identify_with_sweep(cal.identification.measured, sweep.measured, er20)


@pytest.fixture(scope="session")
def calibrated_params(sweep_calibration: tuple[object, object, object]) -> ParamsFile:
    """Parameters calibrated on the simulated er20 (seed 1): a push moves it to the cap."""
    sc = sweep_calibration[2]
    return ParamsFile.from_result(sc.result, sim_seed=1)  # type: ignore[attr-defined]
