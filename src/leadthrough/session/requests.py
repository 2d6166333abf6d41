"""Requests into a running guiding loop, from any thread (a pendant, a UI, a signal handler).

    requests = LoopRequests()
    thread = threading.Thread(target=run_session, args=(...), kwargs={"requests": requests})
    thread.start()
    ...
    snap = requests.snapshot()          # the loop's latest state (never blocks the loop)
    requests.mark("P1")                 # a "mark point", at the loop's next servo period
    requests.set_virtual_mass([100, 100, 100, 1000, 1000, 1000])
    requests.stop()                     # a commanded stop, then the loop returns

Every method returns at once. The loop takes the requests at its next servo period, in the
order they were made; :attr:`LoopRequests.stop` and :meth:`LoopRequests.set_enable` are flags
it reads every period. Requests that change how the robot is guided (frame, axes, virtual mass
and friction) wait until the commanded motion is at rest, so that the law's state never changes
under a moving robot; the loop refuses those outside the session's safe range and says why in
the snapshot's ``notice`` and the recording's events. A fault reset (:meth:`reset_fault`) is
accepted at rest, with the controller reporting OK and the robot within the following-error
limit of its command; the estimator then re-tares and guiding needs a fresh press.

The arguments are checked here, in the caller's thread (a :class:`~leadthrough.errors.ControlError`
names the field and the range): the loop only sees well-formed requests. At most
:data:`MAX_PENDING` requests wait at a time.

Thread safety: the queue is a :class:`collections.deque` (``append`` and ``popleft`` are atomic
in CPython) whose producers share a lock; the loop's side takes no lock. The snapshot side is
:class:`~leadthrough.session.snapshot.SnapshotBoard` (a sequence lock the loop never waits on).
"""

from __future__ import annotations

import math
import signal
import threading
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from enum import StrEnum
from types import FrameType
from typing import Any, NamedTuple

from leadthrough.control.guiding_types import AXIS_NAMES
from leadthrough.errors import ControlError
from leadthrough.session.snapshot import LoopSnapshot, SnapshotBoard

__all__ = ["MASS_RANGE", "MAX_PENDING", "LoopRequests", "Request", "RequestKind"]

#: Requests that may wait at once (a caller beyond it gets a ControlError).
MAX_PENDING = 64
#: Virtual masses a request may set, per axis x, y, z [kg], ωx, ωy, ωz [kg·m²]: (lowest,
#: highest). The Cartesian speed and acceleration limits bound the motion at any mass; below
#: these the robot follows the estimate's noise.
MASS_RANGE: tuple[tuple[float, ...], tuple[float, ...]] = ((20.0,) * 3 + (2.0,) * 3,
                                                           (1e4,) * 6)
#: Longest mark label [characters].
MAX_LABEL = 32


class RequestKind(StrEnum):
    """What a queued request asks of the loop."""

    RESET_FAULT = "reset_fault"
    MARK = "mark"
    SET_FRAME = "set_frame"
    SET_AXES = "set_axes"
    SET_MASS = "set_virtual_mass"
    SET_FRICTION = "set_virtual_friction"


class Request(NamedTuple):
    """One queued request.

    Attributes:
        kind: What it asks.
        value: Its argument: the label (``MARK``, None: the next ``P<k>``), the frame name,
            the 6 axis flags, the 6 masses, or the friction and stopping friction (6 each, the
            latter None to keep it); None for ``RESET_FAULT``.
    """

    kind: RequestKind
    value: Any


def _six(values: Sequence[float], name: str, low: Sequence[float], high: Sequence[float],
         unit: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError) as e:
        raise ControlError("not 6 numbers", field=name, value=values,
                           expected=f"6 values ({', '.join(AXIS_NAMES)}) [{unit}]") from e
    ok = len(out) == 6 and all(math.isfinite(v) and lo <= v <= hi
                               for v, lo, hi in zip(out, low, high, strict=False))
    if not ok:
        raise ControlError("out of range", field=name, value=values,
                           expected=f"6 values ({', '.join(AXIS_NAMES)}) within "
                                    f"{tuple(low)} .. {tuple(high)} [{unit}]")
    return out


class LoopRequests:
    """The request channel into a running loop, and its published snapshot (see the module
    doc). Pass it to :func:`~leadthrough.session.loop.run_session` (``requests=``); one
    channel serves one session."""

    def __init__(self) -> None:
        self._queue: deque[Request] = deque()
        self._lock = threading.Lock()
        self._stop = False
        self._enable = False
        #: What the loop publishes (read it with :meth:`snapshot`).
        self.board = SnapshotBoard()

    # ------------------------------------------------------------------ any thread
    def stop(self) -> None:
        """End the session: a commanded stop at the acceleration limit, then the loop returns.
        """
        self._stop = True

    def reset_fault(self) -> None:
        """Clear a latched fault and re-arm (see the module doc for when it is accepted)."""
        self._put(RequestKind.RESET_FAULT, None)

    def mark(self, label: str | None = None) -> None:
        """Mark the current point (a ``mark`` event at the loop's time).

        Args:
            label: Its name (``"P1"``); None: ``P<k>`` for the k-th mark of the session.

        Raises:
            ControlError: An empty, over-long or multi-line label.
        """
        if label is not None and not (isinstance(label, str) and 0 < len(label) <= MAX_LABEL
                                      and label.isprintable()):
            raise ControlError("bad mark label", field="label", value=label,
                               expected=f"None or 1..{MAX_LABEL} printable characters")
        self._put(RequestKind.MARK, label)

    def set_frame(self, frame: str) -> None:
        """Guide in the base or the tool frame (at rest).

        Raises:
            ControlError: Not ``"base"`` or ``"tool"``.
        """
        if frame not in ("base", "tool"):
            raise ControlError("unknown frame", field="frame", value=frame,
                               expected="'base' or 'tool'")
        self._put(RequestKind.SET_FRAME, frame)

    def set_axes(self, axes_enabled: Sequence[bool]) -> None:
        """Which axes (x, y, z, ωx, ωy, ωz of the frame) the operator can move (at rest).

        Raises:
            ControlError: Not 6 booleans, or none enabled.
        """
        axes = tuple(axes_enabled)
        if len(axes) != 6 or not all(isinstance(a, bool) for a in axes) or not any(axes):
            raise ControlError("bad axes", field="axes_enabled", value=axes_enabled,
                               expected="6 booleans (x, y, z, rx, ry, rz), at least one True")
        self._put(RequestKind.SET_AXES, axes)

    def set_virtual_mass(self, mass: Sequence[float]) -> None:
        """The virtual mass M per axis (at rest; virtual-friction law).

        Raises:
            ControlError: Not 6 values within :data:`MASS_RANGE`.
        """
        self._put(RequestKind.SET_MASS, _six(mass, "mass", *MASS_RANGE, "kg, kg·m²"))

    def set_virtual_friction(self, friction: Sequence[float],
                             stopping_friction: Sequence[float] | None = None) -> None:
        """The virtual friction δ (and stopping friction δ_s) per axis (at rest; fixed friction
        only). The loop accepts values from the session's configured friction (its floor: the
        estimate's noise must not move the robot) up to half the collision thresholds.

        Raises:
            ControlError: Not 6 finite values >= 0, or a stopping friction below the friction.
        """
        inf = (math.inf,) * 6
        f = _six(friction, "friction", (0.0,) * 6, inf, "N, N·m")
        s = None if stopping_friction is None else _six(stopping_friction, "stopping_friction",
                                                        f, inf, "N, N·m")
        self._put(RequestKind.SET_FRICTION, (f, s))

    def set_enable(self, held: bool) -> None:
        """The enabling device of a page or UI, for a simulated robot only (the loop refuses a
        software enabling device on a real one: ``LoopOptions.software_enable``)."""
        self._enable = bool(held)

    def snapshot(self) -> LoopSnapshot | None:
        """The loop's latest published state (None before the loop has started)."""
        return self.board.read()

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
    def enable_held(self) -> bool:
        """The level set by :meth:`set_enable`."""
        return self._enable

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
