"""Shared fixtures."""
# ruff: noqa: E402  (the environment is set before numpy is imported)

from __future__ import annotations

import fcntl
import os
import time
from collections.abc import Generator
from pathlib import Path
from typing import Any

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
from xdist.scheduler import LoadScopeScheduling

from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import identify_with_sweep
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import (
    CalibrationSet,
    SimRecording,
    record_calibration_set,
    record_friction_sweep,
    record_presliding_test,
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


@pytest.fixture(scope="session")
def presliding_test_run(er20: Robot) -> SimRecording:
    """The presliding test on the simulated er20 (seed 1, run 3, from the guiding start pose,
    the default realistic plant), recorded once for the modules that only read it (the
    presliding fit's bounds, the calibration recipe)."""
    return record_presliding_test(er20, seed=1, run=3, q_start=guide_start_pose(er20))


#: Test modules that run a loop or a controller against the wall clock (emulators on loopback
#: sockets, the pendant's processes, Chromium).
REALTIME_MODULES = frozenset({
    "test_emulator_answer_timing", "test_emulator_operator", "test_guide_driver",
    "test_loop_faults", "test_loop_requests", "test_pendant_backend", "test_pendant_browser",
    "test_pendant_driver", "test_pendant_parts", "test_pendant_process", "test_record_driver",
    "test_wire_drivers", "test_wire_fanuc_j519", "test_wire_faults", "test_wire_kuka_rsi",
    "test_wire_ur_rtde", "test_wire_ur_rtde_reference",
})

#: The niceness of the worker that runs the other tests under pytest-xdist.
COMPUTE_NICE = 10


def _realtime(module: str | Path) -> bool:
    """Whether a test module (its path) is one of :data:`REALTIME_MODULES`."""
    return Path(module).stem in REALTIME_MODULES


#: Compute test modules that read the same expensive session fixture: one work unit each, so
#: that the fixture is built once (on the worker that runs them).
SHARED_FIXTURE_UNITS = {
    "test_identification": "ideal_calibration_set", "test_friction_sweep": "ideal_calibration_set",
    "test_presliding": "presliding_test_run", "test_calibration": "presliding_test_run",
}

#: The slowest compute work units, slowest first (measured, 2 workers): they start before the
#: others, so that the last unit of the run is a short one and neither worker idles at the end.
SLOW_COMPUTE_UNITS = (
    "test_cli", "test_cli_calibration", "presliding_test_run", "ideal_calibration_set",
    "test_load_friction", "test_control_properties", "test_consistent",
    "test_examples", "test_exit_codes", "test_session",
)


class TwoGroupScheduling(LoadScopeScheduling):
    """pytest-xdist scheduling (``-n 2 --dist loadgroup`` in pyproject.toml): the wall-clock
    tests (:data:`REALTIME_MODULES`) are one work unit, run first on one worker, so that a loop
    on loopback never runs beside another (their controllers' watchdogs are real); the other
    tests are one unit per module (or per :data:`SHARED_FIXTURE_UNITS` group), dealt to
    whichever worker is free, the slowest (:data:`SLOW_COMPUTE_UNITS`) first. A worker runs
    its units in the order it was dealt them, so the worker of the wall-clock tests takes
    compute units only after them, and the other worker's compute tests are the only thing
    beside them (niced, see :func:`pytest_runtest_protocol`).

    The unit of a test is read from its node id's module here, in the controller's scheduler.
    ``xdist_group`` marks added at collection do not work on pytest 9.2: xdist 3.8 writes the
    group into the item's old ``_nodeid`` field, which pytest 9.2's structured node ids no
    longer read, so every test went its own way (pytest-dev/pytest-xdist#1386, fix pending in
    #1388)."""

    _ordered = False

    def _split_scope(self, nodeid: str) -> str:
        module = Path(nodeid.split("::", 1)[0]).stem
        if module in REALTIME_MODULES:
            return "realtime"
        return SHARED_FIXTURE_UNITS.get(module, module)

    def _assign_work_unit(self, node: Any) -> None:
        """Deal the units in :func:`_unit_rank` order (xdist's: by number of tests)."""
        if not self._ordered:
            units = sorted(self.workqueue.items(), key=lambda unit: _unit_rank(unit[0]))
            self.workqueue.clear()
            self.workqueue.update(units)
            self._ordered = True
        super()._assign_work_unit(node)


def _unit_rank(unit: str) -> int:
    """The wall-clock unit first, then the slow compute units slowest first, then the rest
    (a stable sort keeps xdist's order among those)."""
    if unit == "realtime":
        return 0
    if unit in SLOW_COMPUTE_UNITS:
        return 1 + SLOW_COMPUTE_UNITS.index(unit)
    return 1 + len(SLOW_COMPUTE_UNITS)


@pytest.hookimpl(optionalhook=True)   # no such hook with -p no:xdist
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadgroup`` schedules :class:`TwoGroupScheduling`; other modes are xdist's."""
    if config.getvalue("dist") != "loadgroup":
        return None
    return TwoGroupScheduling(config, log)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "exclusive: a wall-clock test that must not run beside the compute tests "
        "under pytest-xdist (they pause while it runs; see tests/conftest.py)")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None
                            ) -> Generator[None, object, object]:
    """Under pytest-xdist, a worker lowers its priority at its first compute test (niceness
    :data:`COMPUTE_NICE`, inherited by the processes it starts; the worker of the wall-clock
    tests only reaches one after all of those): where the
    wall-clock tests wait on a 1-8 ms controller cycle, the CPU-bound tests beside them only
    use the time they leave.

    And a test marked ``exclusive`` runs on an otherwise idle machine: it
    raises a flag and takes a lock that every compute test holds shared while it runs, so the
    compute worker finishes its current test and waits until the exclusive one is done.
    Those are the wall-clock tests that a loaded 2-core machine made fail in trial runs (J519
    refuses a late command; the browser renders on the CPU). The lock spans the whole test,
    its fixtures' set-up and teardown included (a compute test's session fixture, such as a
    calibration, is built in its set-up). Serial runs: nothing happens."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return (yield)
    # the workers' base temporary folders share this parent (pytest keeps the last three);
    # the tmp_path_factory fixture is this same object
    factory: pytest.TempPathFactory = item.config._tmp_path_factory  # type: ignore[attr-defined]
    shared = factory.getbasetemp().parent
    flag, lock = shared / "exclusive.flag", shared / "exclusive.lock"
    if item.get_closest_marker("exclusive") is not None:
        flag.touch()
        with lock.open("a") as f:
            fcntl.flock(f, fcntl.LOCK_EX)
            try:
                return (yield)
            finally:
                flag.unlink(missing_ok=True)
                fcntl.flock(f, fcntl.LOCK_UN)
    if _realtime(item.path):
        return (yield)
    if os.nice(0) < COMPUTE_NICE:
        os.nice(COMPUTE_NICE - os.nice(0))
    with lock.open("a") as f:
        _lock_after_exclusive(flag, f.fileno())
        try:
            return (yield)
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


#: How long a raised flag may go without its exclusive lock before it counts as left behind
#: by a worker that died inside an exclusive test (the kernel freed its lock) [s].
STALE_FLAG_S = 2.0


def _lock_after_exclusive(flag: Path, fd: int) -> None:
    """Take the shared lock once no exclusive test runs: wait while the flag is up (an
    exclusive test waits for the lock or holds it); a flag whose lock can be had shared
    ``STALE_FLAG_S`` after it was seen is a dead worker's, and is ignored."""
    seen = time.monotonic()
    while flag.exists():
        if time.monotonic() - seen > STALE_FLAG_S:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                pass
        time.sleep(0.1)
    fcntl.flock(fd, fcntl.LOCK_SH)
