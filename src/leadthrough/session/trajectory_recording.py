"""Running a joint trajectory on a robot through its driver and logging it: ``leadthrough
record --driver`` (an excitation, a friction sweep or a presliding test, issue 25).

The robot is a position-streaming controller behind the :class:`~leadthrough.drivers.protocol.
Driver` protocol (FANUC J519, UR RTDE, KUKA RSI, or the emulated ones). One target per
controller cycle, in three phases:

1. **approach**: from where the robot stands to the trajectory's first sample, a minimum-jerk
   joint move whose peak speed and acceleration stay within ``approach_fraction`` of every
   joint's limits (or, with ``approach_fraction = 0``, a clear error if the robot is not
   already there: the user moves it);
2. **settle**: the start held for ``settle_s`` (the servo's following error decays);
3. **trajectory**: the samples, interpolated linearly in time at the controller's clock
   (``sequence × cycle`` since the trajectory began, so that a lost packet does not stretch
   the motion), with their velocities as feed-forward; every fresh sample is logged: the
   controller's time, the encoder positions, the motor currents (or the joint torques, where
   the controller reports torque), and the target that was in force.

Anything that is not a normal sample stops the run: a controller state flag (E-stop,
protective stop, not ready), a non-finite sample, a stretch of stale feedback, of commands the
controller did not take in time (``COMMAND_REJECTED``: a late answer) or of controller cycles
that went by without a command (a sequence jump: this side stalled) longer than
``max_stale_s``, a following error beyond ``max_following_error`` (against the target in force
at the controller: a streaming driver's limited one, which after held cycles catches up with
the trajectory at the controller's speed limit; the recording's ``max_following_error`` is
against the trajectory), or a
:class:`~leadthrough.errors.DriverError`. The robot then gets a **commanded stop**: the
target's velocity brought to zero at each joint's acceleration limit (while the link lasts;
a broken link leaves the stop to the controller's own watchdog), and the run raises
:class:`TrajectoryAbortedError` naming the cause: no recording of a partial run is returned (nothing
half-written).

The excitation's identification needs the samples' rate only through their times: the
recording is at the controller's cycle (2, 4 or 8 ms), not the simulator's 1 ms.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.drivers.protocol import ControllerState, Driver, DriverFeedback, JointCommand
from leadthrough.drivers.streaming import StreamingDriver
from leadthrough.errors import ControlError, DriverError, check_fields
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.robot.description import Robot

__all__ = ["TrajectoryAbortedError", "TrajectoryRecording", "TrajectoryRunConfig",
           "approach_move", "record_trajectory"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TrajectoryRunConfig:
    """How a trajectory is run on a robot.

    Attributes:
        approach_fraction: Share of each joint's velocity and acceleration limits the approach
            move may use (0: no approach; the robot must stand at the start), in [0, 0.5].
        start_tolerance: Largest joint distance [rad] from the start that needs no approach.
        settle_s: Hold at the start before the trajectory [s].
        max_stale_s: Longest stretch without a fresh sample [s] before the run stops.
        max_following_error: Largest |target − measured| [rad] on any joint before the run
            stops (a collision, a wrong robot file, a controller not following).
        first_sample_s: Longest wait for the controller's first sample [s].
    """

    approach_fraction: float = 0.1
    start_tolerance: float = 1e-3
    settle_s: float = 0.5
    max_stale_s: float = 0.05
    max_following_error: float = 0.1
    first_sample_s: float = 2.0

    def __post_init__(self) -> None:
        check_fields("record", self, [
            ("approach_fraction", 0.0 <= self.approach_fraction <= 0.5, "in [0, 0.5]"),
            ("start_tolerance", 0.0 < self.start_tolerance <= 0.1, "in (0, 0.1] rad"),
            ("settle_s", 0.0 <= self.settle_s <= 60.0, "in [0, 60] s"),
            ("max_stale_s", 0.0 < self.max_stale_s <= 1.0, "in (0, 1] s"),
            ("max_following_error", 0.0 < self.max_following_error <= 1.0, "in (0, 1] rad"),
            ("first_sample_s", 0.0 < self.first_sample_s <= 60.0, "in (0, 60] s"),
        ], ControlError)


class TrajectoryAbortedError(DriverError):
    """The run stopped before the trajectory's end (the robot got a commanded stop, or the link
    was gone); ``field`` names the cause, ``value`` the controller time [s] into the run."""


@dataclass(frozen=True)
class TrajectoryRecording:
    """A finished run.

    Attributes:
        recording: The trajectory phase's samples (time from its first sample) [s, rad, A or
            N·m].
        approach_s: Duration of the approach move [s] (0: none was needed).
        cycles: Controller cycles of the trajectory phase.
        stale: Cycles of the trajectory phase without a fresh sample (lost or late packets).
        max_following_error: Largest |target − measured| over the trajectory phase [rad].
    """

    recording: Recording
    approach_s: float
    cycles: int
    stale: int
    max_following_error: float


Target = Callable[[float], tuple[Array, Array]]


def approach_move(q0: Array, q1: Array, robot: Robot, fraction: float) -> tuple[float, Target]:
    """A minimum-jerk joint move from ``q0`` to ``q1`` [rad], shapes (n,), that keeps every
    joint within ``fraction`` of its velocity and acceleration limits.

    Minimum jerk (s = 10u³ − 15u⁴ + 6u⁵) peaks at 1.875·Δ/T in velocity and 5.774·Δ/T² in
    acceleration, so T = max over joints of max(1.875·|Δ|/v, sqrt(5.774·|Δ|/a)).

    Returns:
        (duration [s], target(t) -> (q [rad], qd [rad/s]) for 0 <= t; held at q1 after T).
    """
    delta = np.asarray(q1, dtype=float) - np.asarray(q0, dtype=float)
    v = fraction * robot.velocity_limit
    a = fraction * robot.acceleration_limit
    span = float(np.max(np.maximum(1.875 * np.abs(delta) / v,
                                   np.sqrt(5.7735 * np.abs(delta) / a))))
    span = max(span, 1e-3)

    def target(t: float) -> tuple[Array, Array]:
        u = min(max(t / span, 0.0), 1.0)
        s = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
        ds = 30.0 * u * u * (1.0 - u) * (1.0 - u) / span
        return q0 + s * delta, ds * delta

    return span, target


def _trajectory_target(traj: TrajectorySamples) -> Target:
    """The trajectory's samples interpolated linearly at t [s] from its first sample."""
    t0 = float(traj.time[0])
    n = traj.q.shape[1]
    q, qd = np.empty(n), np.empty(n)

    def target(t: float) -> tuple[Array, Array]:
        tt = t0 + t
        for j in range(n):
            q[j] = np.interp(tt, traj.time, traj.q[:, j])
            qd[j] = np.interp(tt, traj.time, traj.qd[:, j])
        return q, qd

    return target


class _Run:
    """The exchange with the driver: one write, step and read per controller cycle."""

    def __init__(self, driver: Driver, robot: Robot, config: TrajectoryRunConfig) -> None:
        self.driver, self.robot, self.config = driver, robot, config
        self.fb: DriverFeedback = driver.make_feedback()
        self.cmd: JointCommand = driver.make_command()
        self.stale_run = 0
        self.phase = "start"
        self.max_stale = max(1, math.ceil(config.max_stale_s / driver.dt))
        # the target in force at the controller: a streaming driver's limited one (behind the
        # stream after cycles the controller held), else the command itself
        self.limiter = driver.limiter if isinstance(driver, StreamingDriver) else None
        self.last_sequence: int | None = None

    def first_sample(self) -> None:
        end = time.monotonic() + self.config.first_sample_s
        while time.monotonic() < end:
            self.driver.step()
            if self.driver.read(self.fb) and np.all(np.isfinite(self.fb.q)):
                self.cmd.q[:] = self.fb.q
                self.cmd.qd[:] = 0.0
                return
        raise TrajectoryAbortedError("no sample from the controller", field="first sample",
                                value=self.config.first_sample_s,
                                expected="a sample within first_sample_s")

    def cycle(self, phase: str) -> bool:
        """Send the command, wait for the next cycle, read; True on a fresh, normal sample."""
        self.phase = phase
        self.driver.write(self.cmd)
        self.driver.step()
        fresh = self.driver.read(self.fb)
        if not fresh:
            self.stale_run += 1
            if self.stale_run > self.max_stale:
                self.stop(f"no fresh sample for {self.stale_run} cycles", phase)
            return False
        state = ControllerState(self.fb.state)
        if state & ~ControllerState.COMMAND_REJECTED:
            self.stop(f"controller state {state!r}", phase)
        if state & ControllerState.COMMAND_REJECTED:  # an answer came late: as a stale cycle
            self.stale_run += 1
            if self.stale_run > self.max_stale:
                self.stop(f"{self.stale_run} commands in a row not taken", phase)
        else:
            self.stale_run = 0
        gap = 0 if self.last_sequence is None else self.fb.sequence - self.last_sequence - 1
        self.last_sequence = int(self.fb.sequence)
        if gap > self.max_stale:  # cycles that went by without a command of ours
            self.stop(f"{gap} controller cycles went by without a command", phase)
        if not (np.all(np.isfinite(self.fb.q)) and np.all(np.isfinite(self.fb.current))):
            self.stop("a non-finite sample", phase)
        target = self.cmd.q if self.limiter is None else self.limiter.position
        err = float(np.max(np.abs(target - self.fb.q)))
        if err > self.config.max_following_error:
            self.stop(f"following error {err:.3g} rad", phase)
        return True

    def stop(self, cause: str, phase: str) -> None:
        """Bring the target's velocity to zero at each joint's acceleration limit, then raise."""
        t_fault = float(self.fb.t)
        try:
            dt = self.driver.dt
            qd = self.cmd.qd.copy()
            dv = self.robot.acceleration_limit * dt
            while np.any(qd != 0.0):
                qd = np.sign(qd) * np.maximum(np.abs(qd) - dv, 0.0)
                self.cmd.q += qd * dt
                self.cmd.qd[:] = qd
                self.driver.write(self.cmd)
                self.driver.step()
                self.driver.read(self.fb)
            self.driver.write(self.cmd)
        except DriverError:
            pass  # the link is gone: the controller's own watchdog stops the robot
        raise TrajectoryAbortedError(f"stopped during the {phase}: {cause}", field=phase,
                                value=t_fault, expected="a normal run to the trajectory's end")


def _follow(run: _Run, target: Target, duration: float, phase: str) -> None:
    """Stream ``target`` for ``duration`` [s] of controller time (unlogged)."""
    seq0 = run.fb.sequence
    while True:
        t = (run.fb.sequence - seq0) * run.driver.dt
        q, qd = target(t)
        run.cmd.q[:] = q
        run.cmd.qd[:] = qd
        if t >= duration:
            return
        run.cycle(phase)


def record_trajectory(driver: Driver, robot: Robot, traj: TrajectorySamples,
                      config: TrajectoryRunConfig | None = None,
                      progress: Callable[[int, int], None] | None = None
                      ) -> TrajectoryRecording:
    """Run ``traj`` on the robot behind an opened ``driver`` and log it (see the module doc).

    Args:
        driver: An opened driver (its controller streaming).
        robot: The robot file; shapes (n,) as the driver's.
        traj: The trajectory (its limits already checked against the robot).
        config: Run settings.
        progress: Called with (cycles done, cycles in all) during the trajectory phase.

    Returns:
        The recording of the trajectory phase and the run's figures.

    Raises:
        TrajectoryAbortedError: The run stopped early (after a commanded stop).
        DriverError: The link broke (the controller's own watchdog stops the robot).
        ControlError: The robot is away from the start and the approach is off.
    """
    config = config if config is not None else TrajectoryRunConfig()
    if traj.q.shape[1] != driver.n or driver.n != robot.n:
        raise ControlError("joint count does not match", field="trajectory.q",
                           value=traj.q.shape[1], expected=f"{robot.n} (robot), {driver.n} "
                                                           "(driver)")
    run = _Run(driver, robot, config)
    try:
        return _run(run, traj, progress)
    except KeyboardInterrupt:
        run.stop("interrupted by the user", run.phase)
        raise  # not reached: stop raises


def _run(run: _Run, traj: TrajectorySamples,
         progress: Callable[[int, int], None] | None) -> TrajectoryRecording:
    """Approach, settle and the logged trajectory."""
    robot, config = run.robot, run.config
    run.first_sample()
    start = np.asarray(traj.q[0], dtype=float)
    away = float(np.max(np.abs(run.fb.q - start)))
    span = 0.0
    if away > config.start_tolerance:
        if config.approach_fraction == 0.0:
            raise ControlError("the robot is not at the trajectory's start", field="q",
                               value=round(away, 4),
                               expected=f"within {config.start_tolerance} rad of the start "
                                        "(or an approach move)")
        span, move = approach_move(run.fb.q.copy(), start, robot, config.approach_fraction)
        _follow(run, move, span, "approach")
    _follow(run, lambda t: (start, np.zeros(robot.n)), config.settle_s, "settle")
    return _record(run, traj, span, progress)


def _record(run: _Run, traj: TrajectorySamples, approach_s: float,
            progress: Callable[[int, int], None] | None) -> TrajectoryRecording:
    """The trajectory phase, logged."""
    dt, n = run.driver.dt, run.robot.n
    duration = float(traj.time[-1] - traj.time[0])
    total = math.floor(duration / dt + 1e-9) + 1
    torque = run.fb.torque is not None
    t_log, q_log = np.empty(total), np.empty((total, n))
    y_log, c_log = np.empty((total, n)), np.empty((total, n))
    target = _trajectory_target(traj)
    seq0, k, stale, worst = run.fb.sequence, 0, 0, 0.0
    cycles = 0
    while cycles < total:
        q, qd = target(cycles * dt)
        run.cmd.q[:] = q
        run.cmd.qd[:] = qd
        if not run.cycle("trajectory"):
            stale += 1
        elif k < total:
            t_log[k], q_log[k], c_log[k] = run.fb.t, run.fb.q, q
            y_log[k] = run.fb.torque if torque else run.fb.current
            worst = max(worst, float(np.max(np.abs(q - run.fb.q))))
            k += 1
        cycles = run.fb.sequence - seq0
        if progress is not None and cycles % 250 == 0:
            progress(min(cycles, total), total)
    _follow(run, lambda t: (run.cmd.q.copy(), np.zeros(n)), 0.2, "end")
    if k < 2:
        raise TrajectoryAbortedError("fewer than 2 samples", field="trajectory", value=k,
                                expected="a trajectory longer than two controller cycles")
    t = t_log[:k] - t_log[0]
    rec = Recording(time=t, q=q_log[:k], q_cmd=c_log[:k], robot=run.robot.name,
                    current=None if torque else y_log[:k], torque=y_log[:k] if torque else None)
    return TrajectoryRecording(rec, approach_s, cycles, stale, worst)
