"""Figures of a guiding session: peak speeds and accelerations, rest drift, faults, cycle time,
and against the simulator's truth the force error in motion and the phantom force after a
release (issue 24: both are what the operator feels of the estimate's error)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.safety import State
from leadthrough.errors import ControlError
from leadthrough.session.loop import LoopResult
from leadthrough.session_format import SessionLog

__all__ = ["CycleTime", "SessionSummary", "faults_without_hand", "force_error_in_motion",
           "force_errors_in_motion", "hands_off_intervals", "phantom_forces",
           "release_motion_times", "release_overruns", "rest_drift", "summarize"]

#: TCP speed from which the force error counts as "in motion" [m/s] (issue 24).
MOTION_SPEED = 0.02
#: Time after a release over which an estimated force is a phantom [s] (issue 24).
PHANTOM_WINDOW_S = 0.5

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CycleTime:
    """Compute time per controller cycle (estimator + controller + IK + limits + interpolation).

    Attributes:
        median: Median [µs].
        p99: 99th percentile [µs].
    """

    median: float
    p99: float


@dataclass(frozen=True)
class SessionSummary:
    """What a session did.

    Attributes:
        duration_s: Length [s].
        max_linear_speed: Peak commanded TCP speed [m/s].
        max_angular_speed: Peak commanded TCP angular speed [rad/s].
        max_linear_acc: Peak commanded TCP acceleration [m/s²] (controller cycles).
        max_angular_acc: Peak commanded TCP angular acceleration [rad/s²].
        rest_drift_m: Commanded TCP displacement that started while no force was applied (the
            robot was at rest and nobody pushed) [m]; None without the simulator's truth.
        release_overrun_m: The largest commanded TCP travel after a hand let go, beyond a
            stop from the speed at the release at the acceleration limit
            (:func:`release_overruns`) [m]; None without the simulator's truth.
        faults: Faults that occurred, in order (names).
        final_state: Safety state at the end (name).
        cycle_time_us: Compute time per controller cycle.
        force_rms_in_motion_n: RMS of the estimated minus the applied force while the
            commanded TCP speed is at least :data:`MOTION_SPEED` (:func:`force_error_in_motion`)
            [N]; None without the truth or without such motion.
        phantom_force_n: The largest estimated force within :data:`PHANTOM_WINDOW_S` after a
            hand let go (:func:`phantom_forces`) [N]; None without the truth or a release.
    """

    duration_s: float
    max_linear_speed: float
    max_angular_speed: float
    max_linear_acc: float
    max_angular_acc: float
    rest_drift_m: float | None
    release_overrun_m: float | None
    faults: list[str]
    final_state: str
    cycle_time_us: CycleTime
    force_rms_in_motion_n: float | None = None
    phantom_force_n: float | None = None

    def to_json(self) -> dict[str, object]:
        """JSON-ready dict."""
        return asdict(self)


def rest_drift(log: SessionLog) -> float | None:
    """Commanded TCP displacement that began with the robot at rest and no force applied.

    Within each interval where the true applied wrench is exactly zero, from the first sample at
    which the commanded twist is exactly zero (the robot has come to rest; braking after a
    release is intended motion, not drift), the largest distance of the commanded TCP from
    where it rested.

    Returns:
        Drift [m], or None if the session has no applied-wrench truth.
    """
    intervals = _hands_off(log)
    if intervals is None:
        return None
    at_rest = ~np.any(log.twist_cmd_base != 0.0, axis=1)
    drift = 0.0
    for start, stop in intervals:
        rested = np.flatnonzero(at_rest[start:stop])
        if rested.size == 0:
            continue
        k0 = start + rested[0]
        d = np.linalg.norm(log.tcp_cmd_base[k0:stop] - log.tcp_cmd_base[k0], axis=1)
        drift = max(drift, float(d.max()))
    return drift


def hands_off_intervals(applied: Array) -> list[tuple[int, int]]:
    """The intervals [start, stop) of samples where ``applied`` (a wrench or force per sample,
    shape (samples, k)) is exactly zero, in time order."""
    free = ~np.any(applied != 0.0, axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], free.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _hands_off(log: SessionLog) -> list[tuple[int, int]] | None:
    """:func:`hands_off_intervals` of the log's applied wrench (the simulator's truth); None
    without the truth."""
    if log.wrench_applied_base is None:
        return None
    return hands_off_intervals(log.wrench_applied_base)


def force_errors_in_motion(log: SessionLog, min_speed: float = MOTION_SPEED) -> Array | None:
    """|estimated − applied force| [N] at each sample whose commanded TCP speed is at least
    ``min_speed`` [m/s], the estimate in base axes (``wrench_base``) against the simulator's
    applied wrench; shape (samples that fast,), or None without the truth."""
    if log.wrench_applied_base is None:
        return None
    moving = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1) >= min_speed
    return np.asarray(np.linalg.norm(
        log.wrench_base[moving, :3] - log.wrench_applied_base[moving, :3], axis=1))


def force_error_in_motion(log: SessionLog, min_speed: float = MOTION_SPEED) -> float | None:
    """RMS of :func:`force_errors_in_motion`.

    Returns:
        RMS [N], or None without the truth or without a sample that fast.
    """
    err = force_errors_in_motion(log, min_speed)
    if err is None or not err.size:
        return None
    return float(np.sqrt(np.mean(err ** 2)))


def phantom_forces(log: SessionLog, window_s: float = PHANTOM_WINDOW_S) -> Array | None:
    """The largest estimated force |f̂| within ``window_s`` after each release (the start of
    each interval with no applied wrench that follows a push) [N].

    Returns:
        Per release, shape (releases,); None without the truth.
    """
    intervals = _hands_off(log)
    if intervals is None:
        return None
    peaks = []
    for start, stop in intervals:
        if start == 0:
            continue
        end = int(np.searchsorted(log.time, log.time[start] + window_s))
        f = np.linalg.norm(log.wrench_base[start:min(stop, end), :3], axis=1)
        peaks.append(float(f.max()) if f.size else 0.0)
    return np.asarray(peaks)


def _releases(log: SessionLog) -> tuple[list[tuple[int, int]], Array] | None:
    """The hands-off intervals that follow a push (:func:`_hands_off`, not one from the
    session's start) and the commanded linear speed per sample [m/s]; None without the
    truth."""
    intervals = _hands_off(log)
    if intervals is None:
        return None
    return ([(a, b) for a, b in intervals if a > 0],
            np.linalg.norm(log.twist_cmd_base[:, :3], axis=1))


def release_overruns(log: SessionLog, deceleration: float) -> Array | None:
    """Travel after each release beyond a stop at ``deceleration``, one value per release.

    A release is the last sample of an applied wrench before an interval without one (the
    simulator's truth). From there to the next push (or the end), the commanded TCP path
    length minus v²/(2·a), v the commanded speed at the release: what the robot travelled
    with no hand on it beyond the shortest stop the limits allow. The estimate's filter lag
    and the stopping friction make some of it; a phantom force that keeps the robot going
    makes the rest.

    Args:
        log: The session.
        deceleration: a [m/s²], > 0 (the linear acceleration limit).

    Returns:
        Overrun per release [m], >= 0, shape (releases,); None without the truth.
    """
    releases = _releases(log)
    if releases is None:
        return None
    intervals, speed = releases
    step = np.diff(log.tcp_cmd_base, axis=0)
    travel = np.concatenate([[0.0], np.cumsum(np.linalg.norm(step, axis=1))])
    # a release: the last pushed sample r before a hands-off interval, which ends at stop - 1
    ends = [(start - 1, stop - 1) for start, stop in intervals]
    return np.array([max(0.0, travel[end] - travel[r] - speed[r] ** 2 / (2.0 * deceleration))
                     for r, end in ends])


def release_motion_times(log: SessionLog, deceleration: float) -> Array | None:
    """How long the robot kept moving after each release, beyond the shortest stop.

    For each release (as in :func:`release_overruns`), the time from the release to the last
    sample of the hands-off interval with a nonzero commanded twist, minus v/a, the length of
    a stop at ``deceleration`` from the commanded speed v at the release: a robot that brakes
    at the limit at once scores 0; one that restarts 1.5 s after the release scores about
    1.5 s, however briefly it moves then.

    Args:
        log: The session.
        deceleration: a [m/s²], > 0 (the linear acceleration limit).

    Returns:
        Time per release [s], >= 0, shape (releases,); None without the truth.
    """
    releases = _releases(log)
    if releases is None:
        return None
    intervals, speed = releases
    moving = np.any(log.twist_cmd_base != 0.0, axis=1)
    times = []
    for start, stop in intervals:
        moved = np.flatnonzero(moving[start:stop])
        last = log.time[start + moved[-1]] if moved.size else log.time[start - 1]
        times.append(max(0.0, float(last - log.time[start - 1])
                         - speed[start - 1] / deceleration))
    return np.array(times)


def faults_without_hand(log: SessionLog, window_s: float) -> list[str] | None:
    """The faults that no hand caused: those latched when no hand had touched the tool for
    ``window_s`` (the simulator's truth; e.g. the length of a stop from the speed limit at the
    acceleration limit, so that a push toward a joint limit that the stop cannot avoid counts
    as the hand's).

    Args:
        log: The session.
        window_s: Time without any applied wrench before the fault [s], >= 0.

    Returns:
        The faults' names in order; None without the truth.
    """
    if log.wrench_applied_base is None:
        return None
    touched = np.any(log.wrench_applied_base != 0.0, axis=1)
    last_touch = np.maximum.accumulate(np.where(touched, log.time, -np.inf))
    names = []
    for e in log.events:
        if e.kind == "transition" and ":" in e.cause:
            k = min(int(np.searchsorted(log.time, e.t, side="right")) - 1, log.time.size - 1)
            if e.t - last_touch[max(k, 0)] > window_s:
                names.append(e.cause.split(":", 1)[1])
    return names


def summarize(result: LoopResult, controller_dt: float, deceleration: float) -> SessionSummary:
    """Figures of a finished session.

    Args:
        result: The session.
        controller_dt: Controller cycle [s] (accelerations are taken per cycle).
        deceleration: Linear acceleration limit [m/s²] for :func:`release_overruns`.

    Raises:
        ControlError: The session was recorded to a file, not in memory (load it with
            :func:`~leadthrough.session_format.load_session` and summarise the log).
    """
    log = result.log
    if log is None:
        raise ControlError("the session was recorded to a file, not kept in memory",
                           field="result.log", expected="a session recorded in memory")
    twist = log.twist_cmd_base
    dt = float(np.median(np.diff(log.time))) if log.time.size > 1 else controller_dt
    every = max(1, round(controller_dt / dt))
    cycles = twist[::every]
    acc = np.diff(cycles, axis=0) / controller_dt if len(cycles) > 1 else np.zeros((1, 6))
    faults = [e.cause.split(":", 1)[1] for e in log.events
              if e.kind == "transition" and ":" in e.cause]
    us = result.cycle_us if result.cycle_us.size else np.zeros(1)
    overruns = release_overruns(log, deceleration)
    phantoms = phantom_forces(log)
    return SessionSummary(
        duration_s=float(log.time[-1] - log.time[0]) if log.time.size else 0.0,
        max_linear_speed=float(np.linalg.norm(twist[:, :3], axis=1).max()),
        max_angular_speed=float(np.linalg.norm(twist[:, 3:], axis=1).max()),
        max_linear_acc=float(np.linalg.norm(acc[:, :3], axis=1).max()),
        max_angular_acc=float(np.linalg.norm(acc[:, 3:], axis=1).max()),
        rest_drift_m=rest_drift(log),
        release_overrun_m=(None if overruns is None
                           else float(overruns.max()) if overruns.size else 0.0),
        faults=faults,
        final_state=State(int(log.state[-1])).name,
        cycle_time_us=CycleTime(median=float(np.median(us)),
                                p99=float(np.percentile(us, 99))),
        force_rms_in_motion_n=force_error_in_motion(log),
        phantom_force_n=(None if phantoms is None or not phantoms.size
                         else float(phantoms.max())),
    )
