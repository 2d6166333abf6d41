"""The recording of a live session: the last minutes at the controller rate, for the export.

A live session has no end to size its arrays for, so it keeps a ring: one row per controller
cycle (10 ms), the same columns as a session file
(:class:`~leadthrough.session.record.SessionLog`), the oldest row overwritten once the ring is
full. The loop thread writes a row and then advances a counter; the interface reads the ring
without a lock: it reads the counter, copies the rows, reads the counter again, and keeps only
the rows that no write can have touched in between (a row being written, or overwritten while
the copy ran, is dropped). The loop never waits for a reader.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from leadthrough.control.guiding import GuidingController
from leadthrough.errors import TeachError
from leadthrough.session.loop import ServoPeriods, SessionBuffers, transition_event
from leadthrough.session.record import SessionEvent, SessionLog

__all__ = ["LiveRecording"]


class LiveRecording:
    """A ring of the last ``cycles`` controller cycles of a loop.

    Args:
        loop: The loop whose period state is recorded (its feedback, command, estimate and
            controller output).
        cycles: Rows kept.
        n: Number of joints.
        with_truth: Keep the simulator's applied wrench.
    """

    def __init__(self, loop: ServoPeriods, cycles: int, n: int, with_truth: bool) -> None:
        self._loop = loop
        self._rows = SessionBuffers(cycles, n, with_truth)
        self._n, self._with_truth = n, with_truth
        self.capacity = cycles
        #: Rows written so far (the next row's number); only the loop thread writes it.
        self.count = 0

    def store(self, t: float) -> None:
        """Record the loop's state of this period as the next row (loop thread only)."""
        self._loop.store(self._rows, self.count % self.capacity, t)
        self.count += 1

    def rows(self) -> tuple[SessionBuffers, int]:
        """A time-ordered copy of the complete rows, and the number of the first one."""
        first_asked = self.count          # read once: rows below it are complete
        lo = max(0, first_asked - self.capacity)
        idx = np.arange(lo, first_asked) % self.capacity
        copy = SessionBuffers(0, self._n, self._with_truth)
        for name, column in vars(self._rows).items():
            if column is not None:
                setattr(copy, name, np.take(column, idx, axis=0))
        written = self.count              # rows up to it may have overwritten the oldest
        drop = max(0, written + 1 - self.capacity - lo)
        if drop:
            for name, column in vars(copy).items():
                if column is not None:
                    setattr(copy, name, column[drop:])
        return copy, lo + drop

    def session_log(self, robot: str, controller: GuidingController,
                    marks: Sequence[tuple[float, str]],
                    settings: dict[str, object]) -> SessionLog:
        """The recording as a session, with the controller's transitions and ``marks``.

        Args:
            robot: Robot name.
            controller: The loop's controller (its transition log).
            marks: (time [s], label) of the operator's marks.
            settings: Recorded in the session.

        Raises:
            TeachError: Fewer than two rows recorded.
        """
        rows, _ = self.rows()
        if rows.time.shape[0] < 2:
            raise TeachError("nothing recorded yet", field="recording",
                             value=rows.time.shape[0], expected="at least 2 controller cycles")
        events = [transition_event(e) for e in controller.events]
        events += [SessionEvent(t=t, kind="mark", label=label) for t, label in marks]
        events.sort(key=lambda e: e.t)
        return rows.to_log(robot, events, settings)
