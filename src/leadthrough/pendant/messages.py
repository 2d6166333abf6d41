"""What the pendant and the loop's process say to each other: the operator's requests (the
loop's own vocabulary, :mod:`leadthrough.session.requests`, re-exported here), the loop's
snapshot with its notices and marks, the servo periods' timing, and the snapshot's encoding in
shared memory (:class:`~leadthrough.pendant.shared_state.SeqlockRecord`).

A snapshot is encoded in two parts: the numbers that change every controller cycle (time,
joint positions, the TCP pose, wrench, twist, state, fault, estimator status, enabling input,
the simulated hand's force) in a fixed float64 array, and the rest (the transition's cause,
the settings in force, marks, notices, the controller's transition log, an error), pickled and
rewritten only when one of them changes.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import Event, Fault, State
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.session.requests import (
    LEASE_S,
    MAX_SETTING,
    Adjust,
    ClearFault,
    MarkedPoint,
    MarkPoint,
    Notice,
    Request,
    RequestError,
    SetEnable,
    SimulatorRequest,
    Stop,
    check_finite,
    check_request,
    check_vector,
)

__all__ = ["LEASE_S", "MAX_SETTING", "Adjust", "ClearFault", "LoopSnapshot", "MarkPoint",
           "MarkedPoint", "Notice", "PeriodTimes", "Request", "RequestError", "SetEnable",
           "SimulatorRequest", "SlowState", "Stop", "check_finite", "check_request",
           "check_vector",
           "decode_snapshot", "fit_slow", "numbers_size", "snapshot_numbers"]

Array = NDArray[np.float64]

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
        push_base: The simulated hand's force on the tool [N], shape (3,) (zeros on a
            robot).
        refused: Requests the loop refused so far (malformed, or their effect failed).
        lapsed: Holds of the enabling input the loop dropped on a lapsed lease.
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
    push_base: Array = field(default_factory=lambda: np.zeros(3))
    refused: int = 0
    lapsed: int = 0

    @property
    def speed(self) -> float:
        """Commanded TCP speed ‖v‖ [m/s]."""
        return float(np.linalg.norm(self.twist_base[:3]))



@dataclass(frozen=True)
class SlowState:
    """The part of a snapshot that changes only now and then (pickled when it does).

    Attributes:
        cause: The last transition in words.
        settings: The controller's settings in force.
        marks: The points marked so far.
        notices: The latest notices.
        events: The controller's transition log (for the export).
        error: Why the loop stopped, if it did.
        refused: Requests refused so far.
        lapsed: Holds dropped on a lapsed lease so far.
    """

    cause: str = ""
    settings: GuidingConfig | None = None
    marks: tuple[MarkedPoint, ...] = ()
    notices: tuple[Notice, ...] = ()
    events: tuple[Event, ...] = ()
    error: str | None = None
    refused: int = 0
    lapsed: int = 0

    def encode(self) -> bytes:
        """Its pickle."""
        return pickle.dumps(self, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def decode(blob: bytes) -> SlowState:
        """The slow part from its pickle (written by the loop's process, which the pendant
        started itself: a trusted source)."""
        slow = pickle.loads(blob)
        if not isinstance(slow, SlowState):
            raise TypeError(f"not a snapshot's slow part: {type(slow).__name__}")
        return slow


def fit_slow(slow: SlowState, capacity: int) -> tuple[bytes, str | None]:
    """The pickle of ``slow`` in at most ``capacity`` bytes, and what was left out for it
    (None: nothing). Over capacity, the oldest transitions of the log are dropped first, then
    notices are shortened, then the oldest marks dropped: the loop keeps running whatever the
    snapshot has to carry.

    Raises:
        RequestError: ``capacity`` cannot hold even the settings and the error.
    """
    blob = slow.encode()
    if len(blob) <= capacity:
        return blob, None
    dropped: list[str] = []
    slow, blob, n = _drop_oldest(slow, "events", blob, capacity)
    if n:
        dropped.append(f"{n} oldest transitions")
    if len(blob) > capacity and slow.notices:
        slow = replace(slow, notices=tuple(replace(n, text=n.text[:200])
                                           for n in slow.notices[-5:]),
                       cause=slow.cause[:200],
                       error=None if slow.error is None else slow.error[:200])
        blob = slow.encode()
        dropped.append("notices shortened")
    slow, blob, n = _drop_oldest(slow, "marks", blob, capacity)
    if n:
        dropped.append(f"{n} oldest marks")
    if len(blob) > capacity:
        raise RequestError("the snapshot's record is too small for its settings",
                           field="blob_bytes", value=capacity, expected=f">= {len(blob)}")
    return blob, "the snapshot's record is full: " + ", ".join(dropped) + " left out of it"


def _drop_oldest(slow: SlowState, name: str, blob: bytes,
                 capacity: int) -> tuple[SlowState, bytes, int]:
    """Halve the oldest of ``slow``'s tuple ``name`` away (one more each time) until its
    encoding ``blob`` fits ``capacity`` or nothing is left; returns the state, its encoding and
    how many were dropped."""
    items: tuple[Any, ...] = getattr(slow, name)
    kept = items
    change: dict[str, Any] = {}
    while len(blob) > capacity and kept:
        kept = kept[len(kept) // 2 + 1:] if len(kept) > 1 else ()
        change[name] = kept
        blob = replace(slow, **change).encode()
    return replace(slow, **change), blob, len(items) - len(kept)


def numbers_size(n: int) -> int:
    """Numbers of a snapshot of ``n`` joints."""
    return 36 + n


def snapshot_numbers(out: Array, t: float, q: Array, transform: Array, wrench: Array,
                     twist: Array, status: tuple[int, int, int, bool], push: Array) -> None:
    """Write a snapshot's numbers into ``out`` (shape (36 + n,)); ``status``: state, fault,
    estimator status, enabling input."""
    n = q.shape[0]
    out[0] = t
    out[1:1 + n] = q
    out[1 + n:17 + n] = transform.ravel()
    out[17 + n:23 + n] = wrench
    out[23 + n:29 + n] = twist
    out[29 + n:33 + n] = status
    out[33 + n:36 + n] = push


def decode_snapshot(numbers: Array, slow: SlowState) -> LoopSnapshot:
    """The snapshot of these numbers (:func:`snapshot_numbers`) and slow part."""
    n = numbers.shape[0] - 36
    state, fault, estimator, enabled = (int(v) for v in numbers[29 + n:33 + n])
    assert slow.settings is not None, "a published snapshot carries its settings"
    return LoopSnapshot(
        time=float(numbers[0]), q=numbers[1:1 + n].copy(),
        transform_tool_to_base=numbers[1 + n:17 + n].reshape(4, 4).copy(),
        wrench_base=numbers[17 + n:23 + n].copy(), twist_base=numbers[23 + n:29 + n].copy(),
        state=State(state), fault=Fault(fault), cause=slow.cause,
        estimator=EstimatorStatus(estimator), enabled=bool(enabled), settings=slow.settings,
        marks=slow.marks, notices=slow.notices, error=slow.error,
        push_base=numbers[33 + n:36 + n].copy(), refused=slow.refused, lapsed=slow.lapsed)
