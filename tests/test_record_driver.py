"""``record --driver``: a trajectory run on each real-controller driver against its emulated
controller (loopback sockets), logged like the simulator's recordings; every stop (E-stop, a
closed link, NaN, Ctrl-C) is a commanded stop and no recording; the emulator confirms that no
command broke its limits."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.cli.record_robot import check_rsi_reach
from leadthrough.data.io import load_recording
from leadthrough.drivers.controllers import DEFAULT_PORTS, connect
from leadthrough.drivers.protocol import JointCommand
from leadthrough.drivers.streaming import StreamingDriver
from leadthrough.errors import ControlError, DriverError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.trajectory_file import save_trajectory
from leadthrough.identification.command_lag import measure_command_lag
from leadthrough.robot import Robot, load_robot
from leadthrough.session.trajectory_recording import (
    TrajectoryAbortedError,
    TrajectoryRecording,
    TrajectoryRunConfig,
    approach_move,
    record_trajectory,
)
from leadthrough.sim.emulators import EmulatorOptions, FaultPlan, RunningEmulator, Window, start
from wire_helpers import (
    DIRECTION,
    POSE,
    free_loopback_address,
    spawn_emulator,
    stop_process,
    wait_for_line,
)

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
ROBOT = {"fanuc-j519": "er20", "ur-rtde": "ur5", "kuka-rsi": "er20"}


@pytest.fixture(scope="module")
def robots() -> dict[str, Robot]:
    return {name: load_robot(name) for name in ("er20", "ur5")}


def _trajectory(duration: float = 1.5, offset: float = 0.05) -> TrajectorySamples:
    """A smooth out-and-back motion of every joint, starting ``offset`` rad from POSE."""
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    w = 2.0 * np.pi / duration
    s = 0.15 * (1.0 - np.cos(w * t))[:, None] * DIRECTION
    sd = 0.15 * w * np.sin(w * t)[:, None] * DIRECTION
    sdd = 0.15 * w * w * np.cos(w * t)[:, None] * DIRECTION
    return TrajectorySamples(time=t, q=np.asarray(POSE) + offset * DIRECTION + s, qd=sd, qdd=sdd)


@contextmanager
def _robot(kind: str, robot: Robot, **faults: object
           ) -> Iterator[tuple[StreamingDriver, RunningEmulator]]:  # type: ignore[type-arg]
    """A driver from :func:`connect`, opened on an in-process emulator starting at POSE."""
    opts = EmulatorOptions(q0=POSE, watchdog=0.2,
                           faults=FaultPlan(**faults))  # type: ignore[arg-type]
    if kind == "kuka-rsi":
        driver = connect(kind, robot, "127.0.0.1", 0)
        emu = start(kind, robot, seed=2, port=driver.listen()[1],  # type: ignore[attr-defined]
                    options=opts)
    else:
        emu = start(kind, robot, seed=2, port=0, options=opts)
        driver = connect(kind, robot, "127.0.0.1", emu.port)
        if kind == "ur-rtde":
            driver.script_port = emu.emulator.script_port  # type: ignore[attr-defined]
    try:
        with driver:
            yield driver, emu
    finally:
        emu.stop()


@pytest.mark.parametrize("kind", KINDS)
def test_a_trajectory_is_recorded_at_the_controllers_cycle(kind: str,
                                                           robots: dict[str, Robot]) -> None:
    robot = robots[ROBOT[kind]]
    traj = _trajectory()
    with _robot(kind, robot) as (driver, emu):
        done = record_trajectory(driver, robot, traj)
        report = emu.emulator.report()
    rec = done.recording
    assert report.violations == () and report.refused == 0
    # the approach moved the robot 0.05 rad at 10 % of the limits; the recording is the
    # trajectory only, one sample per controller cycle that answered: on the controller's
    # clock, each a whole number of cycles after the one before, at most max_stale cycles
    # lost in a row (the run stops past that), all of the trajectory's cycles run. How many a
    # loaded machine loses depends on its speed: benchmarks/record_samples.py prints it.
    assert done.approach_s > 0.0
    assert rec.time[0] == 0.0 and abs(rec.duration - 1.5) <= 2 * driver.dt
    cycles = math.floor(1.5 / driver.dt + 1e-9) + 1
    assert done.cycles >= cycles and 2 <= rec.samples <= cycles
    apart = np.diff(rec.time) / driver.dt
    assert np.allclose(apart, np.round(apart), rtol=0.0, atol=1e-6), apart
    max_stale = max(1, math.ceil(TrajectoryRunConfig().max_stale_s / driver.dt))
    assert np.all((np.round(apart) >= 1) & (np.round(apart) <= max_stale + 1)), apart
    # the logged target is the trajectory on the controller's clock: the one sent before the
    # sample (one cycle earlier, two after a lost packet), never stretched by lost packets
    assert rec.q_cmd is not None
    expect = np.column_stack([np.interp(rec.time, traj.time, traj.q[:, j])
                              for j in range(robot.n)])
    np.testing.assert_allclose(rec.q_cmd, expect, atol=2.0 * np.max(np.abs(traj.qd)) * driver.dt)
    # the robot followed it (within a few cycles' lag at the peak speed)
    lag = float(np.max(np.abs(rec.q - rec.q_cmd)))
    assert lag <= 4 * driver.dt * np.max(np.abs(traj.qd)) + 1e-3
    assert done.max_following_error == pytest.approx(lag)
    # the emulated controller takes a command in its next cycle: a lag of one cycle, which
    # identify measures and the estimator's friction waits for
    measured = measure_command_lag(rec)
    assert measured is not None and abs(measured.lag_s - driver.dt) <= 0.25 * driver.dt
    signal = rec.torque if kind == "kuka-rsi" else rec.current
    assert signal is not None and np.all(np.isfinite(signal)) and np.ptp(signal, axis=0).min() > 0


def test_a_robot_away_from_the_start_without_an_approach_is_refused(
        robots: dict[str, Robot]) -> None:
    robot = robots["er20"]
    with _robot("fanuc-j519", robot) as (driver, emu):
        with pytest.raises(ControlError) as e:
            record_trajectory(driver, robot, _trajectory(),
                              TrajectoryRunConfig(approach_fraction=0.0))
        report = emu.emulator.report()
    assert e.value.field == "q" and e.value.value == pytest.approx(0.05, abs=2e-3)
    assert report.violations == ()


def _fast_swing(robot: Robot, duration: float = 2.0, share: float = 0.79) -> TrajectorySamples:
    """Joint 1 out and back from POSE at up to ``share`` of its speed limit (0.79: two
    cycles' motion in one is beyond the limit, a servoj jump)."""
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    w = 2.0 * np.pi / duration
    amp = share * robot.velocity_limit[0] / w
    q = np.tile(np.asarray(POSE), (t.size, 1))
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    q[:, 0] += amp * (1.0 - np.cos(w * t))
    qd[:, 0], qdd[:, 0] = amp * w * np.sin(w * t), amp * w * w * np.cos(w * t)
    return TrajectorySamples(time=t, q=q, qd=qd, qdd=qdd)


def _late_every(driver: StreamingDriver, n: int, delay: float) -> None:  # type: ignore[type-arg]
    """Make every ``n``-th answer of ``driver`` leave ``delay`` [s] late (a slow client)."""
    write, count = driver.write, [0]

    def late_write(cmd: JointCommand) -> None:
        count[0] += 1
        if count[0] % n == 0:
            time.sleep(delay)
        write(cmd)

    driver.write = late_write  # type: ignore[method-assign]


@pytest.mark.parametrize("echo", [True, False])
def test_late_answers_on_rtde_are_held_cycles_never_a_servoj_jump(
        echo: bool, robots: dict[str, Robot]) -> None:
    robot = robots["ur5"]
    traj = _fast_swing(robot)
    with _robot("ur-rtde", robot) as (driver, emu):
        if not echo:  # the driver blind to the program's echo: what it did before
            driver._answer_late = lambda sample: False  # type: ignore[method-assign]
        _late_every(driver, 40, 2.5 * driver.dt)
        try:
            done: TrajectoryRecording | None = record_trajectory(driver, robot, traj)
        except TrajectoryAbortedError:
            done = None
        report = emu.emulator.report()
    assert report.violations == ()
    if echo:  # each late answer was seen, the next target judged from what servoj took
        assert done is not None and report.refused == 0, report.stop_reason
        assert driver.late_answers >= 10
    else:  # the target after a late answer was two cycles' motion in one: protective stop
        assert done is None and report.refused == 1 and report.stop_kind == "protective"
        assert "velocity" in report.stop_reason


@pytest.mark.parametrize("stall", [0.04, 0.08])
def test_a_client_stall_is_caught_up_at_the_limits_or_stops_past_max_stale(
        stall: float, robots: dict[str, Robot]) -> None:
    robot = robots["ur5"]
    traj = _fast_swing(robot, share=0.93)
    with _robot("ur-rtde", robot) as (driver, emu):
        write, count = driver.write, [0]

        def stalling_write(cmd: JointCommand) -> None:
            count[0] += 1
            if count[0] == 500:  # 0.5 s into the trajectory, at 0.93 of the speed limit
                # this side stalls while `stall` s of the controller's clock go by: its cycles,
                # whatever a loaded machine does to the emulator's thread meanwhile (a stalled
                # emulator's clock stops, and a wall-clock sleep then spans fewer cycles)
                until, deadline = emu.emulator.t + stall, time.monotonic() + 10.0
                while emu.emulator.t < until:
                    if time.monotonic() > deadline:
                        pytest.fail(f"the emulator's clock stood still at {emu.emulator.t} s")
                    time.sleep(0.5e-3)
            write(cmd)

        driver.write = stalling_write  # type: ignore[method-assign]
        try:
            done: TrajectoryRecording | None = record_trajectory(driver, robot, traj)
            error = ""
        except TrajectoryAbortedError as e:
            done, error = None, str(e)
        report = emu.emulator.report()
    assert report.refused == 0 and report.violations == ()
    if stall < 0.05:  # 20 cycles held (max_stale_s 0.05): the robot fell behind the trajectory
        # (up to 0.12 rad at 2.9 rad/s, 0.1 stops a run) and caught up at the limiter's speed;
        # it followed what it was sent, so the run goes on
        assert done is not None, error
        assert done.max_following_error > 0.05
    else:  # 40 cycles without a command: a stop naming it, not a following error
        assert done is None and "went by without a command" in error


def test_rsi_refuses_a_trajectory_beyond_its_correction_range_before_moving(
        robots: dict[str, Robot], tmp_path: Path) -> None:
    robot = robots["er20"]
    far = _trajectory()
    far.q[:, 0] += 1.6  # A1 up to 92 deg (and more) from where RSI started: beyond 0.95 x 90
    with _robot("kuka-rsi", robot) as (driver, emu):
        lo, hi = driver.reach()  # type: ignore[attr-defined]
        with pytest.raises(ControlError) as e:
            check_rsi_reach(driver, far, tmp_path / "far.csv")  # type: ignore[arg-type]
        check_rsi_reach(driver, _trajectory(), tmp_path / "near.csv")  # type: ignore[arg-type]
        time.sleep(0.2)
        report = emu.emulator.report()
        q_now = emu.emulator.arm.sample().q
    np.testing.assert_allclose(np.degrees(hi - lo), 2 * 0.95 * 90.0)
    np.testing.assert_allclose(np.degrees((lo + hi) / 2), np.degrees(POSE), atol=1e-3)
    assert e.value.field == "q1" and "correction range" in str(e.value)
    assert e.value.value == pytest.approx(np.degrees(far.q[:, 0].min()), abs=0.01)
    # nothing moved: every target the robot got was where RSI started
    assert report.refused == 0 and report.violations == ()
    np.testing.assert_allclose(q_now, POSE, atol=1e-3)


def test_record_rsi_beyond_the_correction_range_exits_2_and_emulate_checks_q0(
        tmp_path: Path) -> None:
    far = _trajectory(1.0)
    far.q[:, 0] += 1.6
    traj = tmp_path / "far.csv"
    save_trajectory(traj, far, robot="er20")
    port = DEFAULT_PORTS["kuka-rsi"]
    host = free_loopback_address(port)
    out = tmp_path / "rec.parquet"
    rec = subprocess.Popen([sys.executable, "-m", "leadthrough", "record", "--driver",
                            "kuka-rsi", "--host", host, "--robot", "er20", "--trajectory",
                            str(traj), "-o", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # RSI's robot sends first and ends the element after 100 unanswered documents (0.4 s):
    # the PC listens first (its first line; the bind follows within milliseconds)
    wait_for_line(rec, "recording on kuka-rsi", 120)
    emu = spawn_emulator("kuka-rsi", "er20", host, port, "--q0", *map(str, POSE))
    try:
        _, stderr = rec.communicate(timeout=120)
    finally:
        stop_process(emu)
    assert rec.returncode == 2 and "correction range" in stderr and "q1" in stderr, stderr
    assert "Traceback" not in stderr and not out.exists()
    emulate = [sys.executable, "-m", "leadthrough", "emulate", "kuka-rsi", "--robot", "er20",
               "--duration", "1", "--q0"]
    short = subprocess.run([*emulate, "0", "0"], capture_output=True, text=True, check=False)
    assert short.returncode == 2 and "'--q0'" in short.stderr and "6 finite" in short.stderr
    wide = subprocess.run([*emulate, "0", "0", "9", "0", "0", "0"], capture_output=True,
                          text=True, check=False)
    assert wide.returncode == 2 and "joint 3" in wide.stderr and "9.0" in wide.stderr
    assert "-1.274 .. 2.845 rad" in wide.stderr and "Traceback" not in wide.stderr


@pytest.mark.parametrize("kind", ["fanuc-j519", "ur-rtde"])
def test_an_estop_mid_run_is_a_commanded_stop_and_no_recording(
        kind: str, robots: dict[str, Robot]) -> None:
    robot = robots[ROBOT[kind]]
    with _robot(kind, robot, estop_at=1.5) as (driver, emu):
        with pytest.raises(TrajectoryAbortedError) as e:
            record_trajectory(driver, robot, _trajectory(3.0))
        report = emu.emulator.report()
    assert e.value.field in ("approach", "settle", "trajectory")
    assert "controller state" in str(e.value)
    assert report.stop_kind == "estop" and report.violations == ()


@pytest.mark.parametrize("kind", KINDS)
def test_nan_or_a_closed_link_mid_run_stops_it(kind: str, robots: dict[str, Robot]) -> None:
    robot = robots[ROBOT[kind]]
    with _robot(kind, robot, nan_q=(Window(1.2, 1.25),)) as (driver, emu):
        with pytest.raises(TrajectoryAbortedError) as e:
            record_trajectory(driver, robot, _trajectory(2.0))
        report = emu.emulator.report()
    assert "non-finite" in str(e.value) and report.violations == ()
    with _robot(kind, robot, close_at=1.2) as (driver, emu):
        with pytest.raises(DriverError) as err:  # TCP: link lost; UDP: silence
            record_trajectory(driver, robot, _trajectory(2.0))
        report = emu.emulator.report()
    # TCP (RTDE): the link is lost; UDP (J519, RSI): silence, or the kernel's ICMP "port
    # unreachable" on the next read once a datagram of ours met the closed port (timing)
    expected = ("link lost",) if kind == "ur-rtde" else ("no fresh sample", "port is closed")
    assert any(e in str(err.value) for e in expected), err.value
    assert report.violations == ()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6),
       st.floats(0.01, 0.5))
def test_the_approach_keeps_within_its_share_of_the_limits(delta: list[float],
                                                           fraction: float) -> None:
    robot = load_robot("er20")
    q0 = np.zeros(6)
    span, move = approach_move(q0, np.asarray(delta), robot, fraction)
    t = np.linspace(0.0, span, 2001)
    q = np.array([move(x)[0] for x in t])
    qd = np.array([move(x)[1] for x in t])
    np.testing.assert_allclose(q[-1], delta, atol=1e-12)
    np.testing.assert_allclose(move(span + 1.0)[0], delta, atol=1e-12)
    assert np.all(np.abs(qd) <= fraction * robot.velocity_limit * (1 + 1e-9) + 1e-12)
    qdd = np.gradient(qd, t, axis=0)
    assert np.all(np.abs(qdd) <= fraction * robot.acceleration_limit * 1.01 + 1e-9)
    np.testing.assert_allclose(np.gradient(q, t, axis=0), qd, atol=1e-3 * (1 + np.abs(qd).max()))


@pytest.mark.parametrize("kind", KINDS)
def test_leadthrough_record_driver_against_emulate_in_its_own_process(
        kind: str, tmp_path: Path) -> None:
    traj = tmp_path / "traj.csv"
    save_trajectory(traj, _trajectory(1.0), robot=ROBOT[kind])
    port = DEFAULT_PORTS[kind]
    host = free_loopback_address(port)
    out = tmp_path / "rec.parquet"
    cmd = [sys.executable, "-m", "leadthrough", "record", "--driver", kind, "--host", host,
           "--robot", ROBOT[kind], "--trajectory", str(traj), "-o", str(out), "--json"]
    if kind == "kuka-rsi":  # the PC listens: start it first, then the robot that sends to it
        rec = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for_line(rec, f"recording on {kind}", 120)   # listening: then the robot
        emu = spawn_emulator(kind, ROBOT[kind], host, port, "--q0", *map(str, POSE))
    else:
        emu = spawn_emulator(kind, ROBOT[kind], host, port, "--q0", *map(str, POSE))
        rec = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = rec.communicate(timeout=120)
    finally:
        report = stop_process(emu)
    assert rec.returncode == 0, stderr
    info = json.loads(stdout)
    assert info["driver"] == kind and info["signal"] == ("torque" if kind == "kuka-rsi"
                                                         else "current")
    loaded = load_recording(out)
    assert loaded.samples == info["samples"] and loaded.robot == ROBOT[kind]
    assert "violations: ()" in report and "refused: 0" in report


def test_simulator_settings_with_a_driver_and_a_dead_controller_are_clear_errors(
        tmp_path: Path) -> None:
    traj = tmp_path / "traj.csv"
    save_trajectory(traj, _trajectory(1.0), robot="er20")
    base = [sys.executable, "-m", "leadthrough", "record", "--robot", "er20", "--trajectory",
            str(traj), "-o", str(tmp_path / "r.parquet")]
    seeded = subprocess.run([*base, "--driver", "fanuc-j519", "--host", "127.0.0.1",
                             "--seed", "3"], capture_output=True, text=True, check=False)
    assert seeded.returncode == 2 and "--seed" in seeded.stderr
    dead = subprocess.run([*base, "--driver", "fanuc-j519", "--host", "127.0.0.1", "--port", "9"],
                          capture_output=True, text=True, check=False)
    assert dead.returncode == 1 and "127.0.0.1:9" in dead.stderr   # the link: exit 1
    assert "Traceback" not in dead.stderr and not (tmp_path / "r.parquet").exists()
    no_host = subprocess.run([*base, "--driver", "ur-rtde"], capture_output=True, text=True,
                             check=False)
    assert no_host.returncode == 2 and "--host" in no_host.stderr


@pytest.mark.exclusive
def test_ctrl_c_mid_run_is_a_commanded_stop_and_no_recording(tmp_path: Path) -> None:
    traj = tmp_path / "traj.csv"
    save_trajectory(traj, _trajectory(20.0), robot="er20")
    host = free_loopback_address(DEFAULT_PORTS["fanuc-j519"])
    emu = spawn_emulator("fanuc-j519", "er20", host, DEFAULT_PORTS["fanuc-j519"],
                         "--q0", *map(str, POSE))
    out = tmp_path / "rec.parquet"
    try:
        rec = subprocess.Popen([sys.executable, "-m", "leadthrough", "record", "--driver",
                                "fanuc-j519", "--host", host, "--robot", "er20", "--trajectory",
                                str(traj), "-o", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert rec.stderr is not None  # its first line: connecting (the imports are done)
        assert rec.stderr.readline().startswith("recording on fanuc-j519")
        time.sleep(4.0)  # the approach (~1 s) and the settle (0.5 s): mid-trajectory
        rec.send_signal(signal.SIGINT)
        _, stderr = rec.communicate(timeout=30)
    finally:
        report = stop_process(emu)
    assert rec.returncode == 130 and "interrupted by the user" in stderr, stderr
    assert "Traceback" not in stderr and not out.exists()
    # the stop went out as commands within the limits, then the stream's own end
    assert "violations: ()" in report and "refused: 0" in report
    assert "stop_reason: stop packet" in report
