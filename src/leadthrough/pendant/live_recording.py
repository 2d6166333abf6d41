"""The recording of a live session: the last minutes at the controller rate, for the export.

A live session has no end to size its arrays for, so it keeps a ring: one row per controller
cycle (10 ms), the same columns as a session file
(:class:`~leadthrough.session.record.SessionLog`), the oldest row overwritten once the ring is
full. The ring's columns and its counter live in shared memory
(:mod:`~leadthrough.pendant.shared_state`): the loop's process writes a row and then advances
the counter; the pendant's process reads the ring without a lock: it reads the counter, copies
the rows, reads the counter again, and keeps only the rows that no write can have touched in
between (a row being written, or overwritten while
the copy ran, is dropped). The loop never waits for a reader.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from leadthrough.control.safety import Event
from leadthrough.errors import TeachError
from leadthrough.pendant.shared_state import ColumnSpec, SharedBlock, shared_columns
from leadthrough.session.loop import ServoPeriods, SessionBuffers, transition_event
from leadthrough.session.record import SessionEvent, SessionLog

__all__ = ["LiveRecording"]


class LiveRecording:
    """A ring of the last ``cycles`` controller cycles of a loop, in shared memory.

    Args:
        cycles: Rows kept.
        n: Number of joints.
        with_truth: Keep the simulator's applied wrench.
        block: The memory (at least :meth:`nbytes`); None: a block of its own (one process).
    """

    def __init__(self, cycles: int, n: int, with_truth: bool,
                 block: SharedBlock | None = None) -> None:
        specs = self.columns(cycles, n, with_truth)
        self.block = block if block is not None else SharedBlock(self.nbytes(specs))
        arrays = shared_columns(self.block, specs, 8)
        self._count = np.ndarray((1,), np.int64, self.block.shm.buf, 0)
        self._rows = SessionBuffers(0, n, with_truth)
        for name, array in arrays.items():
            setattr(self._rows, name, array)
        self._n, self._with_truth = n, with_truth
        self.capacity = cycles

    @staticmethod
    def columns(cycles: int, n: int, with_truth: bool) -> list[ColumnSpec]:
        """The ring's arrays: a session's columns with ``cycles`` rows."""
        one = SessionBuffers(1, n, with_truth)
        return [ColumnSpec(name, (cycles, *column.shape[1:]), column.dtype.str)
                for name, column in vars(one).items() if column is not None]

    @staticmethod
    def nbytes(specs: Sequence[ColumnSpec]) -> int:
        """Bytes of a ring with these columns (and its counter)."""
        return 8 + sum(spec.nbytes for spec in specs)

    @property
    def count(self) -> int:
        """Rows written so far (the next row's number); only the loop writes it."""
        return int(self._count[0])

    def store(self, loop: ServoPeriods, t: float) -> None:
        """Record ``loop``'s state of this period as the next row (the loop's side only)."""
        count = self.count
        loop.store(self._rows, count % self.capacity, t)
        self._count[0] = count + 1

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

    def session_log(self, robot: str, events: Sequence[Event],
                    marks: Sequence[tuple[float, str]],
                    settings: dict[str, object]) -> SessionLog:
        """The recording as a session, with the controller's transitions and ``marks``.

        Args:
            robot: Robot name.
            events: The controller's transitions (its event log).
            marks: (time [s], label) of the operator's marks.
            settings: Recorded in the session.

        Raises:
            TeachError: Fewer than two rows recorded.
        """
        rows, _ = self.rows()
        if rows.time.shape[0] < 2:
            raise TeachError("nothing recorded yet", field="recording",
                             value=rows.time.shape[0], expected="at least 2 controller cycles")
        log_events = [transition_event(e) for e in events]
        log_events += [SessionEvent(t=t, kind="mark", label=label) for t, label in marks]
        log_events.sort(key=lambda e: e.t)
        return rows.to_log(robot, log_events, settings)
