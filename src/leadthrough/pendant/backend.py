"""The pendant's link to the real-time loop: the loop in a process of its own, its snapshot in
shared memory, requests through a pipe. Everything the pendant needs from the loop goes through
this module.

The loop (:mod:`~leadthrough.pendant.loop_process`) runs in a separate process, started with
``multiprocessing``'s *spawn* method: it has its own interpreter, so nothing the pendant does
in Python (viser's page updates hold the interpreter lock for milliseconds) can delay a servo
period; only the operating system's scheduler is shared. The pendant's side:

* **state in**: :meth:`LiveSession.snapshot` reads the latest complete snapshot from a
  sequence-locked record in shared memory (:mod:`~leadthrough.pendant.shared_state`), never
  half of one, never waiting for the loop (and the loop never waits for it);
  :meth:`~LiveSession.period_times` and the recording for the export
  (:meth:`~LiveSession.session_log`) are rings in shared memory, read the same way;
* **requests out**: :meth:`LiveSession.send` writes a request into a ``multiprocessing`` pipe;
  the loop reads what has arrived every servo period and serves it in order
  (:class:`~leadthrough.session.requests.PipeRequests`, :meth:`ServoLoop.serve
  <leadthrough.session.servo_loop.ServoLoop.serve>`). Refusals and results come back as
  notices.

A frozen, slow or closed browser therefore changes nothing in the loop's process
(``benchmarks/pendant_isolation.py`` measures it). If the pendant's process dies, the loop sees
its pipe close, releases the enabling input (a commanded stop) and exits at rest; if the loop's
process dies, the snapshot says the link is lost (state FAULT, with the exit code) instead of
showing its last state. :meth:`LiveSession.stop` ends the process cleanly (and at exit).

Python docs: ``multiprocessing`` (contexts and start methods, ``Pipe``, ``Connection.poll``),
``multiprocessing.shared_memory``.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import State
from leadthrough.errors import ControlError
from leadthrough.pendant.live_recording import LiveRecording
from leadthrough.pendant.loop_process import (
    LoopProcessOptions,
    LoopRecipe,
    SharedNames,
    run_loop_process,
)
from leadthrough.pendant.messages import (
    Adjust,
    ClearFault,
    LoopSnapshot,
    MarkedPoint,
    MarkPoint,
    Notice,
    PeriodTimes,
    Request,
    SetEnable,
    SimulatorRequest,
    SlowState,
    Stop,
    decode_snapshot,
    numbers_size,
)
from leadthrough.pendant.shared_state import PeriodRing, SeqlockRecord, SharedBlock
from leadthrough.robot.description import Robot
from leadthrough.session_format import SessionLog

__all__ = ["Adjust", "ClearFault", "LiveSession", "LoopSnapshot", "MarkPoint", "MarkedPoint",
           "Notice", "PeriodTimes", "Request", "SetEnable", "SimulatorRequest"]

#: Capacity of a snapshot's slow part (marks, notices, transition log) [bytes].
BLOB_BYTES = 1 << 20


class LiveSession:
    """A guiding loop running in its own process until stopped, with a snapshot and requests.

    Args:
        recipe: What the loop's process builds (picklable; e.g.
            :class:`~leadthrough.pendant.simulated.SimulatedRecipe`).
        robot: The robot's description (the page's).
        record_s: Length of the recording kept for the export [s] (older rows dropped).
        paced: Pace to the wall clock; default: when the driver is simulated (a real driver's
            ``step`` waits for the robot).
        timing_window: Servo periods whose timing is kept (:meth:`period_times`).
        rt_priority: Run the loop's process under ``SCHED_FIFO`` at this priority (1–99;
            Linux, needs the privilege to, e.g. root or ``CAP_SYS_NICE``): the operating
            system then runs it before any ordinary process. None: ordinary scheduling. If
            the system refuses, the loop runs anyway and says so in a notice.
        controller_dt: The controller's cycle [s] (to size the recording).
    """

    def __init__(self, recipe: LoopRecipe, robot: Robot, *, record_s: float = 600.0,
                 paced: bool | None = None, timing_window: int = 1000,
                 rt_priority: int | None = None, controller_dt: float = 0.01) -> None:
        self.robot = robot
        cycles = max(2, round(record_s / controller_dt))
        window = max(1, timing_window)
        self._blocks = [SharedBlock(SeqlockRecord.size(numbers_size(robot.n), BLOB_BYTES)),
                        SharedBlock(PeriodRing.nbytes(window)),
                        SharedBlock(LiveRecording.nbytes(cycles, robot.n, recipe.with_truth))]
        self._record = SeqlockRecord(self._blocks[0], numbers_size(robot.n), BLOB_BYTES)
        self._periods = PeriodRing(self._blocks[1], window)
        self.recording = LiveRecording(cycles, robot.n, recipe.with_truth, self._blocks[2])
        names = SharedNames(self._blocks[0].name, self._blocks[1].name, self._blocks[2].name,
                            n=robot.n, blob_bytes=BLOB_BYTES,
                            timing_window=window, cycles=cycles, with_truth=recipe.with_truth)
        ctx = multiprocessing.get_context("spawn")
        self._conn, child_conn = ctx.Pipe(duplex=True)
        self._process: BaseProcess = ctx.Process(
            target=run_loop_process, name="leadthrough-loop", daemon=True,
            args=(recipe, names, child_conn, LoopProcessOptions(paced, rt_priority)))
        self._child_conn: Connection | None = child_conn
        self._send_lock = threading.Lock()
        self._cache: tuple[int, LoopSnapshot, SlowState] | None = None
        self._slow_cache: tuple[bytes, SlowState] | None = None
        self.every = 1
        #: Settings recorded in the session file (the loop's, once started).
        self.settings: dict[str, object] = {}
        self._finalizer = weakref.finalize(self, _shut_down, self._process, self._conn,
                                           self._blocks)

    # ------------------------------------------------------------ life
    def start(self, timeout_s: float = 300.0,
              progress: Callable[[str], None] | None = None) -> None:
        """Start the loop's process and wait until it runs (it builds the loop and loads or
        compiles the compiled code first), passing its steps to ``progress``.

        Raises:
            ControlError: The loop failed to start (its error), or did not within the time.
        """
        self._process.start()
        assert self._child_conn is not None
        self._child_conn.close()                   # the child's end lives in the child now
        self._child_conn = None
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            try:
                if remaining <= 0 or not self._conn.poll(remaining):
                    raise ControlError("the loop did not start in time", field="timeout_s",
                                       value=timeout_s, expected="a first controller cycle")
                message = self._conn.recv()
            except (EOFError, OSError) as e:
                self._process.join(5.0)
                raise ControlError(f"the loop's process ended while starting (exit code "
                                   f"{self._process.exitcode})") from e
            if message[0] == "progress" and progress is not None:
                progress(message[1])
            elif message[0] == "error":
                self._process.join(5.0)
                raise ControlError(f"the loop did not start: {message[1]}")
            elif message[0] == "ready":
                self.settings, self.every = dict(message[1]), int(message[2])
                return

    def stop(self, timeout_s: float = 10.0) -> None:
        """Release the enabling input, let the robot come to rest, and end the process
        (terminated if it does not end within ``timeout_s``)."""
        self.send(Stop())
        _end_process(self._process, timeout_s)

    def close(self) -> None:
        """Stop the loop and release the shared memory."""
        self._finalizer()

    @property
    def running(self) -> bool:
        """Whether the loop's process is running."""
        return self._process.is_alive()

    @property
    def pid(self) -> int | None:
        """The loop's process id (None before the start)."""
        return self._process.pid

    # ------------------------------------------------------------ the interface's side
    def send(self, request: Request | Stop) -> None:
        """Send a request; the loop applies it at its next controller cycle. (Nothing happens
        once the loop is gone: the snapshot says so.)"""
        with self._send_lock, contextlib.suppress(OSError, EOFError, ValueError):
            self._conn.send(request)

    @property
    def periods_run(self) -> int:
        """Servo periods run so far."""
        return self._periods.count

    def period_times(self, last: int | None = None) -> PeriodTimes:
        """Timing of the last ``last`` servo periods (default and at most: the timing window),
        oldest first (copies; the newest period may be missing, being written)."""
        idx, work, done = self._periods.last(last)
        return PeriodTimes(work, done, idx % self.every == 0)

    def snapshot(self) -> LoopSnapshot | None:
        """The latest snapshot (None before the first controller cycle). Once the loop's
        process has died without a last word, its last snapshot in state FAULT with the
        error "lost link"."""
        alive = self._process.is_alive()
        read = self._record.read()                 # None: none yet, or a write cut short
        if read is not None and (self._cache is None or self._cache[0] != read[0]):
            seq, numbers, blob = read
            slow = self._slow(blob)
            self._cache = (seq, decode_snapshot(numbers, slow), slow)
        if self._cache is None:
            return None
        snap = self._cache[1]
        if not alive and snap.error is None and self._process.exitcode is not None:
            snap = replace(snap, state=State.FAULT,
                           error=f"lost link to the loop (its process ended, exit code "
                                 f"{self._process.exitcode})")
        return snap

    @property
    def config(self) -> GuidingConfig:
        """The controller's settings in force (from the latest snapshot).

        Raises:
            ControlError: The loop has not started.
        """
        snap = self.snapshot()
        if snap is None:
            raise ControlError("the loop has not started", field="live", value=None,
                               expected="LiveSession.start() first")
        return snap.settings

    def session_log(self, marks: Sequence[MarkedPoint]) -> SessionLog:
        """The recording so far (the last ``record_s`` seconds) with ``marks`` as its marks.

        Raises:
            TeachError: Nothing recorded yet.
        """
        self.snapshot()
        events = self._cache[2].events if self._cache is not None else ()
        return self.recording.session_log(self.robot.name, events,
                                          [(m.t, m.label) for m in marks], self.settings)

    def _slow(self, blob: bytes) -> SlowState:
        if self._slow_cache is None or self._slow_cache[0] != blob:
            self._slow_cache = (blob, SlowState.decode(blob))
        return self._slow_cache[1]


def _end_process(process: BaseProcess, timeout_s: float) -> None:
    """Wait for ``process`` to end; terminate it, then kill it, if it does not."""
    if process.pid is None:
        return
    process.join(timeout_s)
    if process.is_alive():
        process.terminate()
        process.join(2.0)
    if process.is_alive():
        process.kill()
        process.join(2.0)


def _shut_down(process: BaseProcess, conn: Connection, blocks: list[SharedBlock]) -> None:
    """At exit or when the session is dropped: stop the loop, free the memory."""
    if process.pid is not None and process.is_alive():
        with contextlib.suppress(OSError, ValueError):
            conn.send(Stop())
        _end_process(process, 10.0)
    conn.close()
    for block in blocks:
        block.close()
