"""A session recorded to its Parquet file as it runs, by a writer in its own process: memory
stays bounded for hours, and the loop's process does nothing but copy rows.

:class:`SessionFileSink` is a :class:`~leadthrough.session.recorder.ChunkSink`. Its chunks
(:mod:`leadthrough.session.recorder`, 10 s at 1 kHz) live in memory shared with a writer
process (:mod:`leadthrough.session.writer_link`, started with
:mod:`leadthrough.session.writer_process`). A full chunk is handed over by its index in one
short message; the writer turns it into one Parquet row group (``pyarrow.parquet.ParquetWriter``,
https://arrow.apache.org/docs/python/parquet.html) and hands the chunk back. A few chunks
circulate, so memory is a handful of chunks whatever the session's length. At the end the
events (marks, transitions, the loop's notes) and settings go into the file's key-value metadata
and the file is moved into place: the result reads with
:func:`~leadthrough.session.record.load_session` like one written by
:func:`~leadthrough.session.record.save_session`.

Why a process: a writer thread of the loop's own process converted and wrote a chunk every 10 s
while holding Python's interpreter lock in steps of up to a few ms, and the loop's thread,
woken by the controller's packet, waited for it (measured: the loop's longest cycle 4.0 ms with
the writer thread, 0.8 ms without it, 4 minutes at 2 ms; ``benchmarks/gil_hold.py``). The
loop's side never waits on the writer: it sends without blocking and reads the returned chunks
only when they are there; when none is back (the writer behind), it maps one more chunk and
counts it (:attr:`SessionFileSink.extra_chunks`).

Until the end the rows are in ``<path>.partial`` (a Parquet file has its index at its end: a
process killed outright leaves a partial file that is not readable as a session; Ctrl-C, a stop
request and every fault end the session normally and write the file). If the writer process
dies or cannot write, the recording stops there, the loop goes on, and :meth:`finish` raises.
"""

from __future__ import annotations

import logging
import mmap
import os
import select
import socket
import subprocess
import sys
import time
from collections import deque
from pathlib import Path
from types import TracebackType
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

import leadthrough
from leadthrough.errors import DataError
from leadthrough.session.record import SessionEvent, session_columns, session_metadata
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk, chunks_to_log
from leadthrough.session.writer_link import (
    MessageReader,
    open_chunk_memory,
    recv_message,
    send_message,
)

__all__ = ["SessionFileSink", "serve_writer"]

log = logging.getLogger("leadthrough.session")
#: Chunks mapped at the start besides the one being filled.
_SPARE_CHUNKS = 3
#: How long the writer process may take to start (import NumPy and Arrow) [s].
_START_TIMEOUT_S = 60.0
#: How long the writer may go without a word while it finishes the file [s] (it answers
#: after every chunk it writes).
_FINISH_SILENCE_S = 60.0


class SessionFileSink:
    """Streams a session's chunks to ``path`` through a writer process (see the module doc).

    Usable as a context manager: leaving it without :meth:`finish` stops the writer (the rows
    written stay in the partial file).

    Args:
        path: The session's ``.parquet`` file (its folder must exist).
        n: Number of joints.
        with_truth: Chunks carry the simulator's applied wrench.
        chunk_rows: Rows per chunk.

    Raises:
        DataError: Wrong suffix, missing folder, or the writer process did not start.
    """

    def __init__(self, path: str | Path, n: int, with_truth: bool = False,
                 chunk_rows: int = DEFAULT_CHUNK_ROWS) -> None:
        self.path = Path(path)
        if self.path.suffix.lower() not in (".parquet", ".pq"):
            raise DataError("unsupported session file type", source=self.path, field="suffix",
                            value=self.path.suffix, expected=".parquet")
        if not self.path.parent.is_dir():
            raise DataError("folder does not exist", source=self.path,
                            expected="an existing folder for the session file")
        self.partial = self.path.with_name(self.path.name + ".partial")
        self._n, self._truth, self._rows = n, with_truth, chunk_rows
        #: Rows the writer has written to the file so far (as of its last answer).
        self.rows_written = 0
        #: Chunks mapped beyond the first ones (the writer fell behind).
        self.extra_chunks = 0
        self._chunks: list[RecordChunk] = []
        self._index: dict[int, int] = {}     # id(chunk) -> its index
        self._free: deque[int] = deque()
        self._failure: str | None = None
        self._finished = False
        self._sock, self._process = _start_writer(self.partial, self.path, n, with_truth,
                                                  chunk_rows)
        try:
            for _ in range(_SPARE_CHUNKS + 1):
                self._free.append(self._map_chunk())
        except OSError as e:
            self.close()
            raise DataError(f"the session writer process did not take its memory ({e})",
                            source=self.path, expected="a running writer process") from e
        self._reader = MessageReader(self._sock)

    @property
    def writer_pid(self) -> int:
        """The writer process's id."""
        return self._process.pid

    def empty(self) -> RecordChunk:
        """The first chunk to fill."""
        return self._chunks[self._next_free()]

    def take(self, chunk: RecordChunk) -> RecordChunk:
        """Hand ``chunk`` to the writer; an empty chunk to fill next (one the writer returned,
        or a new one when none is back yet). Never blocks. A chunk that is not this sink's is
        copied into one of its own first. After the writer failed, the recording stops:
        ``chunk`` comes back emptied."""
        self._collect()
        if self._failure is None:
            index = self._index.get(id(chunk))
            if index is None:        # not ours: copied into one of ours, and refilled
                index = self._next_free()
                if self._failure is None:
                    self._chunks[index].copy_from(chunk)
                    self._send(("write", index, chunk.rows))
            else:
                self._send(("write", index, chunk.rows))
                following = self._next_free()
                if self._failure is None:
                    return self._chunks[following]
        chunk.rows = 0
        return chunk

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> None:
        """Have the writer write what is queued, the events and settings, and move the file
        into place; waits for it.

        Raises:
            DataError: The file could not be written, or the writer process ended without
                writing it (the rows written so far stay in the partial file).
        """
        self._collect()
        if self._failure is None:
            self._send(("finish", robot, events, settings))
        done = self._wait_for("done") if self._failure is None else None
        if done is not None:
            self.rows_written = int(done[1])
        error = self._failure if done is None else done[2]
        self._finished = error is None
        self.close()
        if error is not None:
            raise DataError(f"the session file could not be written ({error})",
                            source=self.partial, expected="a writable folder")

    def close(self) -> None:
        """Stop the writer process if it still runs and close the link (idempotent)."""
        if self._process.poll() is None:
            try:
                self._process.wait(timeout=5.0 if self._finished else 0.0)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._sock.close()

    def __enter__(self) -> SessionFileSink:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    def _map_chunk(self) -> int:
        """A new chunk in shared memory, announced to the writer with its descriptor; its
        index."""
        fd, memory = open_chunk_memory(RecordChunk.nbytes(self._rows, self._n, self._truth))
        try:
            index = len(self._chunks)
            send_message(self._sock, ("chunk", index), (fd,))
        finally:
            os.close(fd)
        chunk = RecordChunk(self._rows, self._n, self._truth, memory)
        self._chunks.append(chunk)
        self._index[id(chunk)] = index
        return index

    def _next_free(self) -> int:
        """A chunk to fill (emptied): one the writer returned, or a new one."""
        if self._free:
            index = self._free.popleft()
            self._chunks[index].rows = 0
            return index
        try:
            index = self._map_chunk()
        except OSError as e:
            self._fail(f"no memory for another chunk ({e})")
            return 0
        self.extra_chunks += 1
        return index

    def _send(self, message: tuple[Any, ...]) -> None:
        try:
            send_message(self._sock, message)
        except OSError as e:      # the writer is gone (or stopped reading: its queue is full)
            self._fail(f"the session writer process is gone ({e})")

    def _collect(self) -> None:
        """The writer's answers so far: returned chunks, rows written; never waits."""
        self._handle(self._reader.poll())
        if self._reader.closed and self._failure is None:
            self._fail(f"the session writer process ended (exit code {self._process.poll()})")

    def _handle(self, messages: list[tuple[Any, ...]]) -> tuple[Any, ...] | None:
        done = None
        for message in messages:
            if message[0] == "free":
                self._free.append(int(message[1]))
                self.rows_written = int(message[2])
            elif message[0] == "done":
                done = message
        return done

    def _wait_for(self, kind: str) -> tuple[Any, ...] | None:
        """Wait for the writer's ``kind`` answer (None: it ended or fell silent)."""
        last = time.monotonic()
        while True:
            ready, _, _ = select.select([self._sock], [], [], 1.0)
            if ready:
                last = time.monotonic()
                done = self._handle(self._reader.poll())
                if done is not None and done[0] == kind:
                    return done
                if self._reader.closed:
                    self._fail(f"the session writer process ended (exit code "
                               f"{self._process.poll()})")
                    return None
            elif time.monotonic() - last > _FINISH_SILENCE_S:
                self._fail(f"the session writer said nothing for {_FINISH_SILENCE_S:g} s")
                return None

    def _fail(self, reason: str) -> None:
        if self._failure is None:
            log.error("session file %s: %s (the recording stops here)", self.partial, reason)
            self._failure = reason


def _start_writer(partial: Path, path: Path, n: int, with_truth: bool, chunk_rows: int
                  ) -> tuple[socket.socket, subprocess.Popen[bytes]]:
    """Start the writer process; the link to it and the process, once it said it is ready."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    root = str(Path(leadthrough.__file__).resolve().parent.parent)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    command = [sys.executable, "-m", "leadthrough.session.writer_process",
               "--fd", str(theirs.fileno()), "--joints", str(n), "--rows", str(chunk_rows),
               *(["--truth"] if with_truth else []), str(partial), str(path)]
    try:
        process = subprocess.Popen(command, pass_fds=(theirs.fileno(),), env=env,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    except OSError as e:
        ours.close()
        raise DataError(f"the session writer process could not start ({e})", source=path,
                        expected="a Python that can run leadthrough") from e
    finally:
        theirs.close()
    ours.settimeout(_START_TIMEOUT_S)
    try:
        ready = recv_message(ours)
    except OSError:
        ready = None
    if ready is None or ready[0] != ("ready",):
        process.kill()
        process.wait()
        ours.close()
        raise DataError("the session writer process did not start", source=path,
                        value=process.returncode,
                        expected=f"a ready writer within {_START_TIMEOUT_S:g} s")
    ours.settimeout(None)
    return ours, process


def serve_writer(sock: socket.socket, partial: Path, path: Path, n: int, with_truth: bool,
                 chunk_rows: int) -> int:
    """The writer process's work (see the module doc): write each chunk it is handed, return
    it, and finish the file when asked. Its exit code: 0 once the file is finished (or its
    failure reported), 1 when the loop's process went away first."""
    chunks: dict[int, RecordChunk] = {}
    keep: list[mmap.mmap] = []
    nbytes = RecordChunk.nbytes(chunk_rows, n, with_truth)
    file = _ChunkFile(partial, n, with_truth)
    send_message(sock, ("ready",))
    while True:
        got = recv_message(sock)
        if got is None:
            return 1
        message, fds = got
        if message[0] == "chunk":
            memory = mmap.mmap(fds[0], nbytes)
            os.close(fds[0])
            keep.append(memory)
            chunks[int(message[1])] = RecordChunk(chunk_rows, n, with_truth, memory)
        elif message[0] == "write":
            chunk = chunks[int(message[1])]
            chunk.rows = int(message[2])
            file.write(chunk)
            chunk.rows = 0
            send_message(sock, ("free", message[1], file.rows_written))
        elif message[0] == "finish":
            error = file.finish(path, *message[1:])
            send_message(sock, ("done", file.rows_written, error))
            return 0


class _ChunkFile:
    """The partial file, written chunk by chunk (the writer process's side)."""

    def __init__(self, partial: Path, n: int, with_truth: bool) -> None:
        self.partial, self._n, self._truth = partial, n, with_truth
        self._writer: pq.ParquetWriter | None = None
        self.error: str | None = None
        self.rows_written = 0

    def write(self, chunk: RecordChunk) -> None:
        """One chunk as one row group (nothing after a failure)."""
        if self.error is not None:
            return
        try:
            table = pa.table(session_columns(chunks_to_log([chunk], self._truth, "", [], {})))
            if self._writer is None:
                self._writer = pq.ParquetWriter(self.partial, table.schema)
            self._writer.write_table(table)
            self.rows_written += chunk.rows
        except (OSError, ValueError, pa.ArrowException) as e:   # ValueError: bad rows
            log.error("session file %s: %s (the recording stops here)", self.partial, e)
            self.error = str(e)

    def finish(self, path: Path, robot: str, events: list[SessionEvent],
               settings: dict[str, object]) -> str | None:
        """The metadata written, the file closed and moved to ``path``; the failure, if any."""
        if self.error is None and self._writer is None:   # no rows: an empty session
            self.write(RecordChunk(0, self._n, self._truth))
        if self.error is not None or self._writer is None:
            return self.error
        try:
            self._writer.add_key_value_metadata(session_metadata(robot, self._n, events,
                                                                 settings))
            self._writer.close()
            self.partial.replace(path)
        except (OSError, pa.ArrowException) as e:
            self.error = str(e)
        return self.error
