"""The loop's recording, one row per servo period, in fixed-size chunks.

:class:`SessionRecorder` writes each period's row into a preallocated chunk
(:class:`RecordChunk`, ``chunk_rows`` rows: a row write copies into existing arrays); a full
chunk goes to its sink and the recorder continues in a fresh one. The in-memory sink keeps
the chunks and joins them into a :class:`~leadthrough.session_format.SessionLog` at the end;
memory grows by one chunk at a time, with the session's length.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.errors import DataError
from leadthrough.session_format import SessionEvent, SessionLog

__all__ = ["DEFAULT_CHUNK_ROWS", "ChunkSink", "MemorySink", "RecordChunk",
           "SessionRecorder", "chunks_to_log"]

Array = NDArray[np.float64]
#: Rows per chunk: 10 s at 1 kHz (about 4.5 MB for six joints).
DEFAULT_CHUNK_ROWS = 10_000


def _layout(size: int, n: int, with_truth: bool) -> list[tuple[str, tuple[int, ...], type]]:
    """A chunk's arrays in their order in its memory: name, shape, dtype (all 8-byte items, so
    every array starts aligned)."""
    fields: list[tuple[str, tuple[int, ...], type]] = [
        ("time", (size,), np.float64), ("q", (size, n), np.float64),
        ("current", (size, n), np.float64), ("tau_ext", (size, n), np.float64),
        ("wrench", (size, 6), np.float64), ("q_cmd", (size, n), np.float64),
        ("qd_cmd", (size, n), np.float64), ("tcp", (size, 3), np.float64),
        ("rot", (size, 3, 3), np.float64), ("twist", (size, 6), np.float64),
        ("state", (size,), np.int64), ("fault", (size,), np.int64)]
    if with_truth:
        fields.append(("applied", (size, 6), np.float64))
    return fields


class RecordChunk:
    """Preallocated rows of a session (row ``k`` of each array is servo period ``k`` of the
    chunk; ``rows`` of them are filled). The arrays are views into one block of memory: its
    own, or ``buffer`` (memory shared with the session's writer process,
    :mod:`leadthrough.session.writer_link`).

    Args:
        size: Rows it holds.
        n: Number of joints.
        with_truth: Keep the simulator's applied wrench.
        buffer: Writable memory of at least :meth:`nbytes` bytes to hold the arrays (None: a
            new zeroed block).
    """

    def __init__(self, size: int, n: int, with_truth: bool, buffer: Any = None) -> None:
        self.rows = 0
        memory = (np.zeros(self.nbytes(size, n, with_truth), dtype=np.uint8) if buffer is None
                  else np.frombuffer(buffer, dtype=np.uint8))
        offset = 0
        views: dict[str, Any] = {}
        for name, shape, dtype in _layout(size, n, with_truth):
            count = int(np.prod(shape))
            views[name] = memory[offset:offset + 8 * count].view(dtype).reshape(shape)
            offset += 8 * count
        self.time: Array = views["time"]
        self.q: Array = views["q"]
        self.current: Array = views["current"]
        self.tau_ext: Array = views["tau_ext"]
        self.wrench: Array = views["wrench"]
        self.q_cmd: Array = views["q_cmd"]
        self.qd_cmd: Array = views["qd_cmd"]
        self.tcp: Array = views["tcp"]
        self.rot: Array = views["rot"]
        self.twist: Array = views["twist"]
        self.state: NDArray[np.int64] = views["state"]
        self.fault: NDArray[np.int64] = views["fault"]
        self.applied: Array | None = views.get("applied")

    @staticmethod
    def nbytes(size: int, n: int, with_truth: bool) -> int:
        """Bytes of memory a chunk of ``size`` rows needs."""
        return sum(8 * int(np.prod(shape)) for _, shape, _ in _layout(size, n, with_truth))

    @property
    def size(self) -> int:
        """Rows it holds."""
        return int(self.time.size)

    @property
    def layout(self) -> tuple[int, int, bool]:
        """Rows it holds, number of joints, whether it keeps the applied wrench."""
        return int(self.time.size), int(self.q.shape[1]), self.applied is not None

    @property
    def full(self) -> bool:
        """Every row is filled."""
        return self.rows == self.time.size

    def arrays(self) -> dict[str, NDArray[Any]]:
        """Its arrays by name (``time``, ``q``, ..., ``applied`` if kept), in memory order;
        each has one row per servo period."""
        return {name: getattr(self, name)
                for name, _, _ in _layout(0, 0, self.applied is not None)}

    def write(self, i: int, t: float, q: Array, current: Array, tau_ext: Array, wrench: Array,
              q_cmd: Array, qd_cmd: Array, transform: Array, twist: Array, state: int,
              fault: int, applied: Array | None) -> None:
        """Row ``i``: one servo period (copies into the existing arrays; ``rows`` unchanged).

        Args:
            i: Row, below :attr:`size`.
            t: Time [s].
            q: Measured joint positions [rad], shape (n,).
            current: Measured motor currents [A], shape (n,).
            tau_ext: Estimated external joint torque [N·m], shape (n,).
            wrench: Estimated TCP wrench, base axes [N, N·m], shape (6,).
            q_cmd: Joint position command [rad], shape (n,).
            qd_cmd: Joint velocity feed-forward [rad/s], shape (n,).
            transform: Commanded TCP pose in the base frame, 4x4 (translation in [m]).
            twist: Commanded TCP twist, base axes [m/s, rad/s], shape (6,).
            state: Safety state code.
            fault: Fault code.
            applied: The simulator's applied wrench [N, N·m], shape (6,), or None (kept only
                by a chunk that keeps it).
        """
        self.time[i] = t
        self.q[i] = q
        self.current[i] = current
        self.tau_ext[i] = tau_ext
        self.wrench[i] = wrench
        self.q_cmd[i] = q_cmd
        self.qd_cmd[i] = qd_cmd
        self.tcp[i] = transform[:3, 3]
        self.rot[i] = transform[:3, :3]
        self.twist[i] = twist
        self.state[i] = state
        self.fault[i] = fault
        if self.applied is not None and applied is not None:
            self.applied[i] = applied

    def copy_from(self, other: RecordChunk) -> None:
        """The filled rows of ``other`` (a chunk of the same layout) into this one."""
        self.rows = other.rows
        for name, array in other.arrays().items():
            getattr(self, name)[:other.rows] = array[:other.rows]

    def quaternions(self) -> Array:
        """The commanded TCP orientations of the filled rows, (x, y, z, w), shape (rows, 4)."""
        if self.rows == 0:
            return np.zeros((0, 4))
        return np.asarray(Rotation.from_matrix(self.rot[:self.rows]).as_quat())


class ChunkSink(Protocol):
    """Where full chunks go."""

    def empty(self) -> RecordChunk:
        """A chunk to fill first."""
        ...

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

    def empty(self) -> RecordChunk:
        """A new chunk."""
        return RecordChunk(self._rows, self._n, self._truth)

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
        chunk_rows: Rows per chunk of the default memory sink (a given sink sizes its own).
        events: The session's events list as the loop appends to it: each new one is handed
            to a sink that has a ``note_events`` method (a session file's sidecar, so that a
            killed session keeps its marks), checked once a period.
    """

    def __init__(self, n: int, with_truth: bool, sink: ChunkSink | None = None,
                 chunk_rows: int = DEFAULT_CHUNK_ROWS,
                 events: list[SessionEvent] | None = None) -> None:
        self.sink: ChunkSink = sink if sink is not None else MemorySink(n, with_truth,
                                                                          chunk_rows)
        self.chunk = self.sink.empty()
        if self.chunk.layout[1:] != (n, with_truth):
            raise DataError("the recording's sink holds another robot's rows", field="joints",
                            value=self.chunk.layout[1], expected=f"{n} joints, applied wrench "
                            f"{'kept' if with_truth else 'not kept'}")
        self.rows = 0
        note = getattr(self.sink, "note_events", None)
        self._note: Callable[[list[SessionEvent]], None] | None = note
        self._events = events if note is not None else None
        self._noted = 0

    def store(self, t: float, q: Array, current: Array, tau_ext: Array, wrench: Array,
              q_cmd: Array, qd_cmd: Array, transform: Array, twist: Array, state: int,
              fault: int, applied: Array | None) -> None:
        """Record one servo period (the arguments of :meth:`RecordChunk.write`)."""
        c = self.chunk
        i = c.rows
        c.write(i, t, q, current, tau_ext, wrench, q_cmd, qd_cmd, transform, twist, state,
                fault, applied)
        c.rows = i + 1
        self.rows += 1
        if self._events is not None and len(self._events) != self._noted:
            self._note_new()
        if c.rows == c.time.size:
            self.chunk = self.sink.take(c)

    def _note_new(self) -> None:
        assert self._events is not None and self._note is not None
        new = self._events[self._noted:]
        self._noted = len(self._events)
        self._note(new)

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> SessionLog | None:
        """The session is over: hand the last chunk to the sink and close it."""
        if self.chunk.rows > 0 or self.rows == 0:
            self.sink.take(self.chunk)
        return self.sink.finish(robot, events, settings)
