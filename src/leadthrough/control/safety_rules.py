"""The safety supervisor's rules, compiled (Numba, ``nopython``, cached on disk).

:class:`~leadthrough.control.safety.SafetySupervisor` documents the states, the faults and the
rules; this module holds the supervisor's record and runs the rules on it, so that the guiding
cycle (:mod:`leadthrough.control.guiding_cycle`) runs them inside its own compiled call and the
supervisor's methods run the very same functions. The state is two arrays:

* the supervisor's record (:func:`supervisor_dtype`): settings (per-joint bounds, thresholds,
  the workspace box) and state (the safety state, the latched fault, the deadman's arming, the
  sequence-number watch, the event counter);
* the event ring (:data:`EVENT_DTYPE`): the last transitions, one record each;
  ``event_count`` counts every transition ever logged, so the ring's oldest entry and the number
  dropped follow from it.

Codes are the members of :class:`~leadthrough.control.safety_states.State`, ``Fault`` and
``Cause`` themselves. Nothing here allocates.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control.limits import braking_distance
from leadthrough.control.safety_states import Cause, Fault, State

__all__ = [
    "EVENT_DTYPE",
    "check_feedback",
    "check_motion",
    "clear_fault",
    "deadman",
    "feedback_fault",
    "reset",
    "speed_scale",
    "stopped",
    "supervisor_dtype",
    "transition",
    "trip",
    "workspace_clearance",
]

Array = NDArray[np.float64]
Record = Any   # a record of supervisor_dtype(n) (compiled code reads it by field)
Events = NDArray[np.void]

#: One logged transition: time [s], states before and after, cause, fault, offending value and
#: joint or axis index (-1: none).
EVENT_DTYPE = np.dtype([
    ("t", np.float64), ("from_state", np.int64), ("to_state", np.int64), ("cause", np.int64),
    ("fault", np.int64), ("value", np.float64), ("index", np.int64)])


@cache
def supervisor_dtype(n: int) -> np.dtype[Any]:
    """The supervisor's record for ``n`` joints: settings, then state."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    return np.dtype([
        # settings: per joint, the middle of the position range and half the range plus the
        # position tolerance [rad], the current bound [A], the joint-limit margins [rad]
        ("position_middle", f8, (n,)), ("position_half_range", f8, (n,)),
        ("max_current", f8, (n,)), ("lower_margin", f8, (n,)), ("upper_margin", f8, (n,)),
        # thresholds: following error [rad], collision force [N] and torque [N·m], the
        # manipulability of a stop and the span to that of the slow-down, the smallest speed
        # scale, the IK residual, the workspace margin [m], a_max [m/s²] of the braking distance
        ("following_limit", f8), ("max_force", f8), ("max_torque", f8),
        ("stop_manipulability", f8), ("slow_span", f8), ("min_speed_scale", f8),
        ("tracking_limit", f8), ("workspace_margin", f8), ("max_linear_acceleration", f8),
        ("box_low", f8, (3,)), ("box_high", f8, (3,)), ("has_box", b1),
        ("stale_cycles", i8), ("require_edge", b1),
        # state
        ("state", i8), ("fault", i8), ("fault_value", f8), ("fault_index", i8),
        ("armed", b1),            # a press counts (the deadman was seen released)
        ("has_sequence", b1),     # a sequence number was seen since the last (re)start
        ("last_sequence", i8), ("missed", i8),   # cycles without a new sequence number
        ("inputs_finite", b1),    # t, q, current and wrench of the last check were finite
        ("event_count", i8),      # transitions logged since construction
        ("mu_previous", f8),
        ("check_value", f8), ("check_index", i8),   # the first failed feedback check's
        ("idle_collision", b1),   # the last check found a collision-level wrench in IDLE
    ])


@njit(cache=True, nogil=True)
def transition(sup: Record, events: Events, t: float, to: int, cause: int, fault: int,
               value: float, index: int) -> None:
    """Log a transition in the ring and enter state ``to``."""
    e = events[sup.event_count % events.size]
    e.t, e.from_state, e.to_state = t, sup.state, to
    e.cause, e.fault, e.value, e.index = cause, fault, value, index
    sup.event_count += 1
    sup.state = to


@njit(cache=True, nogil=True)
def _restart(sup: Record) -> None:
    sup.armed = not sup.require_edge
    sup.has_sequence = False
    sup.missed = 0
    sup.mu_previous = math.nan


@njit(cache=True, nogil=True)
def _clear(sup: Record) -> None:
    sup.fault, sup.fault_index = Fault.NONE, -1
    sup.fault_value = math.nan


@njit(cache=True, nogil=True)
def reset(sup: Record, events: Events, t: float) -> None:
    """Back to IDLE, fault cleared, counters restarted (logged as RESET)."""
    _clear(sup)
    _restart(sup)
    transition(sup, events, t, State.IDLE, Cause.RESET, Fault.NONE, math.nan, -1)


@njit(cache=True, nogil=True)
def trip(sup: Record, events: Events, t: float, fault: int, value: float, index: int) -> None:
    """Enter FAULT (no-op if already there: the first fault is kept)."""
    if sup.state == State.FAULT:
        return
    sup.fault, sup.fault_index = fault, index
    sup.fault_value = value
    transition(sup, events, t, State.FAULT, Cause.FAULT, fault, value, index)


@njit(cache=True, nogil=True)
def clear_fault(sup: Record, events: Events, t: float, at_rest: bool) -> bool:
    """FAULT → IDLE, only at rest; returns whether the fault was cleared."""
    if sup.state != State.FAULT or not at_rest:
        return False
    _clear(sup)
    _restart(sup)
    transition(sup, events, t, State.IDLE, Cause.FAULT_CLEARED, Fault.NONE, math.nan, -1)
    return True


@njit(cache=True, nogil=True)
def deadman(sup: Record, events: Events, t: float, held: bool) -> None:
    """IDLE → GUIDING on a press (once armed), GUIDING → STOPPING on a release; a release
    arms the next press. A press while this cycle's check found a collision-level wrench in
    IDLE (``check_feedback``) trips COLLISION instead: guiding never starts on it."""
    state = sup.state
    if state == State.IDLE and held:
        if sup.armed and sup.idle_collision:
            trip(sup, events, t, Fault.COLLISION, sup.check_value, sup.check_index)
        elif sup.armed:
            transition(sup, events, t, State.GUIDING, Cause.DEADMAN_PRESSED, Fault.NONE,
                       math.nan, -1)
        return
    if not held:
        sup.armed = True
        if state == State.GUIDING:
            transition(sup, events, t, State.STOPPING, Cause.DEADMAN_RELEASED, Fault.NONE,
                       math.nan, -1)


@njit(cache=True, nogil=True)
def stopped(sup: Record, events: Events, t: float, at_rest: bool) -> None:
    """STOPPING → IDLE once the commanded motion is at rest."""
    if sup.state == State.STOPPING and at_rest:
        transition(sup, events, t, State.IDLE, Cause.STOPPED, Fault.NONE, math.nan, -1)


@njit(cache=True, nogil=True)
def _all_finite(q: Array, current: Array, wrench: Array) -> bool:
    """Whether every entry of the three arrays is finite (``q`` and ``current`` of one size)."""
    acc = 0.0    # any NaN or inf makes the sum of x·0 NaN
    for j in range(q.size):
        acc += q[j] * 0.0 + current[j] * 0.0
    for j in range(wrench.size):
        acc += wrench[j] * 0.0
    return acc == 0.0


@njit(cache=True, nogil=True)
def feedback_fault(sup: Record, q: Array, current: Array, wrench: Array,
                   q_commanded: Array) -> int:
    """The checks of the feedback, in order: finite (q, current, wrench), position range,
    current range, following error, collision force, collision torque.

    Args:
        sup: The supervisor's record (bounds and thresholds; ``check_value`` and
            ``check_index`` are written).
        q: Measured joint positions [rad], shape (n,).
        current: Measured currents [A], shape (n,).
        wrench: Estimated wrench, force first [N, N·m], shape (6,).
        q_commanded: Commanded joint positions [rad], shape (n,).

    Returns:
        ``Fault.NONE`` or the fault of the first failed check, its value and index in
        ``check_value`` / ``check_index`` (the joint with the largest excess, or the wrench
        norm and 0 for force, 1 for torque; not set for ``NONFINITE_INPUT``, which also stands
        for arrays of the wrong size).
    """
    n = q_commanded.size
    if q.size != n or current.size != n or wrench.size != 6:
        return Fault.NONFINITE_INPUT
    if not _all_finite(q, current, wrench):
        return Fault.NONFINITE_INPUT
    for check in (Fault.POSITION_RANGE, Fault.CURRENT_RANGE, Fault.FOLLOWING_ERROR):
        worst, jw = -math.inf, 0
        for j in range(n):
            if check == Fault.POSITION_RANGE:
                x = abs(q[j] - sup.position_middle[j]) - sup.position_half_range[j]
            elif check == Fault.CURRENT_RANGE:
                x = abs(current[j]) - sup.max_current[j]
            else:
                x = abs(q[j] - q_commanded[j])
            if x > worst:
                worst, jw = x, j
        if check == Fault.FOLLOWING_ERROR:
            if worst > sup.following_limit:
                sup.check_value, sup.check_index = worst, jw
                return check
        elif worst > 0.0:
            sup.check_value = q[jw] if check == Fault.POSITION_RANGE else current[jw]
            sup.check_index = jw
            return check
    force = math.sqrt(wrench[0] ** 2 + wrench[1] ** 2 + wrench[2] ** 2)
    torque = math.sqrt(wrench[3] ** 2 + wrench[4] ** 2 + wrench[5] ** 2)
    if force > sup.max_force:
        sup.check_value, sup.check_index = force, 0
        return Fault.COLLISION
    if torque > sup.max_torque:
        sup.check_value, sup.check_index = torque, 1
        return Fault.COLLISION
    return Fault.NONE


@njit(cache=True, nogil=True)
def check_feedback(sup: Record, events: Events, t: float, sequence: int, q: Array,
                   current: Array, wrench: Array, q_commanded: Array) -> None:
    """Input faults, in order: non-finite (or wrong size), stale, position and current range,
    following error, collision (see :meth:`SafetySupervisor.check_feedback
    <leadthrough.control.safety.SafetySupervisor.check_feedback>`); collision not in IDLE."""
    fault = feedback_fault(sup, q, current, wrench, q_commanded)
    sup.idle_collision = fault == Fault.COLLISION and sup.state == State.IDLE
    if sup.idle_collision:      # held at rest: the press trips it (deadman)
        fault = Fault.NONE
    finite = math.isfinite(t) and fault != Fault.NONFINITE_INPUT
    sup.inputs_finite = finite
    if sup.state == State.FAULT:
        return
    if not finite:
        trip(sup, events, t, Fault.NONFINITE_INPUT, math.nan, -1)
        return
    if sup.has_sequence and sequence <= sup.last_sequence:
        sup.missed += 1
        if sup.missed >= sup.stale_cycles:
            trip(sup, events, t, Fault.STALE_FEEDBACK, float(sequence), -1)
            return
    else:
        sup.missed = 0
        sup.last_sequence = sequence
        sup.has_sequence = True
    if fault != Fault.NONE:
        trip(sup, events, t, fault, sup.check_value, sup.check_index)


@njit(cache=True, nogil=True)
def _joint_at_limit(q: Array, qd: Array, lower: Array, upper: Array) -> int:
    """First joint at or beyond a bound and moving toward it (−1: none)."""
    for j in range(q.size):
        if (qd[j] > 0.0 and q[j] >= upper[j]) or (qd[j] < 0.0 and q[j] <= lower[j]):
            return j
    return -1


@njit(cache=True, nogil=True)
def check_motion(sup: Record, events: Events, t: float, manipulability: float,
                 q_commanded: Array, qd_commanded: Array, residual: float) -> None:
    """Motion faults, in order: singularity (μ below the stop threshold and falling), a joint
    at its margin and moving toward it, the IK residual."""
    mu_previous = sup.mu_previous
    sup.mu_previous = manipulability
    if sup.state == State.FAULT:
        return
    if manipulability < sup.stop_manipulability and manipulability < mu_previous:
        trip(sup, events, t, Fault.SINGULARITY, manipulability, -1)
        return
    j = _joint_at_limit(q_commanded, qd_commanded, sup.lower_margin, sup.upper_margin)
    if j >= 0:
        trip(sup, events, t, Fault.JOINT_LIMIT, q_commanded[j], j)
        return
    if residual > sup.tracking_limit:
        trip(sup, events, t, Fault.TRACKING, residual, -1)


@njit(cache=True, nogil=True)
def speed_scale(sup: Record, manipulability: float) -> float:
    """(μ − μ_stop)/(μ_slow − μ_stop), clipped to [min_speed_scale, 1]."""
    s = (manipulability - sup.stop_manipulability) / sup.slow_span
    return min(1.0, max(sup.min_speed_scale, s))


@njit(cache=True, nogil=True)
def workspace_clearance(sup: Record, position: Array, linear_speed: float,
                        stop_time: float) -> float:
    """min over the box's faces of (distance) − margin − braking distance [m]; +inf without a
    box (:func:`~leadthrough.control.limits.braking_distance`)."""
    if not sup.has_box:
        return math.inf
    c = math.inf
    for i in range(3):
        p = position[i]
        c = min(c, p - sup.box_low[i], sup.box_high[i] - p)
    braking = braking_distance(linear_speed, sup.max_linear_acceleration, stop_time)
    return c - sup.workspace_margin - braking
