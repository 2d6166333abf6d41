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
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import NDArray

__all__ = ["ComputeTimes", "PeriodClock", "sleep_until"]


class PeriodClock:
    """Paces the periods and counts the late ones (see the module doc).

    Args:
        dt: Servo period [s].
        paced: Pace to the wall clock (a simulated driver).
        real_time: Count late periods (paced, or a real driver).

    Attributes:
        late: Late periods so far.
        skipped: Period slots skipped after late periods (paced only).
    """

    __slots__ = ("dt", "late", "next_start", "paced", "real_time", "skipped", "t0",
                 "work_start")

    def __init__(self, dt: float, paced: bool, real_time: bool) -> None:
        self.dt, self.paced, self.real_time = dt, paced, real_time or paced
        self.late = self.skipped = 0
        self.t0 = self.next_start = self.work_start = math.nan

    def start(self) -> None:
        """The first period starts now."""
        self.t0 = self.next_start = time.perf_counter()

    def wait(self) -> None:
        """Before a period's exchange: sleep until its start (paced)."""
        if self.paced:
            remaining = self.next_start - time.perf_counter()
            if remaining > 0:
                time.sleep(remaining)

    def exchanged(self) -> None:
        """The period's exchange with the driver is over; its work starts."""
        if self.real_time:
            self.work_start = time.perf_counter()

    def done(self) -> None:
        """The period's work is over: count it if late; set the next period's start."""
        if not self.real_time:
            return
        now = time.perf_counter()
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


def sleep_until(deadline: float) -> None:
    """Sleep until ``deadline`` (``time.perf_counter`` seconds), at once if past."""
    remaining = deadline - time.perf_counter()
    if remaining > 0:
        time.sleep(remaining)
