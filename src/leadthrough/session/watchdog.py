"""The loop's watchdog on its driver: a driver call (``write``, ``step``, ``read``) that blocks.

The loop times every exchange with its driver. One that returns late is caught by the loop
itself, as a fault (``Fault.DRIVER_TIMEOUT``) followed by a commanded stop. One that never
returns cannot be: the loop's thread is stuck inside it. :class:`DriverWatchdog` is a thread that
looks at the exchange in progress every quarter of the timeout; past the timeout it logs the
stall at once, and past ``abort_s`` (the link is taken as gone: a controller whose cycle is
milliseconds has long stopped the robot by itself) it calls the driver's ``abort()`` if it has
one (see :mod:`leadthrough.drivers.protocol`; every streaming driver has one:
:meth:`~leadthrough.drivers.streaming.StreamingDriver.abort`), which makes the blocked call
return by raising; the loop then ends without further servo targets, and its end closes the
driver (:func:`~leadthrough.session.loop.stop_driver`), which sends the protocol's stop (RSI's
``Stop`` answer, the UR program's stop mode, J519's stop packet) unless the socket itself is
broken: a commanded stop, not the controller's own watchdog.
An exchange that returns between the two is a ``Fault.DRIVER_TIMEOUT`` and the loop commands
its stop.

The loop's side is two attribute writes per period (:meth:`enter`, :meth:`leave`): no lock, no
allocation.

The thread runs on a stack of :data:`STACK_BYTES` instead of the C library's default (8 MiB on
glibc): with the memory locked (``guide --lock-memory``: ``mlockall(MCL_FUTURE)``) a new
thread's whole stack is faulted in when it starts, which took 3.4-5.0 ms for the default and
0.3 ms for 256 KiB on the CI machine's kind (two cores): a late RSI answer at the session's
start. The PREEMPT_RT project's "HOWTO build a simple RT application" (application_base) asks
for the same: threads created, with their stacks, before the real-time work.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable

__all__ = ["STACK_BYTES", "DriverWatchdog"]

log = logging.getLogger("leadthrough.session")

#: The watchdog thread's stack [bytes] (module doc): it logs and calls the driver's ``abort``.
STACK_BYTES = 256 * 1024


class DriverWatchdog:
    """Watches the loop's driver exchanges from a thread (see the module doc).

    Args:
        timeout_s: An exchange longer than this is a stall (logged) [s].
        abort_s: A stall longer than this is aborted [s] (>= ``timeout_s``).
        abort: Called once per stall past ``abort_s``, from the watchdog's thread (the
            driver's ``abort``), or None.

    Attributes:
        started_at: ``time.monotonic()`` when the exchange in progress began (inf: none).
        fired: The watchdog aborted the exchange in progress (reset by :meth:`enter`).
    """

    def __init__(self, timeout_s: float, abort_s: float,
                 abort: Callable[[], None] | None) -> None:
        self.timeout_s, self.abort_s = timeout_s, max(abort_s, timeout_s)
        self._abort = abort
        self.started_at = math.inf
        self.fired = False
        self._logged = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="leadthrough-watchdog",
                                        daemon=True)

    def start(self) -> None:
        """Start the thread, on a stack of :data:`STACK_BYTES`. The interpreter's setting for
        new threads is process-wide: it is put back as soon as the thread has started (a
        thread that another thread starts meanwhile gets the small stack too); a platform
        that refuses the size gives the thread its default stack, logged. It watches from the
        first :meth:`enter` on.

        Raises:
            RuntimeError: The thread could not be started.
        """
        default: int | None = None
        try:
            default = threading.stack_size(STACK_BYTES)
        except (ValueError, RuntimeError) as e:
            log.warning("the watchdog's thread starts on the default stack (%s)", e)
        try:
            self._thread.start()
        finally:
            if default is not None:
                threading.stack_size(default)

    def stop(self) -> None:
        """Stop watching (joins the thread)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()

    def enter(self) -> None:
        """An exchange begins now (the wall clock's: the watchdog watches real time, whatever
        clock the loop reads)."""
        self.fired = self._logged = False
        self.started_at = time.monotonic()

    def leave(self) -> None:
        """The exchange is over."""
        self.started_at = math.inf

    def _watch(self) -> None:
        period = self.timeout_s / 4.0
        while not self._stop.wait(period):
            started = self.started_at
            blocked = time.monotonic() - started
            if started != self.started_at or self.fired:
                continue
            if blocked > self.timeout_s and not self._logged:
                self._logged = True
                log.error("driver call blocked for %.3f s (watchdog %.3f s)", blocked,
                          self.timeout_s)
            if blocked > self.abort_s:
                self.fired = True
                log.error("driver call blocked for %.3f s (abort after %.3f s)%s", blocked,
                          self.abort_s, ": aborting it" if self._abort else "")
                if self._abort is not None:
                    try:
                        self._abort()
                    except Exception:
                        log.exception("the driver's abort() raised")
