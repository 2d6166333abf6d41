"""The pendant's link to the real-time loop: the loop in its own thread, a published snapshot,
and a request channel. Everything the pendant needs from the loop goes through this module.

The loop runs :class:`~leadthrough.session.loop.ServoPeriods` (the periods of
:func:`~leadthrough.session.loop.run_session`: driver, estimator, controller, interpolator) in
a thread of its own, open-ended, paced by the wall clock on a simulator and by the driver's
``step`` on a robot. The user interface never calls into it:

* **state out**: after every controller cycle the loop builds one immutable
  :class:`LoopSnapshot` and swaps a reference to it (atomic in CPython). A reader gets the
  latest complete snapshot, never half of one, and never waits;
* **requests in**: the interface appends :class:`Request` objects to a ``collections.deque``
  (its ``append`` and ``popleft`` are atomic). The loop drains it at the start of each
  controller cycle, before the controller runs, so that a request takes effect at a cycle
  boundary and in the order sent. Refusals and results come back as :class:`Notice` entries
  in the snapshot.

Neither side takes a lock, so a slow, frozen or closed browser cannot hold up a period; the
only coupling left is Python's global interpreter lock, which the interface holds for short
stretches (``benchmarks/pendant_isolation.py`` measures the loop's period work with and without
a pendant and a browser).

The loop also keeps the session at the controller rate in a ring of ``record_s`` seconds
(:class:`~leadthrough.pendant.live_recording.LiveRecording`) for the export to teach-in.

This module stands in for the loop's own request channel (issue 26: ``LoopRequests`` /
``LoopSnapshot`` in ``leadthrough.session``); the pendant uses only the names defined here.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import Fault, State
from leadthrough.drivers.protocol import Driver
from leadthrough.errors import ControlError, LeadthroughError
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.pendant.live_recording import LiveRecording
from leadthrough.pendant.transitions import describe
from leadthrough.robot.description import Robot
from leadthrough.session.loop import ServoPeriods
from leadthrough.session.loop_config import LoopParts
from leadthrough.session.record import SessionLog

__all__ = ["Adjust", "ClearFault", "LiveSession", "LoopSnapshot", "MarkPoint", "MarkedPoint",
           "Notice", "PeriodTimes", "Request", "SetEnable"]

Array = NDArray[np.float64]

#: How far a simulated loop may fall behind the wall clock before it stops catching up [s].
MAX_LAG_S = 0.05


@dataclass(frozen=True)
class SetEnable:
    """The enabling input (deadman): held or released."""

    held: bool


@dataclass(frozen=True)
class ClearFault:
    """Clear a latched fault (done once the commanded motion is at rest)."""


@dataclass(frozen=True)
class MarkPoint:
    """The operator marks the measured pose under a name (``P1``, ``P2``, ``W3``)."""

    label: str


@dataclass(frozen=True)
class Adjust:
    """Change the frame, the axes, the virtual mass or friction (None: unchanged); see
    :meth:`GuidingController.adjust <leadthrough.control.guiding.GuidingController.adjust>`."""

    frame: str | None = None
    axes_enabled: tuple[bool, ...] | None = None
    mass: tuple[float, float] | None = None
    friction: tuple[float, float] | None = None


#: What the interface may ask of the loop.
Request = SetEnable | ClearFault | MarkPoint | Adjust


class PeriodTimes(NamedTuple):
    """Timing of consecutive servo periods of a live loop.

    Attributes:
        work_us: The loop's work of each period [µs]: estimator, controller cycle (every
            ``every``-th period) and interpolation, as ``run_session`` measures it.
        done_us: From the period's scheduled start (the paced loop's deadline) to the end of
            its work [µs]: the wake-up, the driver's step and read, and the work; NaN when the
            loop is not paced.
        controller_cycle: Whether the period ran the controller cycle.
    """

    work_us: NDArray[np.float64]
    done_us: NDArray[np.float64]
    controller_cycle: NDArray[np.bool_]


@dataclass(frozen=True)
class MarkedPoint:
    """A point the operator marked.

    Attributes:
        label: Its name.
        t: Loop time of the mark [s].
        q: Measured joint positions then [rad], shape (n,).
    """

    label: str
    t: float
    q: Array


@dataclass(frozen=True)
class Notice:
    """A message from the loop to the operator (a refused or clamped request, a mark).

    Attributes:
        number: Running number (1, 2, ...), to tell new notices from seen ones.
        level: ``"info"`` or ``"warning"``.
        text: The message.
    """

    number: int
    level: str
    text: str


@dataclass(frozen=True)
class LoopSnapshot:
    """The loop's state after one controller cycle (immutable; arrays are copies).

    Attributes:
        time: Loop time [s].
        q: Measured joint positions [rad], shape (n,).
        transform_tool_to_base: Commanded TCP pose, shape (4, 4) [m].
        wrench_base: Estimated operator wrench at the TCP, base axes [N, N·m], shape (6,).
        twist_base: Commanded TCP twist, base axes [m/s, rad/s], shape (6,).
        state: Safety state.
        fault: Latched fault (``Fault.NONE`` unless FAULT).
        cause: The last transition in words (its cause, the fault with value and index).
        estimator: The estimator's status.
        enabled: The enabling input as the loop sees it.
        settings: The controller's settings in force (frame, axes, mass, friction).
        marks: The points marked so far, in time order.
        notices: The latest notices (at most 20), oldest first.
        error: Why the loop stopped, if it did.
    """

    time: float
    q: Array
    transform_tool_to_base: Array
    wrench_base: Array
    twist_base: Array
    state: State
    fault: Fault
    cause: str
    estimator: EstimatorStatus
    enabled: bool
    settings: GuidingConfig
    marks: tuple[MarkedPoint, ...]
    notices: tuple[Notice, ...]
    error: str | None = None

    @property
    def speed(self) -> float:
        """Commanded TCP speed ‖v‖ [m/s]."""
        return float(np.linalg.norm(self.twist_base[:3]))


@dataclass
class _Published:
    """What the loop keeps between snapshots (touched by the loop thread only)."""

    marks: tuple[MarkedPoint, ...] = ()
    notices: deque[Notice] = field(default_factory=lambda: deque(maxlen=20))
    notice_count: int = 0
    event_count: int = -1
    cause: str = ""


class LiveSession:
    """A guiding loop running in its own thread until stopped, with a snapshot and requests.

    Args:
        driver: The robot (simulated or real).
        parts: Estimator, controller and interpolator (``build_loop``).
        robot: The robot's description.
        record_s: Length of the recording kept for the export [s] (older rows dropped).
        applied_wrench: A simulator's truth, recorded for comparison; None for a robot.
        settings: Recorded in the session file.
        paced: Pace to the wall clock; default: when the driver is simulated (a real driver's
            ``step`` waits for the robot).
        timing_window: Servo periods whose timing is kept (:meth:`period_times`).
        rt_priority: Run the loop's thread under ``SCHED_FIFO`` at this priority (1–99; Linux,
            needs the privilege to, e.g. root or ``CAP_SYS_NICE``): the operating system then
            runs it before any ordinary process or thread. None: ordinary scheduling. If the
            system refuses, the loop runs anyway and says so in a notice.
    """

    def __init__(self, driver: Driver, parts: LoopParts, robot: Robot, *,
                 record_s: float = 600.0, applied_wrench: Callable[[], Array] | None = None,
                 settings: dict[str, object] | None = None, paced: bool | None = None,
                 timing_window: int = 1000, rt_priority: int | None = None) -> None:
        self.robot, self.driver, self.parts = robot, driver, parts
        every = round(parts.controller.config.dt / driver.dt)
        if every < 1 or abs(every * driver.dt - parts.controller.config.dt) > 1e-9:
            raise ControlError("controller cycle must be a multiple of the servo period",
                               field="controller.dt", value=parts.controller.config.dt,
                               expected=f"k × {driver.dt} s")
        self.every = every
        self.paced = driver.simulated if paced is None else paced
        self.rt_priority = rt_priority
        self.settings = dict(settings or {})
        self._loop = ServoPeriods(driver, parts.estimator, parts.controller,
                                  parts.interpolator, every, self._deadman, applied_wrench)
        cycles = max(2, round(record_s / parts.controller.config.dt))
        self.recording = LiveRecording(self._loop, cycles, driver.n, applied_wrench is not None)
        self._requests: deque[Request] = deque()
        self._held = False
        self._stop = threading.Event()
        self._started = threading.Event()
        self._kept = _Published()
        self._snapshot: LoopSnapshot | None = None
        self._thread = threading.Thread(target=self._run, name="leadthrough-loop", daemon=True)
        self._error: str | None = None
        self._work_us = np.zeros(max(1, timing_window))
        self._done_us = np.full(max(1, timing_window), np.nan)
        #: Servo periods run so far.
        self.periods_run = 0

    # ------------------------------------------------------------ the interface's side
    def start(self, timeout_s: float = 120.0) -> None:
        """Start the loop thread and wait for its first snapshot (warm-up compiles or loads
        the compiled code).

        Raises:
            ControlError: The loop failed to start (its error), or did not within the time.
        """
        self._thread.start()
        if not self._started.wait(timeout_s):
            raise ControlError("the loop did not start in time", field="timeout_s",
                               value=timeout_s, expected="a first controller cycle")
        if self._error is not None:
            raise ControlError(f"the loop did not start: {self._error}")

    def stop(self, timeout_s: float = 5.0) -> None:
        """Release the enabling input, let the robot come to rest, and end the thread."""
        self.send(SetEnable(False))
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    @property
    def running(self) -> bool:
        """Whether the loop thread is running."""
        return self._thread.is_alive()

    def send(self, request: Request) -> None:
        """Queue a request; the loop applies it at its next controller cycle."""
        self._requests.append(request)

    def period_times(self, last: int | None = None) -> PeriodTimes:
        """Timing of the last ``last`` servo periods (default and at most: the timing window),
        oldest first (copies; the newest period may be missing, being written)."""
        run, size = self.periods_run, self._work_us.size
        count = min(run, size) if last is None else min(run, size, last)
        idx = np.arange(run - count, run)
        k = idx % size
        return PeriodTimes(self._work_us[k], self._done_us[k], idx % self.every == 0)

    def snapshot(self) -> LoopSnapshot | None:
        """The latest snapshot (None before the first controller cycle)."""
        return self._snapshot

    def session_log(self, marks: Sequence[MarkedPoint]) -> SessionLog:
        """The recording so far (the last ``record_s`` seconds) with ``marks`` as its marks.

        Raises:
            TeachError: Nothing recorded yet.
        """
        return self.recording.session_log(self.robot.name, self.parts.controller,
                                          [(m.t, m.label) for m in marks], self.settings)

    # ------------------------------------------------------------ the loop's side
    def _deadman(self, t: float) -> bool:
        return self._held

    def _run(self) -> None:
        try:
            self._schedule()
            self._periods()
        except LeadthroughError as e:
            self._error = str(e)
        except Exception as e:  # the thread must report, not vanish
            self._error = f"{type(e).__name__}: {e}"
        finally:
            self._started.set()
            if self._snapshot is not None:
                self._snapshot = _with_error(self._snapshot, self._error)

    def _schedule(self) -> None:
        """Real-time scheduling of this thread, if asked for (see ``rt_priority``)."""
        if self.rt_priority is None:
            return
        try:  # on Linux, pid 0 is the calling thread
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
        except (AttributeError, OSError, ValueError) as e:
            self._notice("warning", f"no real-time priority for the loop ({e}); it runs "
                                    "with ordinary scheduling")
        else:
            self._notice("info", f"the loop runs under SCHED_FIFO, priority "
                                 f"{self.rt_priority}")

    def _periods(self) -> None:
        """The loop: periods until stopped (and then at rest), requests at cycle starts."""
        loop, dt, every = self._loop, self.driver.dt, self.every
        t_start = loop.start()
        self._publish(t_start)
        self._started.set()
        wall0 = time.perf_counter()
        i = 0
        while not (self._stop.is_set() and self._at_rest()):
            t_loop = t_start + (i + 1) * dt
            deadline = None
            if self.paced:
                deadline = wall0 + (i + 1) * dt
                if time.perf_counter() - deadline > MAX_LAG_S:   # fell behind: no catching up
                    wall0 = time.perf_counter() - (i + 1) * dt
                    deadline = wall0 + (i + 1) * dt
            cycle = i % every == 0
            if cycle and self._requests:
                self._apply_requests(t_loop)
            work = loop.period(i, t_loop, deadline)
            k = i % self._work_us.size
            self._work_us[k] = work
            if deadline is not None:
                self._done_us[k] = (time.perf_counter() - deadline) * 1e6
            self.periods_run = i + 1
            if cycle:
                self.recording.store(t_loop)
                self._publish(t_loop)
            i += 1

    def _at_rest(self) -> bool:
        snap = self._snapshot
        return snap is None or (snap.state in (State.IDLE, State.FAULT)
                                and not snap.twist_base.any())

    def _apply_requests(self, t: float) -> None:
        ctl = self.parts.controller
        while self._requests:
            req = self._requests.popleft()
            if isinstance(req, SetEnable):
                self._held = bool(req.held)
            elif isinstance(req, ClearFault):
                if ctl.state != State.FAULT:
                    self._notice("warning", "no fault to clear")
                elif not ctl.clear_fault(t):
                    self._notice("warning", "fault not cleared: the robot is still stopping")
            elif isinstance(req, MarkPoint):
                point = MarkedPoint(req.label, t, self._loop.fb.q.copy())
                self._kept.marks = (*self._kept.marks, point)
                self._notice("info", f"marked {req.label} at {t:.2f} s")
            else:
                self._adjust(req)

    def _adjust(self, req: Adjust) -> None:
        ctl = self.parts.controller
        try:
            cfg = ctl.adjust(frame=req.frame, axes_enabled=req.axes_enabled, mass=req.mass,
                             friction=req.friction)
        except ControlError as e:
            self._notice("warning", f"not changed: {e}")
            return
        vf = cfg.virtual_friction
        if req.mass is not None and (vf.mass[0], vf.mass[3]) != tuple(req.mass):
            self._notice("warning", f"virtual mass clamped to {vf.mass[0]:g} kg, "
                                    f"{vf.mass[3]:g} kg·m²")
        if req.friction is not None and (vf.friction[0], vf.friction[3]) != tuple(req.friction):
            self._notice("warning", f"friction clamped to {vf.friction[0]:g} N, "
                                    f"{vf.friction[3]:g} N·m")

    def _notice(self, level: str, text: str) -> None:
        kept = self._kept
        kept.notice_count += 1
        kept.notices.append(Notice(kept.notice_count, level, text))

    def _publish(self, t: float) -> None:
        """Build the snapshot of this cycle and swap it in."""
        loop, ctl, kept = self._loop, self.parts.controller, self._kept
        if ctl.event_count != kept.event_count:
            kept.event_count = ctl.event_count
            kept.cause = describe(ctl.last_event)
        c_out, e_out = loop.c_out, loop.e_out
        self._snapshot = LoopSnapshot(
            time=t, q=loop.fb.q.copy(), transform_tool_to_base=c_out.transform_tool_to_base.copy(),
            wrench_base=e_out.wrench.copy(), twist_base=c_out.twist_base.copy(),
            state=c_out.state, fault=c_out.fault, cause=kept.cause, estimator=e_out.status,
            enabled=self._held, settings=ctl.config, marks=kept.marks,
            notices=tuple(kept.notices))


def _with_error(snap: LoopSnapshot, error: str | None) -> LoopSnapshot:
    return replace(snap, error=error if error is not None else "stopped")
