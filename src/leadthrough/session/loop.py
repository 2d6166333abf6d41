"""The real-time guiding loop: driver → estimator (each sample) → controller (10 ms) →
interpolator → driver, recording everything, until a stop.

Per servo period (``driver.dt``):

1. **exchange** with the driver: write the interpolated joint command, ``driver.step()`` (a
   simulated driver advances one period; a real one blocks until the next), ``driver.read(fb)``;
2. a new sample goes through the external force estimator (eq. 27–30); the controller's own
   state (``fb.state``) is checked, the mark button read, one request served;
3. every ``controller_every`` periods (10 ms), the **controller cycle**: the guiding controller
   takes the measured state, the estimated wrench and the enabling device's state and produces
   a joint setpoint; the interpolator turns it into 1 ms position + velocity commands;
4. the row is recorded (:mod:`~leadthrough.session.recorder`) and the compute time of steps
   2–3 measured.

**One loop for every way of driving a robot.** :func:`run` owns the periods in time: the
real-time set-up (``LoopOptions.realtime``, one switch), the interpreter's settings, the start,
the pacing and late-period count (:class:`~leadthrough.session.pacing.PeriodClock`), the
watchdog, and every way out, each ending in the driver's commanded stop (:func:`stop_driver`).
:func:`run_session` (the CLI's ``guide``, the library) records each period to memory or a file
and returns a :class:`LoopResult`; the pendant's loop process
(:mod:`leadthrough.pendant.loop_process`) runs the same :func:`run` and publishes each
controller cycle to the page. The state and the work of a period are
:class:`~leadthrough.session.servo_loop.ServoLoop`'s.

**Start.** The first sample: each part's compiled code loaded and a few periods computed on
it, then every part reset there; on a real controller the packets of the start answered as the
controller wants them (:meth:`ServoLoop.start
<leadthrough.session.servo_loop.ServoLoop.start>`).

**Enabling.** The enabling device (a digital input of the driver, ``LoopOptions.enable_input``;
or a ``deadman`` function) starts guiding
only on a fresh press seen while the loop is ready: the estimator reports OK (after its warm-up
and tare: guiding on an estimate that has not settled would start the robot on filter
transients), no fault is latched and no stop is requested
(:class:`~leadthrough.session.operator_inputs.EnablingDevice`). A device held at the start must
be released and pressed again; with no enabling input the loop never guides.

**Ways out.** The loop runs until a stop: ``LoopRequests.stop`` (or the operator's
:class:`~leadthrough.session.requests.Stop`), the operator's channel lost, or the end of
``duration_s``.
A stop releases the controller (a stop at the acceleration limit) and the loop ends once the
commanded motion is at rest. However it ended (a stop, a fault's stop, a lost link, a stop
that timed out, an exception escaping the loop such as a second Ctrl-C), a real controller's
stream then ends its own clean way (the driver's ``close()``: :func:`stop_driver`), logged
with how the session ended, before the recording is finished: the file is complete and
holds that event, also when the driver's stop fails.

Faults stop the same way as a stop and latch until ``reset_fault``:

* the controller's own (non-finite, stale or out-of-range feedback, following error, ...);
  on a real controller, feedback is also stale when no sample came for the safety layer's
  ``stale_cycles`` controller cycles (plus a servo period of jitter) on the wall clock (a
  period without a sample lasts the driver's receive timeout, several periods: counted in
  periods, the rule would wait as many times longer);
* the robot controller's state (``Fault.CONTROLLER_STATE``: E-stop, protective stop, not
  ready, a command refused);
* a driver exception (``Fault.DRIVER_ERROR``) or an exchange longer than the watchdog's timeout
  (``Fault.DRIVER_TIMEOUT``). The link is then suspect: the loop keeps commanding the stop, and
  a second failure means the link is gone: the loop ends at once without further servo
  targets, and :func:`stop_driver` sends the protocol's stop (the driver's ``close()``: RSI's
  ``Stop`` answer, the UR program's stop mode, J519's stop packet), which a broken socket alone
  prevents (then the controller's own watchdog stops the robot).

The loop never raises once running: everything ends in a latched, logged state
(:class:`LoopEnd`, the recording's events).

The loop itself reads the clock, to pace (``paced=True``) and to measure; the algorithms it
drives never do. The estimator sees every sample and the controller every tenth: an estimator
fault (a bad sample between two cycles) reaches the controller as ``Fault.ESTIMATOR``.

Python's cyclic garbage collector is paused while the loop runs (and restored after): a
collection stalls whichever cycle it falls in by tens of µs, and the loop creates no reference
cycles for it to find (its temporaries are freed by reference counting; a test checks this), so
pausing it costs no memory.

The interpreter's thread switch interval is shortened to :data:`GIL_SWITCH_S` while the loop
runs (and restored after). Another thread of the process that runs Python code (the watchdog)
makes the loop's thread, woken with a sample, wait for the interpreter lock until that thread
yields it: one switch interval (Python's default 5 ms made the loop answer a 2 ms controller
two cycles late every 10 s, when a writer thread converted a chunk: measured with an emulated
UR controller, ``benchmarks/long_session.py``), or the whole of a call into C that keeps the
lock. The session file is therefore written by a process of its own
(:mod:`leadthrough.session.session_file`); ``benchmarks/gil_hold.py`` measures the wait.
"""

from __future__ import annotations

import gc
import logging
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingController
from leadthrough.control.interpolation import JointInterpolator
from leadthrough.drivers.protocol import Driver
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import ExternalForceEstimator
from leadthrough.session.controller_events import transition_event
from leadthrough.session.loop_config import LoopOptions
from leadthrough.session.loop_end import EndCause, LoopEnd
from leadthrough.session.pacing import Clock, ComputeTimes, PeriodClock
from leadthrough.session.realtime import setup_realtime
from leadthrough.session.recorder import ChunkSink, SessionRecorder
from leadthrough.session.requests import RequestSource
from leadthrough.session.servo_loop import ServoLoop
from leadthrough.session_format import SessionLog

__all__ = ["GIL_SWITCH_S", "REALTIME_NOTE", "EndCause", "LoopEnd", "LoopResult", "PeriodObserver",
           "check_setup", "run", "run_session", "stop_driver", "transition_event"]

Array = NDArray[np.float64]
log = logging.getLogger("leadthrough.session")

#: The label of the session's events that say how the real-time set-up went.
REALTIME_NOTE = "real-time set-up"
#: The interpreter's thread switch interval while the loop runs [s] (see the module doc): the
#: longest the loop's thread waits for the lock when another thread holds it in Python code.
GIL_SWITCH_S = 2e-4


@dataclass(frozen=True)
class LoopResult:
    """A finished session.

    Attributes:
        log: Everything recorded (None when the recording went to a file).
        end: How the loop ended.
        cycle_us: Compute time of each controller cycle's servo period (estimator +
            controller + IK + limits + interpolation) [µs], shape (cycles,).
        servo_us: Compute time of the other servo periods (estimator + interpolation) [µs].
            Both: the last ten minutes at most (:class:`~leadthrough.session.pacing.ComputeTimes`).
        late_periods: Servo periods that missed their slot (paced, or a real driver:
            :class:`~leadthrough.session.pacing.PeriodClock`); none is caught up.
        skipped_periods: Slots skipped after late periods (paced only).
        periods: Servo periods run.
        cycles: Controller cycles run (``cycle_us`` holds all of them when it is as long).
    """

    log: SessionLog | None
    end: LoopEnd
    cycle_us: Array
    servo_us: Array
    late_periods: int = 0
    skipped_periods: int = 0
    periods: int = 0
    cycles: int = 0


def run_session(
    driver: Driver,
    estimator: ExternalForceEstimator,
    controller: GuidingController,
    interpolator: JointInterpolator,
    duration_s: float | None = None,
    *,
    options: LoopOptions | None = None,
    requests: RequestSource | None = None,
    deadman: Callable[[float], bool] | None = None,
    applied_wrench: Callable[[], Array] | None = None,
    settings: dict[str, object] | None = None,
    sink: ChunkSink | None = None,
    clock: Clock | None = None,
) -> LoopResult:
    """Run a guiding session until a stop (see the module doc).

    Args:
        driver: The robot (simulated or real).
        estimator: External force estimator, configured with ``frame="base"`` and the driver's
            period.
        controller: Guiding controller; its cycle must be a multiple of the driver's period.
        interpolator: Controller cycle → servo period interpolation.
        duration_s: Stop after this long [s]; None: run until ``requests.stop()``.
        options: How the loop meets the driver and the operator (the enabling and mark inputs,
            pacing, the watchdog).
        requests: The operator's requests (a :class:`~leadthrough.session.requests.
            LoopRequests` queue from other threads).
        deadman: The enabling device's level as a function of the loop's time, instead of an
            input (e.g. a scripted operator).
        applied_wrench: A simulator's truth: the wrench applied this period (base frame),
            recorded for comparison; None for a real robot.
        settings: Recorded in the session file.
        sink: Where the recording's chunks go (e.g. a
            :class:`~leadthrough.session.session_file.SessionFileSink`, streaming to disk);
            None: memory, returned in the result.
        clock: What the loop times with (default: the wall clock; a
            :class:`~leadthrough.session.pacing.VirtualClock` in tests).

    Returns:
        The recording, how the loop ended, the compute times.

    Raises:
        ControlError: Mismatched periods or frames, or inconsistent options (checked before
            anything runs), or no feedback on the first read.
    """
    options = options if options is not None else LoopOptions()
    every = check_setup(driver, estimator, controller, duration_s, options, requests, deadman)
    dt = driver.dt
    steps = None if duration_s is None else round(duration_s / dt)
    loop = ServoLoop(driver, estimator, controller, interpolator, every, options, requests,
                     deadman, clock=clock)
    rec = SessionRecorder(driver.n, applied_wrench is not None, sink, events=loop.events)
    times = ComputeTimes()
    fb, cmd, e_out, c_out = loop.fb, loop.cmd, loop.e_out, loop.c_out

    def record(i: int, work_us: float) -> None:
        times.add(work_us)
        rec.store(loop.t, fb.q, fb.current, e_out.tau_ext, e_out.wrench, cmd.q, cmd.qd,
                  c_out.transform_tool_to_base, c_out.twist_base, int(c_out.state),
                  int(c_out.fault), applied_wrench() if applied_wrench is not None else None)

    pacing = PeriodClock(dt, options.paced, real_time=not driver.simulated, clock=loop.clock)
    try:
        run(loop, pacing, steps=steps, observe=record)
    finally:
        session_log = rec.finish(controller.robot.name, loop.session_events(), settings or {})
    assert loop.end is not None
    cycle_us, servo_us = times.split(every)
    return LoopResult(log=session_log, end=loop.end, cycle_us=cycle_us, servo_us=servo_us,
                      late_periods=pacing.late, skipped_periods=pacing.skipped,
                      periods=times.count, cycles=-(-times.count // every))


class PeriodObserver(Protocol):
    """Called after each servo period with its index and its compute time [µs] (after the
    period's work, before its late count: what it costs counts)."""

    def __call__(self, i: int, work_us: float) -> None: ...


def run(loop: ServoLoop, pacing: PeriodClock, *, steps: int | None = None,
        observe: PeriodObserver | None = None,
        started: Callable[[float], None] | None = None) -> None:
    """Run ``loop`` until it ends (the one loop, see the module doc): the real-time set-up,
    the start, the periods, and the way out, which always ends in the driver's commanded stop.

    Args:
        loop: The loop, not started.
        pacing: Paces the periods and counts the late ones (on ``loop.clock``).
        steps: Servo periods before a stop (``EndCause.DURATION``); None: until a stop.
        observe: Called after each period (recording, publishing).
        started: Called with the first sample's time [s] once the loop has started, before
            its first period.

    Raises:
        ControlError: No feedback on the first read (nothing was commanded).
        BaseException: Whatever escaped a period (a second Ctrl-C, a bug), after the
            driver's stop.
    """
    lines = setup_realtime(loop.options.realtime)   # before the start's warm-up and locks
    for line in lines:
        refused = " not " in line
        (log.warning if refused else log.info)("real-time set-up: %s", line)
    interpreter = _InterpreterSettings()   # from the start on: no collection between the
    try:                                   # start's last packet and the first answer
        t_start = loop.start()
    except BaseException:
        interpreter.restore()
        raise
    escaped: BaseException | None = None
    try:
        for line in lines:      # in the session's events and the operator's notices
            loop.note(t_start, REALTIME_NOTE, line, "warning" if " not " in line else "info")
        if started is not None:
            started(t_start)
        _periods(loop, t_start, steps, pacing, observe)
    except BaseException as e:   # a second Ctrl-C, or a bug: stopped and recorded, re-raised
        escaped = e
        raise
    finally:
        _end(loop, escaped, interpreter)
    if pacing.late:
        log.warning("%d servo periods late (%d slots skipped, none caught up)", pacing.late,
                    pacing.skipped)


class _InterpreterSettings:
    """The interpreter while the loop runs, its start included (module doc): the cyclic
    collector paused, the thread switch interval at :data:`GIL_SWITCH_S`; :meth:`restore` puts
    both back."""

    def __init__(self) -> None:
        self.gc_was_enabled = gc.isenabled()
        gc.disable()
        self.switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(GIL_SWITCH_S)

    def restore(self) -> None:
        sys.setswitchinterval(self.switch_interval)
        if self.gc_was_enabled:
            gc.enable()


def _end(loop: ServoLoop, escaped: BaseException | None,
         interpreter: _InterpreterSettings) -> None:
    """After the last period, however the loop left: first the driver's stop, which answers the
    controller's packet the last period read (:func:`stop_driver`), with the interpreter still
    set for the loop; then the interpreter restored and the loop closed, whatever the steps
    before did."""
    try:
        stop_driver(loop, escaped)
    finally:
        interpreter.restore()
        loop.close()


def stop_driver(loop: ServoLoop, escaped: BaseException | None = None) -> None:
    """The session is over (at rest after its stop, or the link lost, or ``escaped`` raised in
    the loop): a real controller's stream ends its own way (``driver.close()``: the protocol's
    clean stop, then the disconnect) before the recording is finished, logged as a ``loop``
    event with how the session ended; a failure of it is logged, never raised (the recording
    is still finished). A simulated driver has nothing to stop.

    Called right after the last period, before the loop's own teardown (its watchdog, its
    events, the pendant's board) and with its real-time settings (the collector paused, the
    short switch interval) still on: the exchange of the last period read the controller's
    next packet, which waits for its answer, and the driver's stop is that answer (an RSI
    robot counts it late after one cycle, 4 ms)."""
    driver = loop.driver
    if driver.simulated:
        return
    end = loop.end
    t = end.t if end is not None else loop.t
    if escaped is not None:
        how = f"after {type(escaped).__name__}"
    elif end is None:
        how = "after the loop left without an end"
    else:
        how = f"after {end.cause}: {end.detail}" if end.detail else f"after {end.cause}"
    close = getattr(driver, "close", None)
    if close is None:
        loop.note(t, "driver not stopped", f"{how}; the driver has no close(): the "
                                           "controller's watchdog ends the stream")
        return
    try:
        close()
    except Exception as e:
        log.error("the driver's stop failed: %s: %s", type(e).__name__, e)
        loop.note(t, "driver stop failed", f"{how}; {type(e).__name__}: {e}")
        return
    method = getattr(driver, "stop_method", "")
    loop.note(t, "driver stopped", f"{how}; {method}" if method else how)


def _periods(loop: ServoLoop, t_start: float, steps: int | None, pacing: PeriodClock,
             observe: PeriodObserver | None) -> None:
    """The periods, until the loop ends."""
    dt, simulated = loop.driver.dt, loop.driver.simulated
    pacing.start()
    i = 0
    while True:
        # the loop's clock advances on stale feedback too; on a real controller it catches up
        # with the controller's clock after cycles that went by unseen (ServoLoop.t)
        t_loop = t_start + (i + 1) * dt if simulated else loop.t + dt
        work_us = loop.period(i, t_loop, pacing)
        if observe is not None:
            observe(i, work_us)
        pacing.done()
        loop.late = pacing.late
        t_loop = loop.t
        i += 1
        if steps is not None and i >= steps:
            loop.begin_end(EndCause.DURATION, t_loop)
        if loop.finished(t_loop):
            return


def check_setup(driver: Driver, estimator: ExternalForceEstimator,
                controller: GuidingController, duration_s: float | None, options: LoopOptions,
                requests: RequestSource | None, deadman: Callable[[float], bool] | None) -> int:
    """The loop's settings checked against each other; returns the servo periods per
    controller cycle.

    Raises:
        ControlError: Naming the setting that does not fit the others.
    """
    dt = driver.dt
    every = round(controller.config.dt / dt)
    if every < 1 or abs(every * dt - controller.config.dt) > 1e-9:
        raise ControlError("controller cycle must be a multiple of the servo period",
                           field="controller.dt", value=controller.config.dt,
                           expected=f"k × {dt} s")
    if abs(estimator.config.dt - dt) > 1e-12 or estimator.config.frame != "base":
        raise ControlError("estimator must run at the servo period in the base frame",
                           field="estimator", value=(estimator.config.dt, estimator.config.frame),
                           expected=f"(dt={dt}, frame='base')")
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ControlError("must be > 0", field="duration_s", value=duration_s,
                           expected="> 0 s, or None (until a stop request)")
    if deadman is not None and options.enable_input is not None:
        raise ControlError("two enabling inputs", field="deadman",
                           value="a function and options.enable_input",
                           expected="one enabling device")
    if not driver.simulated and options.watchdog_s <= 2 * dt:
        raise ControlError("shorter than two servo periods", field="options.watchdog_s",
                           value=options.watchdog_s, expected=f"> {2 * dt} s")
    if duration_s is None and requests is None:
        raise ControlError("no way to stop", field="duration_s", value=None,
                           expected="a duration, or requests (their stop())")
    return every

