"""The recording of a live session: the last minutes at the controller rate, for the export.

A live session has no end to size its arrays for, so it keeps a ring: one row per controller
cycle (10 ms), the oldest row overwritten once the ring is full. Its rows are the loop
recorder's own (:class:`~leadthrough.session.recorder.RecordChunk`, one layout for every
recording), laid out in shared memory (:mod:`~leadthrough.pendant.shared_state`) after the
ring's counter: the loop's process writes a row and then advances the counter; the pendant's
process reads the ring without a lock: it reads the counter, copies the rows, reads the
counter again, and keeps only the rows that no write can have touched in between (a row being
written, or overwritten while the copy ran, is dropped). The loop never waits for a reader.
The rows become a session (:class:`~leadthrough.session_format.SessionLog`) the way the
loop's recording does (:func:`~leadthrough.session.recorder.chunks_to_log`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding_types import GuidingOutput
from leadthrough.control.safety import Event
from leadthrough.drivers.protocol import DriverFeedback, JointCommand
from leadthrough.errors import TeachError
from leadthrough.estimation.estimator import EstimatorOutput
from leadthrough.pendant.shared_state import SharedBlock
from leadthrough.session.controller_events import transition_event
from leadthrough.session.recorder import RecordChunk, chunks_to_log
from leadthrough.session_format import SessionEvent, SessionLog

__all__ = ["LiveRecording"]

Array = NDArray[np.float64]
_COUNTER_BYTES = 8


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
        self.block = (block if block is not None
                      else SharedBlock(self.nbytes(cycles, n, with_truth)))
        buf = self.block.shm.buf
        self._count = np.ndarray((1,), np.int64, buf, 0)
        # an array over the block (not a slice of its memoryview, which would keep the block
        # mapped past its close)
        rows = np.ndarray((RecordChunk.nbytes(cycles, n, with_truth),), np.uint8, buf,
                          _COUNTER_BYTES)
        self._ring = RecordChunk(cycles, n, with_truth, buffer=rows)
        self._n, self._with_truth = n, with_truth
        self.capacity = cycles

    @staticmethod
    def nbytes(cycles: int, n: int, with_truth: bool) -> int:
        """Bytes of a ring of ``cycles`` rows (the counter and the rows)."""
        return _COUNTER_BYTES + RecordChunk.nbytes(cycles, n, with_truth)

    @property
    def count(self) -> int:
        """Rows written so far (the next row's number); only the loop writes it."""
        return int(self._count[0])

    def store(self, t: float, fb: DriverFeedback, cmd: JointCommand, e_out: EstimatorOutput,
              c_out: GuidingOutput, applied: Array | None) -> None:
        """Record this controller cycle as the next row (the loop's side only).

        Args:
            t: The cycle's time [s].
            fb: The period's feedback (measured joint positions [rad] and currents [A]).
            cmd: The joint command the period computed (positions [rad], velocities [rad/s]).
            e_out: The estimator's output (external joint torque [N·m], TCP wrench [N, N·m]).
            c_out: The controller's output (commanded TCP pose and twist, safety state, fault).
            applied: The simulator's applied wrench [N, N·m], shape (6,), or None.
        """
        count = self.count
        self._ring.write(count % self.capacity, t, fb.q, fb.current, e_out.tau_ext,
                         e_out.wrench, cmd.q, cmd.qd, c_out.transform_tool_to_base,
                         c_out.twist_base, int(c_out.state), int(c_out.fault), applied)
        self._count[0] = count + 1

    def rows(self) -> tuple[RecordChunk, int]:
        """A time-ordered copy of the complete rows (a chunk of its own memory, every row
        filled), and the number of the first one."""
        first_asked = self.count          # read once: rows below it are complete
        lo = max(0, first_asked - self.capacity)
        idx = np.arange(lo, first_asked) % self.capacity
        taken = {name: np.take(array, idx, axis=0)
                 for name, array in self._ring.arrays().items()}
        written = self.count              # rows up to it may have overwritten the oldest
        drop = min(idx.size, max(0, written + 1 - self.capacity - lo))
        copy = RecordChunk(idx.size - drop, self._n, self._with_truth)
        for name, array in copy.arrays().items():
            array[:] = taken[name][drop:]
        copy.rows = copy.size
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
        if rows.rows < 2:
            raise TeachError("nothing recorded yet", field="recording", value=rows.rows,
                             expected="at least 2 controller cycles")
        log_events = [transition_event(e) for e in events]
        log_events += [SessionEvent(t=t, kind="mark", label=label) for t, label in marks]
        log_events.sort(key=lambda e: e.t)
        return chunks_to_log([rows], self._with_truth, robot, log_events, settings)
