"""The operator's requests to a running guiding loop, in one vocabulary, and what the loop
gives back (marks, notices).

The vocabulary: :class:`SetEnable` (the enabling device, held or released, with an optional
lease), :class:`ClearFault`, :class:`MarkPoint`, :class:`Adjust` (frame, axes, virtual mass and
friction), :class:`SimulatorRequest` (the simulated plant's own) and :class:`Stop`. Every one is
checked by :func:`check_request` before it is sent and again where the loop serves it
(:meth:`ServoLoop.serve <leadthrough.session.servo_loop.ServoLoop.serve>`, the one handler).

Two channels carry them, and the loop reads both the same way (:class:`RequestSource`,
``poll()`` once per servo period, never waiting):

* **within a process**, :class:`LoopRequests`: a queue any thread (a signal handler, a UI)
  writes into::

      requests = LoopRequests()
      thread = threading.Thread(target=run_session, args=(...), kwargs={"requests": requests})
      thread.start()
      ...
      requests.reset_fault()              # clear a latched fault, at the loop's next period
      requests.stop()                     # a commanded stop, then the loop returns

  Every method returns at once; the loop takes the requests in the order they were made, at
  most :data:`MAX_PENDING` wait at a time. :meth:`LoopRequests.stop` is a flag (it must work
  from a signal handler and with the queue full). Thread safety: the queue is a
  :class:`collections.deque` (``append`` and ``popleft`` are atomic in CPython) whose producers
  share a lock; the loop's side takes no lock.
* **between processes**, :class:`PipeRequests`: the loop's end of a ``multiprocessing`` pipe
  (the pendant's). A message that does not unpickle is refused and counted, never raised; a
  closed pipe, or a parent process gone, is :class:`OperatorLost`: the enabling device is
  released (the controller's commanded stop) and the loop ends at rest.

A fault reset (:class:`ClearFault`) is accepted at rest, with the controller reporting OK and
the robot within the following-error limit of its command (:meth:`ServoLoop.reset_fault
<leadthrough.session.servo_loop.ServoLoop.reset_fault>`); the estimator then re-tares and
guiding needs a fresh press.
"""

from __future__ import annotations

import math
import os
import signal
import threading
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.connection import Connection
from types import FrameType
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import ControlError
from leadthrough.labels import LabelError, check_label

__all__ = ["LEASE_S", "MAX_PENDING", "MAX_SETTING", "Adjust", "ClearFault", "LoopRequests",
           "MarkPoint", "MarkedPoint", "Notice", "OperatorLost", "PipeRequests", "Refused",
           "Request", "RequestError", "RequestSource", "SetEnable", "SimulatorRequest", "Stop",
           "check_finite", "check_request", "check_vector"]

Array = NDArray[np.float64]

#: Requests that may wait at once in a :class:`LoopRequests` (a caller beyond it gets a
#: ControlError).
MAX_PENDING = 64

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
    """End the loop: release the enabling device, come to rest, end."""


@dataclass(frozen=True)
class OperatorLost:
    """The channel to the operator closed, or the operator's process is gone (made by a
    :class:`RequestSource`, never sent): the enabling device is released and the loop ends at
    rest.

    Attributes:
        why: In words.
    """

    why: str


@dataclass(frozen=True)
class Refused:
    """A message that could not be read as a request (made by a :class:`RequestSource`): the
    loop counts it and tells the operator.

    Attributes:
        what: What it was.
        why: Why it was refused.
    """

    what: str
    why: str


#: What an operator may ask of the loop.
Request = SetEnable | ClearFault | MarkPoint | Adjust | SimulatorRequest | Stop


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

class RequestSource(Protocol):
    """Where the loop's requests come from (read by the loop's thread only)."""

    @property
    def stop_requested(self) -> bool:
        """A stop was asked for (read every period)."""
        ...

    def poll(self) -> object | None:
        """The next request, or None if none waits (never waits)."""
        ...


class LoopRequests:
    """The request channel into a running loop from another thread of its process (see the
    module doc). Pass it to :func:`~leadthrough.session.loop.run_session` (``requests=``); one
    channel serves one session."""

    def __init__(self) -> None:
        self._queue: deque[object] = deque()
        self._lock = threading.Lock()
        self._stop = False

    # ------------------------------------------------------------------ any thread
    def stop(self) -> None:
        """End the session: a commanded stop at the acceleration limit, then the loop returns.
        """
        self._stop = True

    def reset_fault(self) -> None:
        """Clear a latched fault and re-arm (see the module doc for when it is accepted).

        Raises:
            ControlError: :data:`MAX_PENDING` requests already wait (the loop is not running).
        """
        self.send(ClearFault())

    def send(self, request: Request) -> None:
        """Queue any request (checked here, and again where the loop serves it).

        Raises:
            RequestError: The request is malformed (nothing queued).
            ControlError: :data:`MAX_PENDING` requests already wait (the loop is not running).
        """
        check_request(request)
        with self._lock:
            if len(self._queue) >= MAX_PENDING:
                raise ControlError("too many pending requests (is the loop running?)",
                                   field=type(request).__name__,
                                   expected=f"<= {MAX_PENDING} waiting")
            self._queue.append(request)

    @contextmanager
    def stop_on_interrupt(self) -> Iterator[None]:
        """Within the block, Ctrl-C (SIGINT) requests a stop instead of raising; a second Ctrl-C
        raises ``KeyboardInterrupt`` as usual. Main thread only (Python's signal rule)."""
        previous = signal.getsignal(signal.SIGINT)

        def handler(signum: int, frame: FrameType | None) -> None:
            if self._stop:
                signal.signal(signal.SIGINT, signal.default_int_handler)
                raise KeyboardInterrupt
            self.stop()

        signal.signal(signal.SIGINT, handler)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    # ------------------------------------------------------------------ the loop's side
    @property
    def stop_requested(self) -> bool:
        """:meth:`stop` was called."""
        return self._stop

    @property
    def pending(self) -> bool:
        """A queued request waits."""
        return bool(self._queue)

    def poll(self) -> object | None:
        """The oldest queued request, removed (None: none waits)."""
        try:
            return self._queue.popleft()
        except IndexError:
            return None


class PipeRequests:
    """The loop's end of the pipe from another process (the pendant's; see the module doc).

    Args:
        conn: The pipe's end in the loop's process.
        parent_pid: The process whose end is lost if it is gone (checked by
            :meth:`poll`, ``os.getppid()``); None: not checked.
    """

    def __init__(self, conn: Connection, parent_pid: int | None = None) -> None:
        self.conn, self.parent_pid = conn, parent_pid
        self._open = True
        self._stop = False

    @property
    def stop_requested(self) -> bool:
        """A :class:`Stop` came (the loop also serves it as a request)."""
        return self._stop

    def poll(self) -> object | None:
        """The next message, :class:`Refused` if it does not unpickle, :class:`OperatorLost`
        once when the pipe closes or the parent is gone, then None for ever."""
        if not self._open:
            return None
        if self.parent_pid is not None and os.getppid() != self.parent_pid:
            return self._lost("the pendant's process ended")
        try:
            if not self.conn.poll():
                return None
            message = self.conn.recv()
        except (EOFError, OSError):
            return self._lost("the pendant's link closed")
        except Exception as e:      # a message that does not unpickle
            return Refused("a message", f"{type(e).__name__}: {e}")
        if isinstance(message, Stop):
            self._stop = True
        return message

    def _lost(self, why: str) -> OperatorLost:
        self._open = False
        return OperatorLost(why)
