"""The loop's recording, one row per servo period, in fixed-size chunks.

:class:`SessionRecorder` writes each period's row into a preallocated chunk
(:class:`RecordChunk`, ``chunk_rows`` rows: a row write copies into existing arrays); a full
chunk goes to its sink and the recorder continues in a fresh one. The in-memory sink keeps
the chunks and joins them into a :class:`~leadthrough.session.record.SessionLog` at the end;
memory grows by one chunk at a time, with the session's length.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.session.record import SessionEvent, SessionLog

__all__ = ["DEFAULT_CHUNK_ROWS", "QUATERNION_SLICE_ROWS", "ChunkSink", "MemorySink", "RecordChunk",
           "SessionRecorder", "chunks_to_log"]

Array = NDArray[np.float64]
#: Rows per chunk: 10 s at 1 kHz (about 4.5 MB for six joints).
DEFAULT_CHUNK_ROWS = 10_000
#: Rows converted per call into SciPy when a chunk's orientations become quaternions. A call
#: holds the interpreter lock throughout: 10 000 rows in one call held it 3-4 ms, and a
#: streamed session's writer thread converts a chunk every 10 s while the loop runs (a thread
#: waking from a 1 ms sleep waited up to 4 ms, ``benchmarks/gil_hold.py``). 500 rows hold it
#: about 0.2 ms, and the lock is offered to a waiting thread between two calls.
QUATERNION_SLICE_ROWS = 500


class RecordChunk:
    """Preallocated rows of a session (row ``k`` of each array is servo period ``k`` of the
    chunk; ``rows`` of them are filled).

    Args:
        size: Rows it holds.
        n: Number of joints.
        with_truth: Keep the simulator's applied wrench.
    """

    def __init__(self, size: int, n: int, with_truth: bool) -> None:
        self.rows = 0
        self.time = np.zeros(size)
        self.q = np.zeros((size, n))
        self.current = np.zeros((size, n))
        self.tau_ext = np.zeros((size, n))
        self.wrench = np.zeros((size, 6))
        self.q_cmd = np.zeros((size, n))
        self.qd_cmd = np.zeros((size, n))
        self.tcp = np.zeros((size, 3))
        self.rot = np.zeros((size, 3, 3))
        self.twist = np.zeros((size, 6))
        self.state = np.zeros(size, dtype=np.int64)
        self.fault = np.zeros(size, dtype=np.int64)
        self.applied = np.zeros((size, 6)) if with_truth else None

    @property
    def full(self) -> bool:
        """Every row is filled."""
        return self.rows == self.time.size

    def quaternions(self) -> Array:
        """The commanded TCP orientations of the filled rows, (x, y, z, w), shape (rows, 4),
        converted :data:`QUATERNION_SLICE_ROWS` rows at a time."""
        quat = np.zeros((self.rows, 4))
        for start in range(0, self.rows, QUATERNION_SLICE_ROWS):
            end = min(start + QUATERNION_SLICE_ROWS, self.rows)
            quat[start:end] = Rotation.from_matrix(self.rot[start:end]).as_quat()
            time.sleep(0)   # the lock to a waiting thread (the loop's), if there is one
        return quat


class ChunkSink(Protocol):
    """Where full chunks go."""

    def take(self, chunk: RecordChunk) -> RecordChunk:
        """Accept a full (or, at the end, the last) chunk; return an empty chunk to fill next.
        """
        ...

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> SessionLog | None:
        """The session is over: the recording in memory, or None if it went elsewhere."""
        ...


class MemorySink:
    """Keeps every chunk; the session in memory at the end.

    Args:
        n: Number of joints.
        with_truth: Chunks keep the simulator's applied wrench.
        chunk_rows: Rows of a new chunk.
    """

    def __init__(self, n: int, with_truth: bool, chunk_rows: int) -> None:
        self._n, self._truth, self._rows = n, with_truth, chunk_rows
        self._chunks: list[RecordChunk] = []

    def take(self, chunk: RecordChunk) -> RecordChunk:
        """Keep ``chunk``; a new one."""
        self._chunks.append(chunk)
        return RecordChunk(self._rows, self._n, self._truth)

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> SessionLog:
        """The kept chunks as one session."""
        chunks = [c for c in self._chunks if c.rows > 0] or self._chunks[:1]
        return chunks_to_log(chunks, self._truth, robot, events, settings)


def chunks_to_log(chunks: list[RecordChunk], with_truth: bool, robot: str,
                  events: list[SessionEvent], settings: dict[str, object]) -> SessionLog:
    """The filled rows of ``chunks``, in order, as one session."""

    def join(name: str) -> Any:
        return np.concatenate([getattr(c, name)[:c.rows] for c in chunks])

    applied = join("applied") if with_truth else None
    return SessionLog(robot=robot, time=join("time"), q=join("q"), current=join("current"),
                      tau_ext=join("tau_ext"), wrench_base=join("wrench"), q_cmd=join("q_cmd"),
                      qd_cmd=join("qd_cmd"), tcp_cmd_base=join("tcp"),
                      tcp_cmd_quat=np.concatenate([c.quaternions() for c in chunks]),
                      twist_cmd_base=join("twist"), state=join("state"), fault=join("fault"),
                      wrench_applied_base=applied, events=events, settings=settings)


class SessionRecorder:
    """Records the loop's rows chunk by chunk into a sink (see the module doc).

    Args:
        n: Number of joints.
        with_truth: Record the simulator's applied wrench.
        sink: Where full chunks go (default: memory).
        chunk_rows: Rows per chunk.
    """

    def __init__(self, n: int, with_truth: bool, sink: ChunkSink | None = None,
                 chunk_rows: int = DEFAULT_CHUNK_ROWS) -> None:
        self.sink: ChunkSink = sink if sink is not None else MemorySink(n, with_truth,
                                                                          chunk_rows)
        self.chunk = RecordChunk(chunk_rows, n, with_truth)
        self.rows = 0

    def store(self, t: float, q: Array, current: Array, tau_ext: Array, wrench: Array,
              q_cmd: Array, qd_cmd: Array, transform: Array, twist: Array, state: int,
              fault: int, applied: Array | None) -> None:
        """Record one servo period."""
        c = self.chunk
        i = c.rows
        c.time[i] = t
        c.q[i] = q
        c.current[i] = current
        c.tau_ext[i] = tau_ext
        c.wrench[i] = wrench
        c.q_cmd[i] = q_cmd
        c.qd_cmd[i] = qd_cmd
        c.tcp[i] = transform[:3, 3]
        c.rot[i] = transform[:3, :3]
        c.twist[i] = twist
        c.state[i] = state
        c.fault[i] = fault
        if c.applied is not None and applied is not None:
            c.applied[i] = applied
        c.rows = i + 1
        self.rows += 1
        if c.rows == c.time.size:
            self.chunk = self.sink.take(c)

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> SessionLog | None:
        """The session is over: hand the last chunk to the sink and close it."""
        if self.chunk.rows > 0 or self.rows == 0:
            self.sink.take(self.chunk)
        return self.sink.finish(robot, events, settings)
