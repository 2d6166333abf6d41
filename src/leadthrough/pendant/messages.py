"""What the pendant and the loop's process say to each other: the operator's requests, the
loop's snapshot with its notices and marks, the servo periods' timing, and the snapshot's
encoding in shared memory (:class:`~leadthrough.pendant.shared_state.SeqlockRecord`).

A snapshot is encoded in two parts: the numbers that change every controller cycle (time,
joint positions, the TCP pose, wrench, twist, state, fault, estimator status, enabling input,
the simulated hand's force) in a fixed float64 array, and the rest (the transition's cause,
the settings in force, marks, notices, the controller's transition log, an error), pickled and
rewritten only when one of them changes.
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import Event, Fault, State
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.labels import LabelError, check_label

__all__ = ["LEASE_S", "MAX_SETTING", "Adjust", "ClearFault", "LoopSnapshot", "MarkPoint",
           "MarkedPoint", "Notice", "PeriodTimes", "Request", "RequestError", "SetEnable",
           "SimulatorRequest", "SlowState", "Stop", "check_finite", "check_request",
           "check_vector",
           "decode_snapshot", "fit_slow", "numbers_size", "snapshot_numbers"]

Array = NDArray[np.float64]

#: How long one heartbeat of the page's hold-to-run enabling device keeps it held [s]: the
#: loop releases the input itself once a lease has lapsed (:class:`SetEnable`).
LEASE_S = 0.2
#: The largest virtual mass or friction a request may carry (the controller clamps to its
#: operator limits further) [kg, kg·m², N, N·m].
MAX_SETTING = 1e6


class RequestError(ControlError):
    """A request to the loop is malformed (wrong type, a number not finite or out of range,
    a label outside the label charset): refused, nothing applied."""


@dataclass(frozen=True)
class SetEnable:
    """The enabling input (deadman): held or released.

    Attributes:
        held: Held (True) or released.
        until: When the hold lapses (``time.monotonic()`` of the pendant's machine [s]; a
            lease, renewed by each heartbeat of a hold-to-run device): the loop releases the
            input at its first controller cycle after it, whatever the pendant does. None:
            held until released (a caller of the loop's own interface).
    """

    held: bool
    until: float | None = None


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


@dataclass(frozen=True)
class SimulatorRequest:
    """A request to the simulated plant (the mouse's push, a fault to practise on); refused
    on a robot. Its kinds are defined with the simulator's parts
    (:mod:`~leadthrough.pendant.push`, :mod:`~leadthrough.pendant.simulated`)."""

    def check(self) -> None:
        """Raise :class:`RequestError` if a field is malformed (a kind with fields checks
        them)."""


@dataclass(frozen=True)
class Stop:
    """End the loop: release the enabling input, come to rest, exit (the pendant's own)."""


#: What the interface may ask of the loop.
Request = SetEnable | ClearFault | MarkPoint | Adjust | SimulatorRequest


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float | np.floating | np.integer) and not isinstance(
        value, bool | np.bool_)


def check_finite(value: Any, field: str, *, low: float = -math.inf, high: float = math.inf,
                 low_open: bool = False) -> float:
    """``value`` as a float if it is a real number, finite and within [low, high] (``low``
    excluded if ``low_open``), else a :class:`RequestError` naming ``field``."""
    ok = _is_number(value) and math.isfinite(float(value))
    if ok:
        v = float(value)
        ok = (v > low if low_open else v >= low) and v <= high
    if not ok:
        shown = value if not isinstance(value, str) or len(value) <= 40 else value[:40] + "..."
        raise RequestError("not a finite number in range", source="pendant", field=field,
                           value=shown, expected=f"a number in {'(' if low_open else '['}"
                                                 f"{low:g}, {high:g}]")
    return float(value)


def check_vector(value: Any, field: str, size: int, *, bound: float) -> tuple[float, ...]:
    """``value`` as ``size`` finite floats within ±``bound``, else a :class:`RequestError`."""
    if not isinstance(value, tuple | list | np.ndarray) or len(value) != size:
        raise RequestError(f"not {size} numbers", source="pendant", field=field,
                           value=type(value).__name__, expected=f"{size} finite numbers")
    return tuple(check_finite(v, f"{field}[{k}]", low=-bound, high=bound)
                 for k, v in enumerate(value))


def check_request(request: Any) -> None:
    """Check a request before it is sent and again where the loop applies it: types, finite
    numbers, ranges, labels (:func:`leadthrough.labels.check_label`).

    Raises:
        RequestError: naming the field, the value and what is accepted; nothing is applied.
    """
    if isinstance(request, SetEnable):
        if not isinstance(request.held, bool | np.bool_):
            raise RequestError("held must be true or false", source="pendant", field="held",
                               value=type(request.held).__name__, expected="a bool")
        if request.until is not None:
            check_finite(request.until, "until")
    elif isinstance(request, MarkPoint):
        try:
            check_label(request.label, source="pendant", field="label")
        except LabelError as e:   # the same words, as a refused request
            raise RequestError(e.message, source=e.source, field=e.field, value=e.value,
                               expected=e.expected) from e
    elif isinstance(request, Adjust):
        _check_adjust(request)
    elif isinstance(request, SimulatorRequest):
        request.check()
    elif not isinstance(request, ClearFault | Stop):
        raise RequestError("unknown request", source="pendant", field="request",
                           value=type(request).__name__, expected="a pendant request")


def _check_adjust(req: Adjust) -> None:
    if req.frame is not None and req.frame not in ("base", "tool"):
        shown = req.frame if not isinstance(req.frame, str) else req.frame[:40]
        raise RequestError("unknown frame", source="pendant", field="frame", value=shown,
                           expected="'base' or 'tool'")
    if req.axes_enabled is not None and (
            not isinstance(req.axes_enabled, tuple) or len(req.axes_enabled) != 6
            or not all(isinstance(a, bool) for a in req.axes_enabled)):
        raise RequestError("axes must be six true/false values", source="pendant",
                           field="axes_enabled", value=type(req.axes_enabled).__name__,
                           expected="a tuple of 6 bools")
    for name, pair, low_open in (("mass", req.mass, True), ("friction", req.friction, False)):
        if pair is None:
            continue
        if not isinstance(pair, tuple) or len(pair) != 2:
            raise RequestError("not a pair of numbers", source="pendant", field=name,
                               value=type(pair).__name__,
                               expected="(translational, rotational)")
        for k, v in enumerate(pair):
            check_finite(v, f"{name}[{k}]", low=0.0, high=MAX_SETTING, low_open=low_open)


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
