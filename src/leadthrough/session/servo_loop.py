"""The guiding loop: its parts and their named state between servo periods, its start, one
period, and the operator's requests (see :mod:`leadthrough.session.loop` for the loop as a
whole and :func:`~leadthrough.session.loop.run` for the periods in time).

:class:`ServoLoop` holds every preallocated input and output, the operator's side (the enabling
device, the mark and reset inputs, requests and their notices and marks), the state of the link
to the driver (:class:`Link`), the stop in progress and the session's events.
:meth:`ServoLoop.start` takes the first sample; :meth:`ServoLoop.period` runs one servo period
(an exchange with the driver, then :meth:`ServoLoop.compute`); :meth:`ServoLoop.serve` is the
one handler of the operator's requests (:mod:`leadthrough.session.requests`), whichever channel
they come through (a queue of the same process, the pendant's pipe).

**Faults of a period**, all here, next to the controller's compiled rules
(:mod:`~leadthrough.control.safety_rules`, run in the controller cycle): the driver's
(an exception, ``Fault.DRIVER_ERROR``; an exchange over the watchdog's timeout,
``Fault.DRIVER_TIMEOUT``), stale feedback on the clock (``Fault.STALE_FEEDBACK``) and the robot
controller's own state (``Fault.CONTROLLER_STATE``); each latches through
:meth:`GuidingController.trip <leadthrough.control.guiding.GuidingController.trip>`.

**Fault reset**: at rest, with the robot controller reporting OK, the feedback finite and the
robot within the following-error limit of its command (beyond it the reported position cannot
be trusted to restart from: an encoder or a following fault), unless the controller stopped the
robot itself (``Fault.CONTROLLER_STATE``: it stopped short of the commanded stop). Every part
restarts at the measured position (after an E-stop the robot stopped where it was, short of the
commanded stop); the estimator warms up and tares again, and guiding needs a fresh press. A
reset that cannot be made is refused with a note (a ``loop`` event in the recording).

**The enabling device** is one of: a digital input of the driver (``LoopOptions.enable_input``),
a function of the loop's time (``deadman``, a scripted operator), or the operator's
:class:`~leadthrough.session.requests.SetEnable` requests (the pendant's hold-to-run button, with
a lease the loop enforces on its own clock: a hold whose lease has lapsed is released at the
next controller cycle, whatever the sender does). Requests cannot hold the device when an input
or a function is the enabling device. Whichever it is, guiding starts only on a fresh press
while the loop is ready (:class:`~leadthrough.session.operator_inputs.EnablingDevice`).

**The start** (:meth:`ServoLoop.start`): the first sample, every part warmed up and reset on it,
and a packet just come for the first period to answer. On a real controller the start is where
packets are most easily answered late: the first one may have waited since the driver opened,
and the set-up's compute (the watchdog's thread started, each part's ``warm_up``,
:data:`DRY_CYCLES` controller cycles of the loop's periods, the resets) may outlast a cycle. So
the start answers at once a packet it waited for (a hold where the robot stands), and one that
may have waited is answered only where the controller counts an unanswered packet late anyway
(a driver's ``answer_late_packets``, RSI); J519 refuses a late answer, the UR program holds a
cycle (:func:`fresh_packet`). Nothing that takes time is left between the last packet read and
its answer: the watchdog's thread, whose start faults in its whole stack where the memory is
locked, starts with the compute.

On a real controller the start then answers that packet itself, at once, and runs the loop's
period code once more (:meth:`ServoLoop.rewarm`) while the controller's next cycle comes.
Without it the start's compute ended up to three cycles before the first period's (two waits
for a packet, then the first period's own), against less than one between later periods, and
the first periods ran 1.5-2x slower than the steady state, by steps over four or five periods,
though the dry periods had already run the same code (a trace of the parts: cold caches, at a
guess). In short RSI sessions (``benchmarks/long_session.py --minutes 0.3``) the first
controller cycle was 1.15-2.02x the median (11 runs, median 1.75x), with it 0.64-1.40x (12
runs, median 1.05x). The rewarm (eight periods of 50-110 us each in the traced dry periods:
under 1 ms) runs after the answer, so a slow one delays no answer of the start's; at worst the
first period's packet has been waiting when its step comes, as after any overrun.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingController
from leadthrough.control.interpolation import InterpolatorStatus, JointInterpolator
from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.protocol import ControllerState, Driver, DriverFeedback, JointCommand
from leadthrough.errors import ControlError, LeadthroughError
from leadthrough.estimation.estimator import EstimatorStatus, ExternalForceEstimator
from leadthrough.session.controller_events import transition_event
from leadthrough.session.loop_config import LoopOptions
from leadthrough.session.loop_end import EndCause, Link, LoopEnd
from leadthrough.session.operator_inputs import EnablingDevice, MarkButton, input_bit
from leadthrough.session.pacing import Clock, PeriodClock, WallClock
from leadthrough.session.requests import (
    Adjust,
    ClearFault,
    MarkedPoint,
    MarkPoint,
    Notice,
    OperatorLost,
    Refused,
    RequestSource,
    SetEnable,
    SimulatorRequest,
    Stop,
    check_request,
)
from leadthrough.session.rest_rezero import zero_velocity_update
from leadthrough.session.watchdog import DriverWatchdog
from leadthrough.session_format import SessionEvent

__all__ = ["DRY_CYCLES", "MAX_MARKS", "NOTICES_KEPT", "REQUESTS_PER_PERIOD", "ServoLoop",
           "Simulator", "fresh_packet"]

Array = NDArray[np.float64]
log = logging.getLogger("leadthrough.session")

#: Controller cycles' periods of the loop computed on the first sample at the start, before
#: every part is reset (:meth:`ServoLoop.dry_periods`): as many as the calls after which the
#: interpreter has specialised a function's bytecode (CPython 3.11 quickens a code object on
#: its 8th call and specialises its instructions as that call runs them; 3.12 and later
#: sooner). Kept to that so that the start's compute stays within a cycle; a real
#: controller's packets that come meanwhile are answered by :func:`fresh_packet`.
DRY_CYCLES = 8
#: Notices kept for the operator (the latest).
NOTICES_KEPT = 20
#: Marks a session takes (the pendant's snapshot carries them all in a record of fixed size).
MAX_MARKS = 1000
#: Requests served in one servo period at most (the rest wait for the next).
REQUESTS_PER_PERIOD = 8

#: Applies a simulator's request at loop time t [s]; returns a notice for the operator (or
#: None).
Simulator = Callable[[SimulatorRequest, float], "str | None"]


class ServoLoop:
    """The loop's parts, preallocated inputs and outputs, and state (see the module doc).

    Args:
        driver: The robot.
        estimator: External force estimator.
        controller: Guiding controller.
        interpolator: Controller cycle → servo period interpolation.
        every: Servo periods per controller cycle.
        options: The loop's options.
        requests: Where the operator's requests come from, or None.
        deadman: The enabling device's level as a function of time, or None.
        simulator: Applies the simulator's requests (None: refused, a robot).
        clock: What the loop times with (default: the wall clock).
    """

    def __init__(self, driver: Driver, estimator: ExternalForceEstimator,
                 controller: GuidingController, interpolator: JointInterpolator, every: int,
                 options: LoopOptions, requests: RequestSource | None,
                 deadman: Callable[[float], bool] | None,
                 simulator: Simulator | None = None, clock: Clock | None = None) -> None:
        self.clock: Clock = clock if clock is not None else WallClock()
        self.options = options
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
        self._init_operator(options, requests, deadman, simulator)
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
        self.fresh_at = math.inf       # the clock's time of the newest sample
        self.fresh_sequence = -1       # and its sequence number
        self.stale = False             # latched (and logged) once until a fault reset
        # the session's events
        self.events: list[SessionEvent] = []
        # controller transitions taken into events (those before the session, e.g. of a
        # warm-up at set-up, are not the session's)
        self.seen = controller.event_count

    def _init_operator(self, options: LoopOptions, requests: RequestSource | None,
                       deadman: Callable[[float], bool] | None,
                       simulator: Simulator | None) -> None:
        """The operator's side: the enabling device, the mark and reset inputs, the requests
        and what the loop gives back."""
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
        self.simulator = simulator
        self.held = self.ready = False
        #: The operator's enabling device (:class:`SetEnable` requests), and its lease (the
        #: clock's time [s] it lapses at; inf: none).
        self.operator_held = False
        self.lease_until = math.inf
        #: Why the operator's channel was lost, if it was.
        self.operator_lost: str | None = None
        #: For the operator: notices (the latest), marked points, requests refused, holds
        #: dropped on a lapsed lease, and whether any of them (or the settings) changed since
        #: :attr:`changed` was last cleared (by whoever shows them).
        self.notices: deque[Notice] = deque(maxlen=NOTICES_KEPT)
        self.notice_count = 0
        self.marks: tuple[MarkedPoint, ...] = ()
        self.refused = self.lapsed = 0
        self.changed = True

    # ------------------------------------------------------------------ the start
    def start(self) -> float:
        """The first sample: every part reset there, their compiled code loaded (see the module
        doc); returns the sample's time [s].

        Raises:
            ControlError: No fresh sample within a second (a real controller) or on the first
                read (the simulator).
        """
        driver, fb, cmd = self.driver, self.fb, self.cmd
        # a real controller: its next packet within a second (a step waits a few cycles)
        tries = 1 if driver.simulated else max(1, math.ceil(1.0 / driver.dt))
        fresh = False
        for _ in range(tries):
            driver.step()
            fresh = driver.read(fb)
            if fresh:
                break
        if not fresh:
            raise ControlError("no feedback on the first read (the robot must report a "
                               "position to start from)", field="driver",
                               value=type(driver).__name__,
                               expected="a fresh sample on the first read")
        answer_all = bool(getattr(driver, "answer_late_packets", False))
        if not driver.simulated:   # that one may have been waiting: the next, just come,
            cmd.q[:] = fb.q        # is the one answered at once (that one too: a hold, if
            cmd.qd[:] = 0.0        # the controller counts an unanswered packet late)
            fresh_packet(driver, fb, cmd if answer_all else None, drained=True)
        q0 = fb.q.copy()
        if not driver.simulated:  # answered at once (a hold where it stands): the compute
            # below may outlast the cycle, and a packet seen and not answered in time is a
            # late answer to the controller (RSI counts it, the loop faults on it)
            cmd.q[:] = q0
            cmd.qd[:] = 0.0
            driver.write(cmd)
        watch = self.watch
        try:
            if watch is not None:   # its thread started in the set-up's compute (it watches
                watch.start()       # from the first period's exchange on), not in a period
            self._set_up(q0, answer_all)
        except BaseException:
            if watch is not None:
                watch.stop()
            raise
        self.t = fb.t
        self.fresh_at, self.fresh_sequence = self.clock.now(), fb.sequence
        return fb.t

    def _set_up(self, q0: Array, answer_all: bool) -> None:
        """The start's compute on the first sample ``q0``, then (a real controller) a packet
        just come for the first period to answer."""
        driver, fb, cmd = self.driver, self.fb, self.cmd
        t0 = fb.t
        self.dry_periods(q0, t0)
        self._reset(q0, t0)
        if not driver.simulated:  # a packet that has just come (one that came during the
            # compute: a hold, or unanswered as a lost one), answered at once with the hold
            fresh_packet(driver, fb, cmd if answer_all else None)
            driver.write(cmd)      # (the first period's write then has nothing to answer)
            self.rewarm(q0, t0)

    def _reset(self, q0: Array, t: float, drain: bool = True) -> None:
        """Every part reset at ``q0`` [rad], time ``t`` [s], and the hold computed; the reset's
        transition taken into the session's events now, not in a period (``drain``), or
        dropped."""
        self.estimator.reset(q0)
        self.controller.reset(q0, t)
        self.interpolator.reset(q0)
        self.interp_status = self.interpolator.update(self.cmd)
        if drain:
            self.drain()
        else:
            self.seen = self.controller.event_count

    def rewarm(self, q0: Array, t0: float) -> None:
        """The loop's period code once more, just before the first period (a real controller:
        after the start's answer, while its next cycle comes; module doc): the dry periods on
        the sample in ``fb``, without the parts' ``warm_up``, then every part reset as the
        start left it, at the first sample ``q0`` [rad], ``t0`` [s]. Nothing of it is the
        session's (``tests/test_loop_faults.py`` compares sessions with and without it)."""
        self._dry(self.fb.t)
        self._reset(q0, t0, drain=False)   # (the start's reset is already in the log)

    def dry_periods(self, q0: Array, t: float) -> None:
        """:data:`DRY_CYCLES` of the loop's own periods that run a controller cycle
        (:meth:`compute`) on the first sample, as if the robot stood there (the sample's time
        and sequence number counted on to each of those periods), with the operator's side held
        still (:meth:`_operator_still`); then every part is reset by the caller. The session's
        first period then runs code and state already touched, and code the interpreter has
        already specialised: each part's ``warm_up`` loads its compiled code on copies of its
        state, but the first update of the state itself took 2-3 times the steady-state median,
        and the period's own code (the controller cycle, the enabling device) ran
        unspecialised in the first cycles. Nothing of them is the session's: their transitions,
        notes and notices are dropped."""
        estimator, controller, interpolator = self.estimator, self.controller, self.interpolator
        estimator.reset(q0)
        controller.reset(q0, t)
        interpolator.reset(q0)
        for part in (estimator, controller, interpolator):
            part.warm_up()
        self._dry(t)

    def _dry(self, t: float) -> None:
        """:data:`DRY_CYCLES` controller cycles' periods on the sample in ``fb``, from time
        ``t`` [s] on, the operator's side held still; the sample's time and sequence number
        put back."""
        fb, every, dt = self.fb, self.every, self.driver.dt
        saved, sequence = fb.t, fb.sequence
        with self._operator_still():
            for k in range(DRY_CYCLES):   # the controller cycles' periods, the robot standing
                i = k * every
                fb.t, fb.sequence = t + i * dt, sequence + i
                self.compute(i, fb.t, True)
        fb.t, fb.sequence = saved, sequence
        self.seen = self.controller.event_count

    @contextmanager
    def _operator_still(self) -> Iterator[None]:
        """While the start's dry periods run: no enabling device, mark or reset button, requests
        or controller-state fault is read, and what they may write (the session's events,
        notices, the enabling device's history, the loop's flags) is put back after."""
        saved = (self.requests, self.enable_level, self.mark_bit, self.reset_bit, self.inputs,
                 self.controller_ready, self.controller_tripped, self.held, self.ready,
                 self.notice_count, self.changed)
        events, notices = len(self.events), tuple(self.notices)
        self.requests, self.mark_bit, self.reset_bit = None, -1, -1
        self.enable_level = _released
        self.controller_tripped = True   # the controller's state is the first period's to read
        try:
            yield
        finally:
            (self.requests, self.enable_level, self.mark_bit, self.reset_bit, self.inputs,
             self.controller_ready, self.controller_tripped, self.held, self.ready,
             self.notice_count, self.changed) = saved
            del self.events[events:]
            self.notices.clear()
            self.notices.extend(notices)
            self.enabling.reset()

    # ------------------------------------------------------------------ the end
    def begin_end(self, cause: EndCause, t: float) -> None:
        """Stop, then end: the controller is released (a stop at the acceleration limit) and
        the loop ends once the commanded motion is at rest."""
        if self.ending is None:
            self.ending, self.ending_since = cause, t
            self.note(t, "stop", str(cause), "info")

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
        clock = self.clock
        t0 = clock.now()
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
            for _ in range(REQUESTS_PER_PERIOD):
                request = requests.poll()
                if request is None:
                    break
                self.serve(request, t_loop)
            if requests.stop_requested:
                self.begin_end(EndCause.STOP_REQUESTED, t_loop)
        if i % self.every == 0:
            self._cycle(i, t_loop)
        self.interp_status = self.interpolator.update(self.cmd)
        return (clock.now() - t0) * 1e6

    def _exchange(self, t_loop: float) -> bool:
        """Write the command, step, read; a failure or a stall is a fault (see the module doc
        of :mod:`leadthrough.session.loop`). Returns whether a new sample arrived."""
        if self.link is Link.LOST:
            return False
        driver, watch = self.driver, self.watch
        start = self.clock.now()
        if watch is not None:
            watch.enter()
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
        elapsed = self.clock.now() - start
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
        level = self.enable_level
        self.held = held = (self.enabled_by_operator(t_loop) if level is None
                            else level(t_loop))
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
    def serve(self, request: object, t: float) -> None:
        """Serve one request at loop time ``t`` [s] (the one handler, whichever channel it came
        through): checked again here, applied under a guard; a malformed one, or one whose
        effect fails, is refused with a notice and counted (:attr:`refused`), never raised,
        and a malformed hold or stop releases the enabling device."""
        try:
            if not isinstance(request, OperatorLost | Refused):
                check_request(request)
            self._serve(request, t)
        except Exception as e:  # nothing a request carries may end the loop
            if isinstance(request, SetEnable | Stop):   # when in doubt, released
                self.operator_held, self.lease_until = False, math.inf
            why = str(e) if isinstance(e, LeadthroughError) else f"{type(e).__name__}: {e}"
            self.refuse(f"request {type(request).__name__}", why)

    def _serve(self, request: object, t: float) -> None:
        if isinstance(request, SetEnable):
            self._set_enable(request)
        elif isinstance(request, Stop):
            self.operator_held, self.lease_until = False, math.inf
            self.begin_end(EndCause.STOP_REQUESTED, t)
        elif isinstance(request, ClearFault):
            self.reset_fault(t)
        elif isinstance(request, MarkPoint):
            self.mark(t, request.label)
        elif isinstance(request, Adjust):
            self._adjust(request)
        elif isinstance(request, SimulatorRequest):
            if self.simulator is None:
                self.notice("warning", f"not a simulator: {type(request).__name__} refused")
            else:
                text = self.simulator(request, t)
                if text is not None:
                    self.notice("info", text)
        elif isinstance(request, OperatorLost):
            if self.operator_lost is None:
                self.operator_lost = request.why
                self.operator_held, self.lease_until = False, math.inf
                self.note(t, "operator lost", f"{request.why}: enabling device released")
                self.begin_end(EndCause.OPERATOR_LOST, t)
        elif isinstance(request, Refused):
            self.refuse(request.what, request.why)

    def _set_enable(self, request: SetEnable) -> None:
        """The operator's enabling device: held (with its lease) or released."""
        if request.held and self.enable_level is not None:
            what = ("a scripted enabling device" if self.options.enable_input is None
                    else f"the controller's input {self.options.enable_input}")
            self.refuse("holding the enabling device", f"the enabling device is {what}")
            return
        self.operator_held = request.held and self.operator_lost is None
        self.lease_until = (request.until if self.operator_held and request.until is not None
                            else math.inf)
        if self.operator_held:
            self._check_lease()     # a heartbeat arriving after its own lease: no hold

    def enabled_by_operator(self, t: float) -> bool:
        """The operator's enabling device at loop time ``t`` (its lease checked)."""
        if self.operator_held:
            self._check_lease()
        return self.operator_held

    def _check_lease(self) -> None:
        """Release the operator's enabling device if its lease has lapsed."""
        late = self.clock.now() - self.lease_until
        if late > 0.0:
            self.operator_held, self.lease_until = False, math.inf
            self.lapsed += 1
            self.notice("warning", f"enabling device released: no heartbeat from the page "
                                   f"(lease lapsed {1e3 * late:.0f} ms before this cycle)")

    def _adjust(self, req: Adjust) -> None:
        """Frame, axes, virtual mass or friction changed (refused or clamped with a notice)."""
        try:
            cfg = self.controller.adjust(frame=req.frame, axes_enabled=req.axes_enabled,
                                         mass=req.mass, friction=req.friction)
        except ControlError as e:
            self.notice("warning", f"not changed: {e}")
            return
        self.changed = True
        vf = cfg.virtual_friction
        if req.mass is not None and (vf.mass[0], vf.mass[3]) != tuple(req.mass):
            self.notice("warning", f"virtual mass clamped to {vf.mass[0]:g} kg, "
                                   f"{vf.mass[3]:g} kg·m²")
        if req.friction is not None and (vf.friction[0], vf.friction[3]) != tuple(req.friction):
            self.notice("warning", f"friction clamped to {vf.friction[0]:g} N, "
                                   f"{vf.friction[3]:g} N·m")

    def refuse(self, what: str, why: str) -> None:
        """Count and report a refused request."""
        self.refused += 1
        self.notice("warning", f"{what} refused: {why[:300]}")

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
                                    "again (hands off), then press the enabling device",
                  "info")

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
    def note(self, t: float, label: str, detail: str, level: str = "warning") -> None:
        """A loop event: recorded, logged, and a notice for the operator."""
        self.events.append(SessionEvent(t=t, kind="loop", label=label, cause=detail))
        log.info("t = %.3f s: %s: %s", t, label, detail)
        self.notice(level, f"{label}: {detail}")

    def notice(self, level: str, text: str) -> None:
        """A message for the operator (``level`` ``"info"`` or ``"warning"``)."""
        self.notice_count += 1
        self.notices.append(Notice(self.notice_count, level, text))
        self.changed = True

    def mark(self, t: float, label: str | None) -> None:
        """Mark the measured pose at ``t`` (``label`` None: ``P<k>``); at most
        :data:`MAX_MARKS`."""
        if len(self.marks) >= MAX_MARKS:
            self.notice("warning", f"not marked: {MAX_MARKS} marks is the most a session "
                                   "keeps (export, then restart)")
            return
        name = label if label is not None else f"P{len(self.marks) + 1}"
        self.marks = (*self.marks, MarkedPoint(name, t, self.fb.q.copy()))
        self.events.append(SessionEvent(t=t, kind="mark", label=name))
        self.notice("info", f"marked {name} at {t:.2f} s")

    def drain(self) -> None:
        """The controller's new transitions into the session's events."""
        count = self.controller.event_count
        for e in self.controller.events_since(self.seen):
            self.events.append(transition_event(e))
        self.seen = count


def _enable_source(loop: ServoLoop, options: LoopOptions,
                   deadman: Callable[[float], bool] | None) -> Callable[[float], bool] | None:
    """The enabling device's level at the loop's time: ``deadman``, the enabling input, or
    None: the operator's requests (:meth:`ServoLoop.enabled_by_operator`; not a bound method
    kept on the loop, which would make the loop a reference cycle for the collector)."""
    if deadman is not None:
        return deadman
    bit = options.enable_input
    if bit is not None:
        return lambda t: input_bit(loop.inputs, bit)
    return None


def _released(t: float) -> bool:
    """No enabling device held (the start's dry periods)."""
    return False


def fresh_packet(driver: Driver, fb: DriverFeedback, hold: JointCommand | None = None,
                 drained: bool = False) -> None:
    """Read a real controller's packet that has just come: a whole cycle ahead to answer it.

    ``step`` returns the newest packet waiting, which may have come up to a cycle ago (during
    a compute): answered then, the answer may reach the controller after its next cycle, a
    late answer (J519 refuses it and reports it, a fault at the stream's start). So the
    packets waiting are taken (``drained``: the caller has just taken them) and left
    unanswered, as lost ones (J519 and the UR program hold a cycle), or answered with ``hold``
    when given (RSI counts an unanswered packet late as well: the answer may still be in
    time); then the next one, waited for, is read: the answer written at once goes out within
    the cycle."""
    if not drained:
        driver.step()
        driver.read(fb)
    if hold is not None:
        driver.write(hold)
    driver.step()
    driver.read(fb)
