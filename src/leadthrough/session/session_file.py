"""A session recorded to its Parquet file as it runs, by a writer in its own process: memory
stays bounded for hours, and the loop's process does nothing but copy rows.

:class:`SessionFileSink` is a :class:`~leadthrough.session.recorder.ChunkSink`. Its chunks
(:mod:`leadthrough.session.recorder`, 10 s at 1 kHz) live in memory shared with a writer
process (:mod:`leadthrough.session.writer_link`, started with
:mod:`leadthrough.session.writer_process`). A full chunk is handed over by its index in one
short message; the writer (:mod:`leadthrough.session.session_writer`) turns it into one
Parquet row group and hands the chunk back. A few chunks
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
only when they are there; when none is back (the writer a minute behind), the rows are dropped
and counted (:attr:`SessionFileSink.dropped_rows`), never waited for.

Until the end the rows are in ``<path>.partial`` (a Parquet file has its index at its end: a
process killed outright leaves a partial file that is not readable as a session; Ctrl-C, a stop
request and every fault end the session normally and write the file; a writer whose loop's
process went away closes the rows it has, which then read with ``pyarrow`` but not as a
session). If the writer process dies or cannot write, the recording stops there, the loop goes
on, and :meth:`SessionFileSink.finish` raises.
"""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import time
from collections import deque
from pathlib import Path
from types import TracebackType
from typing import Any

import leadthrough
from leadthrough.errors import DataError
from leadthrough.session.record import SessionEvent, session_metadata
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk
from leadthrough.session.writer_link import (
    MessageReader,
    open_chunk_memory,
    recv_message,
    send_message,
)

__all__ = ["POOL_CHUNKS", "SessionFileSink"]

log = logging.getLogger("leadthrough.session")
#: Chunks mapped at the start (the writer may fall this many chunks behind: a minute at 1 kHz
#: with 10 000-row chunks) before rows are dropped.
POOL_CHUNKS = 6
#: How long the writer process may take to start (import NumPy and Arrow) [s].
_START_TIMEOUT_S = 60.0
#: How long the writer may go without a word while it finishes the file [s] (it answers
#: after every chunk it writes).
_FINISH_SILENCE_S = 60.0
#: How long a writer left without ``finish`` has to close the rows it wrote [s].
_CLOSE_WAIT_S = 5.0


class SessionFileSink:
    """Streams a session's chunks to ``path`` through a writer process (see the module doc).

    The loop's side (:meth:`empty`, :meth:`take`) never waits for the writer and maps no
    memory: all ``chunks`` are mapped here, before the loop (and before ``mlockall``, which
    would make a later mapping fault in every page at once). When none is back from the writer,
    the rows of the next chunk are dropped and counted (:attr:`dropped_rows`; logged, and kept
    in the file's settings as ``recording_rows_dropped``).

    Usable as a context manager: leaving it without :meth:`finish` ends the writer, which first
    closes the rows it wrote (the partial file then reads with ``pyarrow``, without the session's
    events).

    Args:
        path: The session's ``.parquet`` file (its folder must exist).
        n: Number of joints.
        with_truth: Chunks carry the simulator's applied wrench.
        chunk_rows: Rows per chunk.
        chunks: Chunks in shared memory (at least 2).

    Raises:
        DataError: Wrong suffix, missing folder, too few chunks, or the writer process did not
            start.
    """

    def __init__(self, path: str | Path, n: int, with_truth: bool = False,
                 chunk_rows: int = DEFAULT_CHUNK_ROWS, chunks: int = POOL_CHUNKS) -> None:
        self.path = Path(path).absolute()
        if self.path.suffix.lower() not in (".parquet", ".pq"):
            raise DataError("unsupported session file type", source=self.path, field="suffix",
                            value=self.path.suffix, expected=".parquet")
        if not self.path.parent.is_dir():
            raise DataError("folder does not exist", source=self.path,
                            expected="an existing folder for the session file")
        if chunks < 2:
            raise DataError("too few chunks for a recording", field="chunks", value=chunks,
                            expected="2 or more")
        self.partial = self.path.with_name(self.path.name + ".partial")
        self._n, self._truth, self._rows = n, with_truth, chunk_rows
        #: Rows the writer has written to the file so far (as of its last answer).
        self.rows_written = 0
        #: Rows dropped because no chunk was back from the writer.
        self.dropped_rows = 0
        self._chunks: list[RecordChunk] = []
        self._index: dict[int, int] = {}     # id(chunk) -> its index
        self._free: deque[int] = deque()
        self._scratch = RecordChunk(chunk_rows, n, with_truth)   # rows to drop go here
        self._filling = self._scratch      # the chunk last handed to the loop
        self._failure: str | None = None
        self._finished = False
        self._sock, self._process = _start_writer(self.partial, self.path, n, with_truth,
                                                  chunk_rows)
        try:
            for _ in range(chunks):
                self._free.append(self._map_chunk())
        except OSError as e:
            self.close()
            raise DataError(f"no shared memory for the recording ({e})", source=self.path,
                            field="chunks", value=chunks,
                            expected=f"{chunks} chunks of "
                                     f"{RecordChunk.nbytes(chunk_rows, n, with_truth)} bytes"
                            ) from e
        self._reader = MessageReader(self._sock)

    @property
    def writer_pid(self) -> int:
        """The writer process's id."""
        return self._process.pid

    def pending(self) -> int:
        """Chunks handed to the writer and not back yet (reads its answers; never waits)."""
        self._collect()
        in_hand = 0 if self._filling is self._scratch else 1   # the chunk the loop fills
        return len(self._chunks) - len(self._free) - in_hand

    def empty(self) -> RecordChunk:
        """The first chunk to fill."""
        return self._next()

    def take(self, chunk: RecordChunk) -> RecordChunk:
        """Hand ``chunk`` to the writer; an empty chunk to fill next: one the writer returned,
        or, when none is back, a scratch chunk whose rows will be dropped. Never waits; never
        raises for the writer's state. A chunk that is not this sink's (of the same layout) is
        copied into one of its own. After the writer failed the recording stops (rows go to the
        scratch chunk)."""
        self._collect()
        own = self._index.get(id(chunk))
        if self._failure is not None or chunk.rows == 0:
            if own is not None and self._failure is None:
                self._free.append(own)                 # an empty chunk of ours: back to the pool
        elif own is not None:
            self._send(("write", own, chunk.rows))
        elif chunk is not self._scratch and self._free and chunk.layout == self._scratch.layout:
            copy = self._free.popleft()
            self._chunks[copy].copy_from(chunk)
            self._send(("write", copy, chunk.rows))
        else:
            self._drop(chunk.rows)
        if own is None or self._failure is not None:
            chunk.rows = 0
        return self._next()

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> None:
        """Have the writer write what is queued, the events and settings, and move the file
        into place; waits for it.

        Raises:
            DataError: A setting that is not JSON, the file could not be written, or the writer
                process ended without writing it.
        """
        self._collect()
        if self.dropped_rows:
            log.warning("session file %s: %d rows dropped (the writer fell behind)",
                        self.path, self.dropped_rows)
            settings = {**settings, "recording_rows_dropped": self.dropped_rows}
        try:
            metadata = session_metadata(robot, self._n, events, settings)
        except (TypeError, ValueError) as e:
            self.close()
            raise DataError(f"the session's settings are not JSON ({e})", source=self.path,
                            field="settings", value=settings,
                            expected="str, int, float, bool, None, lists, dicts") from e
        if self._failure is None:
            self._sock.settimeout(_FINISH_SILENCE_S)     # off the loop: may wait
            try:
                send_message(self._sock, ("finish", metadata))
            except OSError as e:
                self._fail(f"the session writer process is gone ({e})")
            self._sock.setblocking(False)
        done = self._wait_for_done() if self._failure is None else None
        if done is not None:
            self.rows_written = int(done[1])
        error = self._failure if done is None else done[2]
        self._finished = error is None
        self.close()
        if error is not None:
            raise DataError(f"the session file was not finished ({error})",
                            source=self.partial, expected="a running writer that can write "
                            "to the folder")

    def close(self) -> None:
        """End the link to the writer and the writer with it (idempotent). A writer left
        before :meth:`finish` sees the link end, closes the rows it wrote and exits; one that
        does not within a few seconds is killed."""
        self._sock.close()
        if self._process.poll() is None:
            try:
                self._process.wait(timeout=_CLOSE_WAIT_S)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()

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

    def _next(self) -> RecordChunk:
        """A chunk to fill, emptied: one of the pool if one is back, else the scratch chunk."""
        if self._free and self._failure is None:
            chunk = self._chunks[self._free.popleft()]
        else:
            chunk = self._scratch
        chunk.rows = 0
        self._filling = chunk
        return chunk

    def _drop(self, rows: int) -> None:
        if self.dropped_rows == 0:
            log.warning("session file %s: the writer is behind, rows are dropped until a "
                        "chunk is back", self.path)
        self.dropped_rows += rows

    def _send(self, message: tuple[Any, ...]) -> None:
        try:
            send_message(self._sock, message)
        except OSError as e:      # the writer is gone
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

    def _wait_for_done(self) -> tuple[Any, ...] | None:
        """Wait for the writer's last answer (None: it ended or fell silent)."""
        last = time.monotonic()
        while True:
            if self._reader.wait(1.0):
                last = time.monotonic()
                done = self._handle(self._reader.poll())
                if done is not None:
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
    """Start the writer process (a session of its own: a signal to the terminal's or the
    service's process group does not reach it); the link to it and the process, once it said
    it is ready."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    env = dict(os.environ)
    root = str(Path(leadthrough.__file__).resolve().parent.parent)
    if root not in sys.path:       # leadthrough found through a path the child would not have
        env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("PYTHONPATH"), root) if p)
    command = [sys.executable, "-P", "-m", "leadthrough.session.writer_process",
               "--fd", str(theirs.fileno()), "--joints", str(n), "--rows", str(chunk_rows),
               *(["--truth"] if with_truth else []), "--", str(partial), str(path)]
    try:
        process = subprocess.Popen(command, pass_fds=(theirs.fileno(),), env=env,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   start_new_session=True)
    except OSError as e:
        ours.close()
        raise DataError(f"the session writer process could not start ({e})", source=path,
                        expected="a Python that can run leadthrough") from e
    finally:
        theirs.close()
    ours.settimeout(_START_TIMEOUT_S)
    why = "it ended"
    try:
        ready = recv_message(ours)
    except OSError as e:
        ready, why = None, str(e) or type(e).__name__
    if ready is None or ready[0] != ("ready",):
        process.kill()
        process.wait()
        ours.close()
        raise DataError(f"the session writer process did not start ({why})", source=path,
                        field="exit code", value=process.returncode,
                        expected=f"a ready writer within {_START_TIMEOUT_S:g} s")
    ours.settimeout(None)
    return ours, process
