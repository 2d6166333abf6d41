"""Record the feedback a driver delivers, and replay it as a driver.

:class:`RecordingDriver` wraps any :class:`~leadthrough.drivers.protocol.Driver` and keeps every
:meth:`~leadthrough.drivers.protocol.Driver.read` (the sample, and whether one arrived) in a
preallocated :class:`FeedbackTrace`. :class:`ReplayDriver` delivers such a trace read for read and
takes no notice of the commands written to it.

The loop is deterministic, so replaying a session's trace through a loop built with the same
settings repeats its computation exactly: the same estimates, the same states, the same commands,
bit for bit. That serves two purposes:

* timing the loop's own computation without the simulator (or the fieldbus) between cycles,
  whose work evicts the loop's data and code from the caches (``benchmarks/guiding.py``);
* re-running a recorded session offline, e.g. to inspect it with more logging. With other
  settings the replay is open loop: the recorded robot did not follow the new commands.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand, WrappedDriver
from leadthrough.errors import DataError

__all__ = ["FeedbackTrace", "RecordingDriver", "ReplayDriver"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FeedbackTrace:
    """The reads of one session, in order (one per call of ``read``).

    Attributes:
        dt: Servo period of the driver [s].
        t: Sample time [s], shape (N,) (NaN where no sample arrived).
        q: Joint positions [rad], shape (N, n).
        current: Motor currents [A], shape (N, n).
        sequence: Sample counter, shape (N,).
        fresh: Whether ``read`` delivered a new sample, shape (N,).
        controller_state: The controller's state, shape (N,); None: ``OK`` throughout.
        digital_inputs: The digital inputs' bit field, shape (N,); None: none set.
    """

    dt: float
    t: Array
    q: Array
    current: Array
    sequence: NDArray[np.int64]
    fresh: NDArray[np.bool_]
    controller_state: NDArray[np.int64] | None = None
    digital_inputs: NDArray[np.int64] | None = None

    @property
    def reads(self) -> int:
        """Number of reads N."""
        return int(self.t.size)


class RecordingDriver(WrappedDriver):
    """A driver that records every read of the driver it wraps.

    Args:
        driver: The driver doing the work.
        capacity: Reads to keep (a session of S servo periods reads S + 1 times); later reads
            are passed through but not kept.

    Raises:
        DataError: ``capacity`` not positive.
    """

    def __init__(self, driver: Driver, capacity: int) -> None:
        if capacity < 1:
            raise DataError("must be >= 1", field="capacity", value=capacity, expected=">= 1")
        super().__init__(driver)
        n = driver.n
        self._t = np.full(capacity, np.nan)
        self._q = np.full((capacity, n), np.nan)
        self._current = np.full((capacity, n), np.nan)
        self._sequence = np.full(capacity, -1, dtype=np.int64)
        self._fresh = np.zeros(capacity, dtype=bool)
        self._state = np.zeros(capacity, dtype=np.int64)
        self._inputs = np.zeros(capacity, dtype=np.int64)
        self._k = 0

    def read(self, fb: DriverFeedback) -> bool:
        """Read from the wrapped driver and keep the sample."""
        fresh = self._driver.read(fb)
        k = self._k
        if k < self._t.size:
            self._fresh[k] = fresh
            if fresh:
                self._t[k] = fb.t
                self._q[k] = fb.q
                self._current[k] = fb.current
                self._sequence[k] = fb.sequence
                self._state[k] = fb.state
                self._inputs[k] = fb.inputs
            self._k = k + 1
        return fresh

    def trace(self) -> FeedbackTrace:
        """The reads so far (copies)."""
        k = self._k
        return FeedbackTrace(dt=self.dt, t=self._t[:k].copy(), q=self._q[:k].copy(),
                             current=self._current[:k].copy(),
                             sequence=self._sequence[:k].copy(), fresh=self._fresh[:k].copy(),
                             controller_state=self._state[:k].copy(),
                             digital_inputs=self._inputs[:k].copy())


class ReplayDriver:
    """A driver that delivers a recorded :class:`FeedbackTrace`, read for read.

    ``step`` does nothing (a replay is not paced), ``write`` keeps the last command
    (:attr:`last_command`), and after the trace's last read every read is stale.

    Args:
        trace: The recorded reads.

    Raises:
        DataError: An empty trace, or arrays of inconsistent shapes.
    """

    simulated = True

    def __init__(self, trace: FeedbackTrace) -> None:
        N = trace.reads
        if N < 1 or trace.q.ndim != 2 or trace.q.shape[0] != N \
                or trace.current.shape != trace.q.shape \
                or trace.sequence.shape != (N,) or trace.fresh.shape != (N,):
            raise DataError("inconsistent or empty trace", field="trace",
                            value=(trace.t.shape, trace.q.shape, trace.current.shape,
                                   trace.sequence.shape, trace.fresh.shape),
                            expected="N >= 1 reads: t (N,), q and current (N, n), sequence and "
                                     "fresh (N,)")
        if not (np.isfinite(trace.dt) and trace.dt > 0):
            raise DataError("must be > 0", field="trace.dt", value=trace.dt, expected="> 0 s")
        for name in ("controller_state", "digital_inputs"):
            column = getattr(trace, name)
            if column is not None and np.shape(column) != (N,):
                raise DataError("inconsistent trace", field=f"trace.{name}",
                                value=np.shape(column), expected=f"None or shape ({N},)")
        self._trace = trace
        self._state = (trace.controller_state if trace.controller_state is not None
                       else np.zeros(N, dtype=np.int64))
        self._inputs = (trace.digital_inputs if trace.digital_inputs is not None
                        else np.zeros(N, dtype=np.int64))
        self._n = int(trace.q.shape[1])
        self._k = 0
        self.last_command = JointCommand.zeros(self._n)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self._n

    @property
    def dt(self) -> float:
        """Servo period of the recording [s]."""
        return self._trace.dt

    def make_feedback(self) -> DriverFeedback:
        """An empty feedback."""
        return DriverFeedback.empty(self._n)

    def make_command(self) -> JointCommand:
        """A zero command."""
        return JointCommand.zeros(self._n)

    def read(self, fb: DriverFeedback) -> bool:
        """Deliver the next recorded read (False: none arrived then, or the trace is over)."""
        k, tr = self._k, self._trace
        if k >= tr.t.size:
            return False
        self._k = k + 1
        if not tr.fresh[k]:
            return False
        fb.t = float(tr.t[k])
        fb.q[:] = tr.q[k]
        fb.current[:] = tr.current[k]
        fb.sequence = int(tr.sequence[k])
        fb.state = int(self._state[k])
        fb.inputs = int(self._inputs[k])
        fb.inputs_read = True
        return True

    def write(self, cmd: JointCommand) -> None:
        """Keep the command (a copy) in :attr:`last_command`; nothing else."""
        self.last_command.q[:] = cmd.q
        self.last_command.qd[:] = cmd.qd

    def step(self) -> None:
        """Nothing to wait for."""
