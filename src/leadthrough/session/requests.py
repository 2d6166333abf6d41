"""Requests into a running guiding loop, from any thread (a signal handler, a UI):

    requests = LoopRequests()
    thread = threading.Thread(target=run_session, args=(...), kwargs={"requests": requests})
    thread.start()
    ...
    requests.reset_fault()              # clear a latched fault, at the loop's next servo period
    requests.stop()                     # a commanded stop, then the loop returns

Every method returns at once. The loop takes the queued requests at its next servo period, in
the order they were made; :meth:`LoopRequests.stop` is a flag it reads every period. A fault
reset (:meth:`LoopRequests.reset_fault`) is accepted at rest, with the controller reporting OK
and the robot within the following-error limit of its command (the same rule as the reset
input's: :meth:`ServoLoop.reset_fault <leadthrough.session.servo_loop.ServoLoop.reset_fault>`);
the estimator then re-tares and guiding needs a fresh press. At most :data:`MAX_PENDING`
requests wait at a time.

Thread safety: the queue is a :class:`collections.deque` (``append`` and ``popleft`` are atomic
in CPython) whose producers share a lock; the loop's side takes no lock.
"""

from __future__ import annotations

import signal
import threading
from collections import deque
from collections.abc import Iterator
from contextlib import contextmanager
from enum import StrEnum
from types import FrameType
from typing import Any, NamedTuple

from leadthrough.errors import ControlError

__all__ = ["MAX_PENDING", "LoopRequests", "Request", "RequestKind"]

#: Requests that may wait at once (a caller beyond it gets a ControlError).
MAX_PENDING = 64


class RequestKind(StrEnum):
    """What a queued request asks of the loop."""

    RESET_FAULT = "reset_fault"


class Request(NamedTuple):
    """One queued request.

    Attributes:
        kind: What it asks.
        value: Its argument (None for ``RESET_FAULT``).
    """

    kind: RequestKind
    value: Any


class LoopRequests:
    """The request channel into a running loop (see the module doc). Pass it to
    :func:`~leadthrough.session.loop.run_session` (``requests=``); one channel serves one
    session."""

    def __init__(self) -> None:
        self._queue: deque[Request] = deque()
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
        self._put(RequestKind.RESET_FAULT, None)

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

    def _put(self, kind: RequestKind, value: Any) -> None:
        with self._lock:
            if len(self._queue) >= MAX_PENDING:
                raise ControlError("too many pending requests (is the loop running?)",
                                   field=str(kind), expected=f"<= {MAX_PENDING} waiting")
            self._queue.append(Request(kind, value))

    # ------------------------------------------------------------------ the loop's side
    @property
    def stop_requested(self) -> bool:
        """:meth:`stop` was called."""
        return self._stop

    @property
    def pending(self) -> bool:
        """A queued request waits."""
        return bool(self._queue)

    def take(self) -> Request | None:
        """The oldest queued request, removed (None: none waits)."""
        try:
            return self._queue.popleft()
        except IndexError:
            return None
