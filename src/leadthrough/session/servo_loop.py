"""The guiding loop's state between servo periods, and one period (see
:mod:`leadthrough.session.loop` for the loop as a whole).

:class:`ServoLoop` holds every preallocated input and output, the operator's inputs, the state
of the link to the driver (:class:`Link`), the stop in progress and the session's events; its
:meth:`ServoLoop.period` runs one servo period; :meth:`ServoLoop.reset_fault` is the fault reset
of the reset input and of the requests from other threads (:mod:`leadthrough.session.requests`).
The start is :func:`~leadthrough.session.loop_start.start_loop`'s.

**Fault reset**: at rest, with the robot controller reporting OK, the feedback finite and the
robot within the following-error limit of its command (beyond it the reported position cannot
be trusted to restart from: an encoder or a following fault), unless the controller stopped the
robot itself (``Fault.CONTROLLER_STATE``: it stopped short of the commanded stop). Every part
restarts at the measured position (after an E-stop the robot stopped where it was, short of the
commanded stop); the estimator warms up and tares again, and guiding needs a fresh press. A
reset that cannot be made is refused with a note (a ``loop`` event in the recording).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingController
from leadthrough.control.interpolation import InterpolatorStatus, JointInterpolator
from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.protocol import ControllerState, Driver, DriverFeedback, JointCommand
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import EstimatorStatus, ExternalForceEstimator
from leadthrough.session.controller_events import transition_event
from leadthrough.session.loop_config import LoopOptions
from leadthrough.session.loop_end import EndCause, Link, LoopEnd
from leadthrough.session.operator_inputs import EnablingDevice, MarkButton, input_bit
from leadthrough.session.pacing import PeriodClock
from leadthrough.session.requests import LoopRequests, Request, RequestKind
from leadthrough.session.rest_rezero import zero_velocity_update
from leadthrough.session.watchdog import DriverWatchdog
from leadthrough.session_format import Mark, SessionEvent

__all__ = ["ServoLoop"]

Array = NDArray[np.float64]
log = logging.getLogger("leadthrough.session")


class ServoLoop:
    """The loop's parts, preallocated inputs and outputs, and state (see the module doc).

    Args:
        driver: The robot.
        estimator: External force estimator.
        controller: Guiding controller.
        interpolator: Controller cycle → servo period interpolation.
        every: Servo periods per controller cycle.
        options: The loop's options.
        requests: Requests from other threads, or None.
        deadman: The enabling device's level as a function of time, or None.
    """

    def __init__(self, driver: Driver, estimator: ExternalForceEstimator,
                 controller: GuidingController, interpolator: JointInterpolator, every: int,
                 options: LoopOptions, requests: LoopRequests | None,
                 deadman: Callable[[float], bool] | None) -> None:
        self.driver, self.estimator, self.controller = driver, estimator, controller
        self.interpolator, self.every = interpolator, every
        self.e_in, self.e_out = estimator.make_input(), estimator.make_output()
        # the feedback's arrays are the estimator input's and the command's velocity is its
        # qd_cmd (the command sent this period until the interpolator writes the next at its
        # end): the driver fills what the estimator reads, with no copies in the period
        self.e_in.q[:] = self.e_in.current[:] = np.nan
        self.fb = DriverFeedback(t=float("nan"), q=self.e_in.q, current=self.e_in.current,
                                 sequence=-1)
        self.cmd = JointCommand(q=np.zeros(driver.n), qd=self.e_in.qd_cmd)
        self.c_in, self.c_out = controller.make_input(), controller.make_output()
        cfg = controller.config
        self.settle_s, self.cycle_s = cfg.settle_s, cfg.dt
        self.rezero_samples = round(cfg.rezero_s / driver.dt)
        self.interp_status = InterpolatorStatus.FINISHED
        # the operator
        self.enabling = EnablingDevice()
        #: The digital inputs of the last sample that carried them (a sample without them,
        #: e.g. before J519 echoes its I/O request, keeps the last: 0, released, at first).
        self.inputs = 0
        self.enable_level = _enable_source(self, options, deadman)
        self.mark_bit = -1 if options.mark_input is None else options.mark_input
        self.mark_button = MarkButton()
        self.reset_bit = -1 if options.reset_input is None else options.reset_input
        self.reset_button = MarkButton()   # one reset request per (debounced) press
        self.requests = requests
        self.held = self.ready = False
        # the link, and the end
        self.link = Link.OK
        self.controller_tripped = False           # a controller-state fault is latched
        #: The controller has reported itself ready: from then on NOT_READY is a fault (before,
        #: the stream is starting on its side: no guiding, no fault).
        self.controller_ready = False
        self.timeout_s = math.inf if driver.simulated else options.watchdog_s
        self.watch = (None if driver.simulated else
                      DriverWatchdog(options.watchdog_s, options.abort_s,
                                     getattr(driver, "abort", None)))
        self.stop_timeout_s = options.stop_timeout_s
        self.ending: EndCause | None = None
        self.ending_since = math.nan
        self.end: LoopEnd | None = None
        self.late = 0
        #: The loop's time [s]: its periods counted from the first sample, on a real
        #: controller caught up with the controller's clock when cycles went by unseen.
        self.t = math.nan
        self.follow_clock = not driver.simulated
        #: A real controller's feedback is stale when no new sample came for this long [s]:
        #: the safety layer's ``stale_cycles`` controller cycles on the wall clock (a period
        #: without a sample lasts the driver's timeout, several servo periods), plus one servo
        #: period for the packets' jitter (the sample of the last of those cycles arriving a
        #: little late is not a third cycle missed). Checked after each exchange: at the
        #: driver's timeout's granularity.
        self.stale_s = (math.inf if driver.simulated
                        else cfg.safety.stale_cycles * cfg.dt + driver.dt)
        self.fresh_at = math.inf       # time.perf_counter() of the newest sample
        self.fresh_sequence = -1       # and its sequence number
        self.stale = False             # latched (and logged) once until a fault reset
        # the session's events
        self.events: list[SessionEvent] = []
        self.marks: list[Mark] = []
        # controller transitions taken into events (those before the session, e.g. of a
        # warm-up at set-up, are not the session's)
        self.seen = controller.event_count

    # ------------------------------------------------------------------ the end
    def begin_end(self, cause: EndCause, t: float) -> None:
        """Stop, then end: the controller is released (a stop at the acceleration limit) and
        the loop ends once the commanded motion is at rest."""
        if self.ending is None:
            self.ending, self.ending_since = cause, t
            self.note(t, "stop", str(cause))

    def finished(self, t: float) -> bool:
        """Whether the loop ends after this period (link lost, or a stop complete or timed
        out)."""
        if self.end is not None:
            return True
        if self.ending is None:
            return False
        if self.at_rest() and self.c_out.state != State.GUIDING:   # released, and at rest
            self.end = self._end_state(self.ending, t)
        elif t - self.ending_since >= self.stop_timeout_s:
            self.end = self._end_state(EndCause.STOP_TIMEOUT, t,
                                       f"not at rest {self.stop_timeout_s} s after the stop")
        return self.end is not None

    def close(self) -> None:
        """After the last period and the driver's stop: the watchdog stops, the controller's
        last transitions are taken into the events."""
        if self.watch is not None:
            self.watch.stop()
        self.drain()

    def session_events(self) -> list[SessionEvent]:
        """Transitions, marks and the loop's notes, in time order."""
        self.drain()
        return sorted(self.events, key=lambda e: e.t)

    def at_rest(self) -> bool:
        """The commanded motion is at rest: the controller holds its setpoint (no twist, no
        joint velocity, not stopping) and the servo command has reached it."""
        c_out, cmd = self.c_out, self.cmd
        return (not (cmd.qd.any() or c_out.qd.any() or c_out.twist_base.any())
                and c_out.state != State.STOPPING and np.array_equal(cmd.q, c_out.q))

    def restart(self, q: Array, t: float) -> None:
        """Restart every part at rest at ``q`` (a fault reset): the estimator warms up and tares
        again, the enabling device needs a fresh press, a suspect link is trusted again.

        Raises:
            ControlError: ``q`` refused by the controller (nothing changed).
        """
        self.controller.reset(q, t)
        self.estimator.reset(q)
        # the last output is the estimator's before the reset (a latched fault of a NaN
        # sample): the controller cycle of this period must not read it as the fresh one's
        self.e_out.status = EstimatorStatus.WARMING_UP
        self.e_out.wrench[:] = 0.0
        self.e_out.tau_ext[:] = 0.0
        self.interpolator.reset(q)
        self.cmd.q[:] = q
        self.cmd.qd[:] = 0.0
        self.enabling.reset()
        self.controller_tripped = self.stale = False
        if self.link is Link.SUSPECT:
            self.link = Link.OK

    def _end_state(self, cause: EndCause, t: float, detail: str = "") -> LoopEnd:
        return LoopEnd(cause, t, self.controller.state, self.controller.fault, detail)

    # ------------------------------------------------------------------ one period
    def period(self, i: int, t_loop: float, clock: PeriodClock) -> float:
        """Servo period ``i``: exchange with the driver, then :meth:`compute`. Returns the
        compute time [µs]."""
        clock.wait()
        fresh = self._exchange(t_loop)
        clock.exchanged()
        return self.compute(i, t_loop, fresh)

    def compute(self, i: int, t_loop: float, fresh: bool) -> float:
        """Period ``i``'s work after its exchange (``fresh``: a new sample came): estimate, the
        operator's inputs and requests, every ``every`` periods the controller cycle,
        interpolate. Returns its time [µs]."""
        t0 = time.perf_counter()
        fb = self.fb
        if fresh and self.follow_clock and fb.t > t_loop:
            t_loop = fb.t       # a real controller's cycles that went by without a packet
        self.t = t_loop
        if t0 - self.fresh_at > self.stale_s:
            self._stale(fresh, t_loop, t0 - self.fresh_at)
        if fresh:
            self.fresh_at, self.fresh_sequence = t0, fb.sequence
            self.e_in.t = fb.t
            self.estimator.update(self.e_in, self.e_out)
            if fb.inputs_read:
                self.inputs = fb.inputs
            if fb.state == ControllerState.NORMAL:
                self.controller_ready = True
            elif not self.controller_tripped and (self.controller_ready
                                                  or fb.state != ControllerState.NOT_READY):
                self._controller_fault(t_loop)
        if self.mark_bit >= 0 and self.mark_button.update(
                input_bit(self.inputs, self.mark_bit), t_loop):
            self.mark(t_loop, None)
        if self.reset_bit >= 0 and self.reset_button.update(
                input_bit(self.inputs, self.reset_bit), t_loop):
            self.reset_fault(t_loop)
        requests = self.requests
        if requests is not None:
            if requests.pending:
                self.serve(requests.take(), t_loop)
            if requests.stop_requested:
                self.begin_end(EndCause.STOP_REQUESTED, t_loop)
        if i % self.every == 0:
            self._cycle(i, t_loop)
        self.interp_status = self.interpolator.update(self.cmd)
        return (time.perf_counter() - t0) * 1e6

    def _exchange(self, t_loop: float) -> bool:
        """Write the command, step, read; a failure or a stall is a fault (see the module doc
        of :mod:`leadthrough.session.loop`). Returns whether a new sample arrived."""
        if self.link is Link.LOST:
            return False
        driver, watch = self.driver, self.watch
        start = time.perf_counter()
        if watch is not None:
            watch.enter(start)
        try:
            driver.write(self.cmd)
            driver.step()
            fresh = driver.read(self.fb)
        except Exception as e:
            fresh = False
            aborted = watch is not None and watch.fired
            self._link_failed(t_loop, Fault.DRIVER_TIMEOUT if aborted else Fault.DRIVER_ERROR,
                              math.nan, f"{type(e).__name__}: {e}", lost=aborted)
        finally:    # also when a second Ctrl-C escapes: the driver's stop is no exchange
            if watch is not None:
                watch.leave()
        elapsed = time.perf_counter() - start
        if elapsed > self.timeout_s and self.link is not Link.LOST:
            self._link_failed(t_loop, Fault.DRIVER_TIMEOUT, elapsed,
                              f"an exchange took {elapsed * 1e3:.1f} ms (watchdog "
                              f"{self.timeout_s * 1e3:.0f} ms)", lost=False)
        return fresh

    def _link_failed(self, t: float, fault: Fault, value: float, detail: str,
                     lost: bool) -> None:
        """A driver failure: the first latches ``fault`` and the stop goes on; a second (or an
        aborted call) ends the loop without commanding."""
        log.error("driver failure at t = %.3f s: %s", t, detail)
        self.controller.trip(t, fault, value)
        if lost or self.link is not Link.OK:
            self.link = Link.LOST
            self.note(t, "link lost", detail)
            self.end = self._end_state(EndCause.LINK_LOST, t, detail)
        else:
            self.link = Link.SUSPECT
            self.note(t, fault.name.lower().replace("_", " "), detail)

    def _stale(self, fresh: bool, t: float, age: float) -> None:
        """No sample from a real controller for longer than ``stale_s`` (``age`` [s]): the
        safety layer's stale feedback, on the wall clock (its own count of controller cycles
        would wait for as many stretched periods); seen when a period goes by without one,
        or when a sample comes that late with none newer behind it (the controller's packets
        came late; a sample with newer ones queued behind it means the loop itself was late,
        which the controller reports its own way). Latched and logged once until a reset."""
        if self.stale or (fresh and self.fb.sequence - self.fresh_sequence > 1):
            return
        self.stale = True
        self.controller.trip(t, Fault.STALE_FEEDBACK, float(self.fb.sequence))
        self.note(t, "stale feedback", f"no sample for {age * 1e3:.0f} ms (limit "
                                       f"{self.stale_s * 1e3:.0f} ms)"
                                       + ("; then a late one" if fresh else ""))

    def _controller_fault(self, t: float) -> None:
        code = int(self.fb.state)
        name = ControllerState(code).name or f"code {code}"
        self.controller.trip(t, Fault.CONTROLLER_STATE, float(code))
        self.controller_tripped = True
        self.note(t, "controller state", name)

    def _cycle(self, i: int, t_loop: float) -> None:
        """The controller cycle, and its setpoint for the interpolator."""
        c_in, c_out, e_out, fb = self.c_in, self.c_out, self.e_out, self.fb
        c_in.t = t_loop
        c_in.sequence = fb.sequence
        c_in.q[:] = fb.q
        c_in.current[:] = fb.current
        c_in.wrench_base[:] = e_out.wrench
        status = e_out.status
        self.held = held = self.enable_level is not None and self.enable_level(t_loop)
        self.ready = ready = (status == EstimatorStatus.OK and c_out.state != State.FAULT
                              and self.ending is None and self.controller_ready)
        c_in.deadman = self.enabling.update(held, ready)
        c_in.estimator_status = int(status)
        self.controller.update(c_in, c_out)
        if self.rezero_samples:
            zero_velocity_update(self.estimator, c_out.rest_s, self.settle_s, self.cycle_s,
                                  self.rezero_samples)
        self.interpolator.set_target(c_out.q, c_out.qd)
        if self.controller.event_count != self.seen:
            self.drain()

    # ------------------------------------------------------------------ the operator
    def serve(self, request: Request | None, t: float) -> None:
        """Serve one request from another thread (a fault reset, at once)."""
        if request is not None and request.kind is RequestKind.RESET_FAULT:
            self.reset_fault(t)

    def reset_fault(self, t: float) -> None:
        """Clear a latched fault and restart at the measured position (see the module doc)."""
        refusal = self._reset_refusal()
        if refusal is not None:
            self.note(t, "reset refused", refusal)
            return
        try:
            self.restart(self.fb.q.copy(), t)
        except ControlError as e:
            self.note(t, "reset refused", str(e))
            return
        self.note(t, "fault reset", "restarted at the measured position; the estimator tares "
                                    "again (hands off), then press the enabling device")

    def _reset_refusal(self) -> str | None:
        """Why a fault reset cannot be made now (None: it can)."""
        if self.controller.state != State.FAULT:
            return "no fault is latched"
        if not self.at_rest():
            return "the stop is not complete"
        state = int(self.fb.state)
        if state != ControllerState.NORMAL:
            name = (ControllerState(state).name if state in ControllerState._value2member_map_
                    else f"code {state}")
            return f"the robot controller reports {name}"
        q, q_cmd = self.fb.q, self.c_out.q
        if not np.isfinite(q).all():
            return "the measured position is not finite"
        error = np.abs(q - q_cmd)
        limit = self.controller.config.safety.following_error_limit
        # after the controller's own stop the robot is short of the commanded stop, where it
        # reports: its position is good to restart from
        if self.controller.fault != Fault.CONTROLLER_STATE and error.max() > limit:
            j = int(np.argmax(error))
            return (f"joint {j + 1} is {error[j]:.4f} rad from its command (limit {limit} rad): "
                    "check the robot and its encoders, then restart the session")
        return None

    # ------------------------------------------------------------------ events
    def note(self, t: float, label: str, detail: str) -> None:
        """A loop event (recorded and logged)."""
        self.events.append(SessionEvent(t=t, kind="loop", label=label, cause=detail))
        log.info("t = %.3f s: %s: %s", t, label, detail)

    def mark(self, t: float, label: str | None) -> None:
        """A mark at ``t`` (``label`` None: ``P<k>``)."""
        mark = Mark(t=t, label=label if label is not None else f"P{len(self.marks) + 1}")
        self.marks.append(mark)
        self.events.append(SessionEvent(t=t, kind="mark", label=mark.label))

    def drain(self) -> None:
        """The controller's new transitions into the session's events."""
        count = self.controller.event_count
        for e in self.controller.events_since(self.seen):
            self.events.append(transition_event(e))
        self.seen = count


def _enable_source(loop: ServoLoop, options: LoopOptions,
                   deadman: Callable[[float], bool] | None) -> Callable[[float], bool] | None:
    """The enabling device's level at the loop's time; None: no enabling device."""
    if deadman is not None:
        return deadman
    bit = options.enable_input
    if bit is not None:
        return lambda t: input_bit(loop.inputs, bit)
    return None
