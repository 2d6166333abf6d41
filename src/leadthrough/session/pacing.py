"""The loop's servo periods against the wall clock: pacing without catch-up, and late periods.

A real driver paces the loop itself (its ``step`` waits for the controller's next cycle); a
simulated one runs flat out unless the loop is paced. :class:`PeriodClock` does both jobs:

* **Pacing** (a simulated driver, ``paced=True``): period k starts at the boundary
  ``t0 + k·dt``. A period that overruns its slot is *late*; the next one starts at the first
  boundary after its end, so the periods missed are skipped, never run back to back to catch up
  (a burst of commands in a few microseconds is what a servo must never see).
* **Late periods** (paced, or a real driver): a paced period is late when its work ends after
  the next boundary; a real driver's period when the work after its exchange (the estimator,
  the controller, recording: what stands between a sample and the reply to it) takes longer than
  a period, so the reply misses the controller's cycle.

Flat out, on a simulated driver, nothing is late: there is no clock to be late against.

**The clock.** Everything the loop times (pacing, late periods, compute times, stale feedback,
the exchange's watchdog timeout, the enabling device's lease) reads one :class:`Clock`: the
:class:`WallClock` (``time.monotonic``, which on Linux is ``CLOCK_MONOTONIC``, the clock of
another process's lease too) in a session, a :class:`VirtualClock` that a test advances
itself, so that the loop's logic is tested deterministically (a driver whose ``step``
advances the virtual clock scripts the controller's timing).
"""

from __future__ import annotations

import math
import time
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["Clock", "ComputeTimes", "PeriodClock", "VirtualClock", "WallClock"]


class Clock(Protocol):
    """What the loop reads the time from (see the module doc)."""

    def now(self) -> float:
        """The time [s] (a monotonic clock: only differences mean anything)."""
        ...

    def sleep_until(self, t: float) -> None:
        """Return at ``t`` [s] (at once if past)."""
        ...


class WallClock:
    """The machine's monotonic clock (``time.monotonic``)."""

    __slots__ = ()

    def now(self) -> float:
        """``time.monotonic()`` [s]."""
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        """Sleep until ``t`` [s] (at once if past)."""
        remaining = t - time.monotonic()
        if remaining > 0:
            time.sleep(remaining)


class VirtualClock:
    """A clock that moves only when told to (tests; see the module doc).

    Args:
        t: Its time at first [s].
    """

    __slots__ = ("t",)

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def now(self) -> float:
        """Its time [s]."""
        return self.t

    def sleep_until(self, t: float) -> None:
        """Its time moves on to ``t`` (never back)."""
        self.t = max(self.t, t)

    def advance(self, dt: float) -> None:
        """Its time moves on by ``dt`` [s] (>= 0)."""
        self.t += max(0.0, dt)


class PeriodClock:
    """Paces the periods and counts the late ones (see the module doc).

    Args:
        dt: Servo period [s].
        paced: Pace to the clock (a simulated driver).
        real_time: Count late periods (paced, or a real driver).
        clock: The time (default: the wall clock).

    Attributes:
        late: Late periods so far.
        skipped: Period slots skipped after late periods (paced only).
    """

    __slots__ = ("clock", "dt", "late", "next_start", "paced", "real_time", "skipped", "t0",
                 "work_start")

    def __init__(self, dt: float, paced: bool, real_time: bool,
                 clock: Clock | None = None) -> None:
        self.dt, self.paced, self.real_time = dt, paced, real_time or paced
        self.clock: Clock = clock if clock is not None else WallClock()
        self.late = self.skipped = 0
        self.t0 = self.next_start = self.work_start = math.nan

    def start(self) -> None:
        """The first period starts now."""
        self.t0 = self.next_start = self.clock.now()

    def wait(self) -> None:
        """Before a period's exchange: sleep until its start (paced)."""
        if self.paced:
            self.clock.sleep_until(self.next_start)

    def exchanged(self) -> None:
        """The period's exchange with the driver is over; its work starts."""
        if self.real_time:
            self.work_start = self.clock.now()

    def done(self) -> None:
        """The period's work is over: count it if late; set the next period's start."""
        if not self.real_time:
            return
        now = self.clock.now()
        if not self.paced:
            if now - self.work_start > self.dt:
                self.late += 1
            return
        end_of_slot = self.next_start + self.dt
        if now <= end_of_slot:
            self.next_start = end_of_slot
            return
        self.late += 1
        # the first boundary after now: the slots in between are skipped, not caught up
        slots = math.floor((now - self.t0) / self.dt) + 1
        following = self.t0 + slots * self.dt
        self.skipped += max(0, round((following - end_of_slot) / self.dt))
        self.next_start = following


class ComputeTimes:
    """The compute time of the last ``capacity`` servo periods, in a preallocated ring (memory
    stays bounded however long the session runs).

    Args:
        capacity: Periods kept (default: 10 min at 1 kHz, 4.8 MB).
    """

    __slots__ = ("count", "ring")

    def __init__(self, capacity: int = 600_000) -> None:
        self.ring = np.zeros(max(1, capacity))
        self.count = 0

    def add(self, us: float) -> None:
        """One period's compute time [µs]."""
        self.ring[self.count % self.ring.size] = us
        self.count += 1

    def split(self, every: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The kept periods' times [µs], oldest first: those of controller cycles (period
        index a multiple of ``every``) and the others."""
        size = self.ring.size
        idx = np.arange(max(0, self.count - size), self.count)
        times = self.ring[idx % size]
        cycle = idx % every == 0
        return times[cycle], times[~cycle]
