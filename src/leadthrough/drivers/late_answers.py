"""When late answers to a streaming controller become a fault: :class:`LateAnswerTolerance`.

A controller that holds its last target for a cycle it got no answer in (KUKA RSI's ``HOLDON``)
and stops only after many late answers in a row (RSI's ``Timeout``, 100 in the shipped
context) tolerates an isolated late answer: the robot held still for one cycle. A PC on a
general-purpose OS answers late now and then (a page fault, another process, the interpreter's
lock), and latching a fault on each of those would end sessions that the controller itself
carries on with. So isolated late answers are counted and reported, and only late answers that
come in a run mean the PC has lost the controller's cycle: ``COMMAND_REJECTED`` in the
feedback, which the loop latches as a fault (a commanded stop) long before the controller's
own stop.

A run is either :data:`LATE_RUN` late answers in a row, or :data:`LATE_IN_WINDOW` within
:data:`LATE_WINDOW` controller cycles. Why these numbers:

* :data:`LATE_RUN` = 5: the robot holds its last target through each late answer, so five in a
  row are 20 ms (4 ms cycle) or 60 ms (12 ms) during which the robot did not follow the loop:
  longer than a scheduling hiccup of a loaded PC (a few ms), and 20 times below RSI's limit of
  100, so the loop's commanded stop starts while RSI still takes its corrections (the loop's
  own watchdog, 50 ms by default, catches a single exchange that stalls longer);
* :data:`LATE_IN_WINDOW` = 20 within :data:`LATE_WINDOW` = 250 cycles (1 s at 4 ms, 3 s at
  12 ms): 8 % of the cycles late, scattered, is a PC that is not keeping up, even if no run
  reaches five; it also bounds how much the robot may lag the commanded motion.

The counts are in controller cycles (the documents' sequence numbers), not wall time.
"""

from __future__ import annotations

from collections import deque

__all__ = ["LATE_IN_WINDOW", "LATE_RUN", "LATE_WINDOW", "LateAnswerTolerance"]

#: Late answers in a row that are a fault.
LATE_RUN = 5
#: Late answers within :data:`LATE_WINDOW` cycles that are a fault.
LATE_IN_WINDOW = 20
#: The window of :data:`LATE_IN_WINDOW` [controller cycles].
LATE_WINDOW = 250


class LateAnswerTolerance:
    """Counts late answers; says when they come in a run (see the module doc).

    Args:
        run: Late answers in a row that are a fault (>= 1; 1: every late answer is one).
        in_window: Late answers within ``window`` cycles that are a fault (>= ``run``).
        window: The window [controller cycles] (>= ``in_window``).

    Attributes:
        late: Late answers counted.
        longest_run: The longest run of late answers in a row.
        run_now: Late answers in the current run.
    """

    def __init__(self, run: int = LATE_RUN, in_window: int = LATE_IN_WINDOW,
                 window: int = LATE_WINDOW) -> None:
        if not (1 <= run <= in_window <= window):
            raise ValueError(f"need 1 <= run ({run}) <= in_window ({in_window}) <= window "
                             f"({window})")
        self.run, self.in_window, self.window = run, in_window, window
        self._recent: deque[int] = deque(maxlen=in_window)
        self._last_late: int | None = None
        self.late = self.longest_run = self.run_now = 0

    def reset(self) -> None:
        """Forget every late answer (a new stream)."""
        self._recent.clear()
        self._last_late = None
        self.late = self.longest_run = self.run_now = 0

    def update(self, sequence: int, late: int) -> bool:
        """One document: its cycle number and how many late answers of ours it reports.

        Args:
            sequence: The document's controller cycle (+1 per cycle).
            late: Late answers it reports (the controller's count grown by more than the
                documents we never received); k > 1: the k cycles before it, in a row.

        Returns:
            Whether the late answers now come in a run (a fault).
        """
        if late <= 0:
            self.run_now = 0
            return False
        self.late += late
        in_row = self._last_late is not None and sequence - self._last_late == 1
        self.run_now = (self.run_now if in_row else 0) + late
        self.longest_run = max(self.longest_run, self.run_now)
        self._last_late = sequence
        for _ in range(min(late, self.in_window)):
            self._recent.append(sequence)
        crowded = (len(self._recent) == self.in_window
                   and sequence - self._recent[0] < self.window)
        return self.run_now >= self.run or crowded
