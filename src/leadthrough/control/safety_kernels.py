"""The safety layer's state machine and checks, compiled (Numba, ``nopython``, cached on disk).

:class:`~leadthrough.control.safety.SafetySupervisor` documents the states, the faults and the
rules; this module holds its state and runs its rules, so that the guiding cycle
(:mod:`leadthrough.control.cycle_kernel`) can run them inside one compiled call and the
supervisor's own methods run the very same code. The state lives in four packed arrays:

* ``flags`` (:data:`FLAG_SLOTS`,), int64: the state, the latched fault and its index, the
  deadman's arming, the sequence-number watch, the event counter, and integer settings;
* ``values`` (:data:`VALUE_SLOTS`,), float64: the fault's value, the last μ, scratch, and the
  float settings (thresholds, the workspace box);
* ``joints`` (:data:`JOINT_ROWS`, n), float64: per-joint bounds;
* ``events`` (capacity, :data:`EVENT_COLUMNS`), float64: a ring of the last transitions, one
  row each (t, from, to, cause, fault, value, index); ``flags[EVENT_COUNT]`` counts every
  transition ever logged, so the ring's oldest row and the number dropped follow from it.

The three float arrays are views of one buffer (:func:`safety_views`), so that a compiled call
takes them as one argument.

Codes are those of :class:`~leadthrough.control.safety.State`,
:class:`~leadthrough.control.safety.Fault` and :class:`~leadthrough.control.safety.Cause`
(tested to agree). Nothing here allocates.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control import kernels

__all__ = [
    "EVENT_COLUMNS",
    "FLAG_SLOTS",
    "JOINT_ROWS",
    "VALUE_SLOTS",
    "check_feedback",
    "check_motion",
    "clear_fault",
    "deadman",
    "reset",
    "safety_size",
    "safety_views",
    "speed_scale",
    "stopped",
    "transition",
    "trip",
    "workspace_clearance",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

# states (State), faults (Fault) and causes (Cause) used here
IDLE, GUIDING, STOPPING, FAULT = 0, 1, 2, 3
F_NONE, F_NONFINITE, F_POSITION, F_CURRENT, F_STALE, F_FOLLOWING, F_COLLISION = range(7)
F_JOINT_LIMIT, F_WORKSPACE, F_SINGULARITY, F_TRACKING, F_NOT_STARTED, F_ESTIMATOR = range(7, 13)
C_PRESSED, C_RELEASED, C_STOPPED, C_FAULT, C_CLEARED, C_RESET = range(6)

# slots of ``flags``
STATE = 0
FAULT_CODE = 1
FAULT_INDEX = 2
ARMED = 3                 # a press counts (the deadman was seen released)
HAS_SEQUENCE = 4          # a sequence number was seen since the last (re)start
LAST_SEQUENCE = 5
MISSED = 6                # consecutive cycles without a new sequence number
INPUTS_FINITE = 7         # t, q, current and wrench of the last check were finite
EVENT_COUNT = 8           # transitions logged since construction
REQUIRE_EDGE = 9          # setting: a press counts only after a release
STALE_CYCLES = 10         # setting
HAS_BOX = 11              # setting: a workspace face is finite
FLAG_SLOTS = 12

# slots of ``values``
FAULT_VALUE = 0
MU_PREVIOUS = 1
INFO = 2                  # 2 slots: value and index of the first failed feedback check
FEEDBACK_LIMITS = 4       # 3 slots: following error [rad], force [N], torque [N·m]
MU_STOP = 7
SCALE_SPAN = 8            # slow − stop manipulability
MIN_SCALE = 9
TRACKING_LIMIT = 10
WORKSPACE_MARGIN = 11
MAX_LINEAR_ACCELERATION = 12
BOX_LOW = 13              # 3 slots [m]
BOX_HIGH = 16             # 3 slots [m]
VALUE_SLOTS = 19

# rows of ``joints``: middle of the range, half range + tolerance, current bound (the layout
# of kernels.feedback_fault), then the joint-limit margins of the motion check
MIDDLE, HALF_RANGE, MAX_CURRENT, LOWER_MARGIN, UPPER_MARGIN = range(5)
JOINT_ROWS = 5

# columns of ``events``
EVENT_T, EVENT_FROM, EVENT_TO, EVENT_CAUSE, EVENT_FAULT, EVENT_VALUE, EVENT_INDEX = range(7)
EVENT_COLUMNS = 7


@njit(cache=True, nogil=True)
def transition(flags: IntArray, events: Array, t: float, to: int, cause: int, fault: int,
               value: float, index: int) -> None:
    """Log a transition in the ring and enter state ``to``."""
    row = events[flags[EVENT_COUNT] % events.shape[0]]
    row[EVENT_T], row[EVENT_FROM], row[EVENT_TO] = t, flags[STATE], to
    row[EVENT_CAUSE], row[EVENT_FAULT] = cause, fault
    row[EVENT_VALUE], row[EVENT_INDEX] = value, index
    flags[EVENT_COUNT] += 1
    flags[STATE] = to


@njit(cache=True, nogil=True)
def _restart(flags: IntArray, values: Array) -> None:
    flags[ARMED] = 1 - flags[REQUIRE_EDGE]
    flags[HAS_SEQUENCE] = 0
    flags[MISSED] = 0
    values[MU_PREVIOUS] = math.nan


@njit(cache=True, nogil=True)
def _clear(flags: IntArray, values: Array) -> None:
    flags[FAULT_CODE], flags[FAULT_INDEX] = F_NONE, -1
    values[FAULT_VALUE] = math.nan


@njit(cache=True, nogil=True)
def reset(flags: IntArray, values: Array, events: Array, t: float) -> None:
    """Back to IDLE, fault cleared, counters restarted (logged as RESET)."""
    _clear(flags, values)
    _restart(flags, values)
    transition(flags, events, t, IDLE, C_RESET, F_NONE, math.nan, -1)


@njit(cache=True, nogil=True)
def trip(flags: IntArray, values: Array, events: Array, t: float, fault: int, value: float,
         index: int) -> None:
    """Enter FAULT (no-op if already there: the first fault is kept)."""
    if flags[STATE] == FAULT:
        return
    flags[FAULT_CODE], flags[FAULT_INDEX] = fault, index
    values[FAULT_VALUE] = value
    transition(flags, events, t, FAULT, C_FAULT, fault, value, index)


@njit(cache=True, nogil=True)
def clear_fault(flags: IntArray, values: Array, events: Array, t: float, at_rest: bool) -> bool:
    """FAULT → IDLE, only at rest; returns whether the fault was cleared."""
    if flags[STATE] != FAULT or not at_rest:
        return False
    _clear(flags, values)
    _restart(flags, values)
    transition(flags, events, t, IDLE, C_CLEARED, F_NONE, math.nan, -1)
    return True


@njit(cache=True, nogil=True)
def deadman(flags: IntArray, events: Array, t: float, held: bool) -> None:
    """IDLE → GUIDING on a press (once armed), GUIDING → STOPPING on a release; a release
    arms the next press."""
    state = flags[STATE]
    if state == IDLE and held:
        if flags[ARMED]:
            transition(flags, events, t, GUIDING, C_PRESSED, F_NONE, math.nan, -1)
        return
    if not held:
        flags[ARMED] = 1
        if state == GUIDING:
            transition(flags, events, t, STOPPING, C_RELEASED, F_NONE, math.nan, -1)


@njit(cache=True, nogil=True)
def stopped(flags: IntArray, events: Array, t: float, at_rest: bool) -> None:
    """STOPPING → IDLE once the commanded motion is at rest."""
    if flags[STATE] == STOPPING and at_rest:
        transition(flags, events, t, IDLE, C_STOPPED, F_NONE, math.nan, -1)


@njit(cache=True, nogil=True)
def check_feedback(flags: IntArray, values: Array, joints: Array, events: Array, t: float,
                   sequence: int, q: Array, current: Array, wrench: Array,
                   q_commanded: Array) -> None:
    """Input faults, in order: non-finite (or wrong size), stale, position and current range,
    following error, collision (see :meth:`SafetySupervisor.check_feedback
    <leadthrough.control.safety.SafetySupervisor.check_feedback>`)."""
    info = values[INFO:INFO + 2]
    code = kernels.feedback_fault(q, current, wrench, q_commanded, joints[:MAX_CURRENT + 1],
                                  values[FEEDBACK_LIMITS:FEEDBACK_LIMITS + 3], info)
    finite = math.isfinite(t) and code != kernels.FEEDBACK_NONFINITE
    flags[INPUTS_FINITE] = 1 if finite else 0
    if flags[STATE] == FAULT:
        return
    if not finite:
        trip(flags, values, events, t, F_NONFINITE, math.nan, -1)
        return
    if flags[HAS_SEQUENCE] and sequence <= flags[LAST_SEQUENCE]:
        flags[MISSED] += 1
        if flags[MISSED] >= flags[STALE_CYCLES]:
            trip(flags, values, events, t, F_STALE, float(sequence), -1)
            return
    else:
        flags[MISSED] = 0
        flags[LAST_SEQUENCE] = sequence
        flags[HAS_SEQUENCE] = 1
    if code == kernels.FEEDBACK_OK:
        return
    if code == kernels.FEEDBACK_POSITION:
        fault = F_POSITION
    elif code == kernels.FEEDBACK_CURRENT:
        fault = F_CURRENT
    elif code == kernels.FEEDBACK_FOLLOWING:
        fault = F_FOLLOWING
    else:
        fault = F_COLLISION
    trip(flags, values, events, t, fault, info[0], int(info[1]))


@njit(cache=True, nogil=True)
def check_motion(flags: IntArray, values: Array, joints: Array, events: Array, t: float,
                 manipulability: float, q_commanded: Array, qd_commanded: Array,
                 residual: float) -> None:
    """Motion faults, in order: singularity (μ below the stop threshold and falling), a joint
    at its margin and moving toward it, the IK residual."""
    mu_previous = values[MU_PREVIOUS]
    values[MU_PREVIOUS] = manipulability
    if flags[STATE] == FAULT:
        return
    if manipulability < values[MU_STOP] and manipulability < mu_previous:
        trip(flags, values, events, t, F_SINGULARITY, manipulability, -1)
        return
    j = kernels.joint_limit_index(q_commanded, qd_commanded, joints[LOWER_MARGIN],
                                  joints[UPPER_MARGIN])
    if j >= 0:
        trip(flags, values, events, t, F_JOINT_LIMIT, q_commanded[j], j)
        return
    if residual > values[TRACKING_LIMIT]:
        trip(flags, values, events, t, F_TRACKING, residual, -1)


@njit(cache=True, nogil=True)
def speed_scale(values: Array, manipulability: float) -> float:
    """(μ − μ_stop)/(μ_slow − μ_stop), clipped to [min_speed_scale, 1]."""
    s = (manipulability - values[MU_STOP]) / values[SCALE_SPAN]
    return min(1.0, max(values[MIN_SCALE], s))


@njit(cache=True, nogil=True)
def workspace_clearance(flags: IntArray, values: Array, position: Array, linear_speed: float,
                        stop_time: float) -> float:
    """min over the box's faces of (distance) − margin − braking distance [m]; +inf without a
    box. The braking distance is ½·‖v‖·max(‖v‖/a_max, ``stop_time``)
    (:meth:`~leadthrough.control.limits.CartesianLimits.braking_distance`)."""
    if not flags[HAS_BOX]:
        return math.inf
    c = math.inf
    for i in range(3):
        p = position[i]
        c = min(c, p - values[BOX_LOW + i], values[BOX_HIGH + i] - p)
    braking = 0.5 * linear_speed * max(linear_speed / values[MAX_LINEAR_ACCELERATION],
                                       stop_time)
    return c - values[WORKSPACE_MARGIN] - braking


def safety_size(n: int, events: int) -> int:
    """Length of the supervisor's buffer for ``n`` joints and a ring of ``events``."""
    return VALUE_SLOTS + JOINT_ROWS * n + EVENT_COLUMNS * events


@njit(cache=True, nogil=True)
def safety_views(buffer: Array, n: int) -> tuple[Array, Array, Array]:
    """``values``, ``joints`` and ``events`` of the supervisor's buffer."""
    events_at = VALUE_SLOTS + JOINT_ROWS * n
    capacity = (buffer.size - events_at) // EVENT_COLUMNS
    return (buffer[:VALUE_SLOTS],
            buffer[VALUE_SLOTS:events_at].reshape((JOINT_ROWS, n)),
            buffer[events_at:events_at + EVENT_COLUMNS * capacity].reshape(
                (capacity, EVENT_COLUMNS)))
