"""The guiding loop's start (:func:`start_loop`, on a
:class:`~leadthrough.session.servo_loop.ServoLoop`): the first sample, every part warmed up and
reset on it, and a packet just come for the first period to answer.

On a real controller the start is where packets are most easily answered late: the first one
may have waited since the driver opened, and the set-up's compute (the watchdog's thread
started, each part's ``warm_up``, :data:`DRY_CYCLES` controller cycles of the loop's periods,
the resets) may outlast a cycle. So the start answers at once a packet it waited for (a hold
where the robot stands), and one that may have waited is answered only where the controller
counts an unanswered packet late anyway (a driver's ``answer_late_packets``, RSI); J519 refuses
a late answer, the UR program holds a cycle (:func:`fresh_packet`). Nothing that takes time is
left between the last packet read and its answer: the watchdog's thread, whose start faults in
its whole stack where the memory is locked, starts with the compute.

On a real controller the start then answers that packet itself, at once, and runs the loop's
period code once more (:func:`rewarm`) while the controller's next cycle comes. Without it the
start's compute ended up to three cycles before the first period's (two waits for a packet,
then the first period's own), against less than one between later periods, and the first
periods ran 1.5-2x slower than the steady state, by steps over four or five periods, though the
dry periods had already run the same code (a trace of the parts: cold caches, at a guess). In
short RSI sessions (``benchmarks/long_session.py --minutes 0.3``) the first controller cycle
was 1.15-2.02x the median (11 runs, median 1.75x), with it 0.64-1.40x (12 runs, median
1.05x); issue 25's goal is 2x. The rewarm (eight periods of 50-110 us each in the traced dry
periods: under 1 ms) runs after the answer, so a slow one delays no answer of the start's; at
worst the first period's packet has been waiting when its step comes, as after any overrun.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand
from leadthrough.errors import ControlError

if TYPE_CHECKING:
    from leadthrough.session.servo_loop import ServoLoop

__all__ = ["DRY_CYCLES", "dry_periods", "fresh_packet", "rewarm", "start_loop"]

Array = NDArray[np.float64]
#: Controller cycles' periods of the loop computed on the first sample at the start, before
#: every part is reset (:func:`dry_periods`): as many as the calls after which the interpreter
#: has specialised a function's bytecode (CPython 3.11 quickens a code object on its 8th call
#: and specialises its instructions as that call runs them; 3.12 and later sooner). Kept to
#: that so that the start's compute stays within a cycle; a real controller's packets that
#: come meanwhile are answered by :func:`fresh_packet`.
DRY_CYCLES = 8


def start_loop(loop: ServoLoop) -> float:
    """The first sample: every part reset there, their compiled code loaded (see the module
    doc); returns the sample's time [s].

    Raises:
        ControlError: No fresh sample within a second (a real controller) or on the first
            read (the simulator).
    """
    driver, fb, cmd = loop.driver, loop.fb, loop.cmd
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
    watch = loop.watch
    try:
        if watch is not None:   # its thread started in the set-up's compute (it watches
            watch.start()       # from the first period's exchange on), not in a period
        _set_up(loop, q0, answer_all)
    except BaseException:
        if watch is not None:
            watch.stop()
        raise
    loop.t = fb.t
    loop.fresh_at, loop.fresh_sequence = time.perf_counter(), fb.sequence
    return fb.t


def _set_up(loop: ServoLoop, q0: Array, answer_all: bool) -> None:
    """The start's compute on the first sample ``q0``, then (a real controller) a packet just
    come for the first period to answer."""
    driver, fb, cmd = loop.driver, loop.fb, loop.cmd
    t0 = fb.t
    dry_periods(loop, q0, t0)
    _reset(loop, q0, t0)
    if not driver.simulated:  # a packet that has just come (one that came during the
        # compute: a hold, or unanswered as a lost one), answered at once with the hold
        fresh_packet(driver, fb, cmd if answer_all else None)
        driver.write(cmd)      # (the first period's write then has nothing to answer)
        rewarm(loop, q0, t0)


def _reset(loop: ServoLoop, q0: Array, t: float, drain: bool = True) -> None:
    """Every part reset at ``q0`` [rad], time ``t`` [s], and the hold computed; the reset's
    transition taken into the session's events now, not in a period (``drain``), or
    dropped."""
    loop.estimator.reset(q0)
    loop.controller.reset(q0, t)
    loop.interpolator.reset(q0)
    loop.interp_status = loop.interpolator.update(loop.cmd)
    if drain:
        loop.drain()
    else:
        loop.seen = loop.controller.event_count


def rewarm(loop: ServoLoop, q0: Array, t0: float) -> None:
    """The loop's period code once more, just before the first period (a real controller:
    after the start's answer, while its next cycle comes; module doc): :func:`dry_periods`'
    periods on the sample in ``loop.fb``, without the parts' ``warm_up``, then every part
    reset as the start left it, at the first sample ``q0`` [rad], ``t0`` [s]. Nothing of it is
    the session's (``tests/test_loop_faults.py`` compares sessions with and without it)."""
    _periods(loop, loop.fb.t)
    _reset(loop, q0, t0, drain=False)   # (the start's reset is already in the session's log)


def dry_periods(loop: ServoLoop, q0: Array, t: float) -> None:
    """:data:`DRY_CYCLES` of the loop's own periods that run a controller cycle
    (:meth:`ServoLoop.compute <leadthrough.session.servo_loop.ServoLoop.compute>`) on the first
    sample, as if the robot stood there (the sample's time and sequence number counted on to
    each of those periods), with the operator's side held still (:func:`_operator_held`); then
    every part is reset by the caller. The session's first period then runs code and state
    already touched, and code the interpreter has already specialised: each part's ``warm_up``
    loads its compiled code on copies of its state, but the first update of the state itself
    took 2-3 times the steady-state median, and the period's own code (the controller cycle, the
    enabling device) ran unspecialised in the first cycles. Nothing of them is the
    session's: their transitions and notes are dropped."""
    estimator, controller, interpolator = loop.estimator, loop.controller, loop.interpolator
    estimator.reset(q0)
    controller.reset(q0, t)
    interpolator.reset(q0)
    for part in (estimator, controller, interpolator):
        part.warm_up()
    _periods(loop, t)


def _periods(loop: ServoLoop, t: float) -> None:
    """:data:`DRY_CYCLES` controller cycles' periods on the sample in ``loop.fb``, from time
    ``t`` [s] on, the operator's side held still; the sample's time and sequence number put
    back."""
    fb, every, dt = loop.fb, loop.every, loop.driver.dt
    saved, sequence = fb.t, fb.sequence
    with _operator_held(loop):
        for k in range(DRY_CYCLES):   # the controller cycles' periods, the robot standing
            i = k * every
            fb.t, fb.sequence = t + i * dt, sequence + i
            loop.compute(i, fb.t, True)
    fb.t, fb.sequence = saved, sequence
    loop.seen = loop.controller.event_count


@contextmanager
def _operator_held(loop: ServoLoop) -> Iterator[None]:
    """While the start's dry periods run: no enabling device, mark or reset button, requests
    or controller-state fault is read, and what they may write (the session's events, the
    enabling device's history, the loop's flags) is put back after."""
    saved = (loop.requests, loop.enable_level, loop.mark_bit, loop.reset_bit, loop.inputs,
             loop.controller_ready, loop.controller_tripped, loop.held, loop.ready)
    events = len(loop.events)
    loop.requests, loop.enable_level, loop.mark_bit, loop.reset_bit = None, None, -1, -1
    loop.controller_tripped = True   # the controller's state is the first period's to read
    try:
        yield
    finally:
        (loop.requests, loop.enable_level, loop.mark_bit, loop.reset_bit, loop.inputs,
         loop.controller_ready, loop.controller_tripped, loop.held, loop.ready) = saved
        del loop.events[events:]
        loop.enabling.reset()


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
