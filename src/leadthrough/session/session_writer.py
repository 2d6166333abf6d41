"""The session writer process's side of a recording streamed to disk: each chunk it is handed
becomes one Parquet row group of the partial file, the chunk goes back to the loop's process,
and at the end the events and settings go into the file's metadata and the file is moved into
place (``pyarrow.parquet.ParquetWriter``, https://arrow.apache.org/docs/python/parquet.html).
Meanwhile the session's metadata and each event as it comes go to the partial file's sidecar
(one JSON line each, flushed at once): what ``leadthrough recover`` needs when the loop's
process was killed. Both files are created new (``O_EXCL``, never through a symbolic link:
``O_NOFOLLOW``), with a normal file's mode.

The loop's side, and why a process, are in :mod:`leadthrough.session.session_file`; the link
(messages and shared chunks) in :mod:`leadthrough.session.writer_link`; the process's entry
point in :mod:`leadthrough.session.writer_process`, which imports this module only after it has
lowered its priority.
"""

from __future__ import annotations

import logging
import mmap
import os
import socket
from pathlib import Path
from typing import BinaryIO

import pyarrow as pa
import pyarrow.parquet as pq

from leadthrough.session.recorder import RecordChunk, chunks_to_log
from leadthrough.session.writer_link import SIDECAR_SUFFIX, recv_message, send_message
from leadthrough.session_format import session_columns

__all__ = ["serve_writer"]

log = logging.getLogger("leadthrough.session")


def serve_writer(sock: socket.socket, partial: Path, path: Path, n: int, with_truth: bool,
                 chunk_rows: int) -> int:
    """The writer process's work (see the module doc): write each chunk it is handed, return
    it, and finish the file when asked. Its exit code: 0 once the file is finished (or its
    failure reported), 1 when the loop's process went away first (the rows written are then
    closed into the partial file, without the session's events)."""
    chunks: dict[int, RecordChunk] = {}
    keep: list[mmap.mmap] = []
    nbytes = RecordChunk.nbytes(chunk_rows, n, with_truth)
    file = _ChunkFile(partial, n, with_truth)
    sidecar = _Sidecar(partial.with_name(partial.name + SIDECAR_SUFFIX))
    try:
        send_message(sock, ("ready",))
        while True:
            got = recv_message(sock)
            if got is None:
                break
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
            elif message[0] == "meta":
                sidecar.write([str(message[1])])
            elif message[0] == "events":
                sidecar.write([str(line) for line in message[1]])
            elif message[0] == "finish":
                error = file.finish(path, message[1])
                sidecar.close(remove=error is None)
                send_message(sock, ("done", file.rows_written, error))
                return 0
    except OSError:
        pass        # the loop's process is gone (a reset or broken link)
    file.abandon()
    sidecar.close(remove=False)
    return 1


def create_new(path: Path) -> int:
    """A new file at ``path`` for writing (refused if anything is there, a symbolic link
    included), with a normal file's mode: its descriptor.

    Raises:
        OSError: Something is in the way, or the folder is not writable.
    """
    return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                   | getattr(os, "O_CLOEXEC", 0), 0o666)


class _Sidecar:
    """The partial file's sidecar: JSON lines, each flushed as written (a killed loop's
    process loses none; the writer process's own death loses at most the line it wrote)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: BinaryIO | None = None
        self._failed = False

    def write(self, lines: list[str]) -> None:
        if self._failed:
            return
        try:
            if self._file is None:
                self._file = os.fdopen(create_new(self.path), "wb", buffering=0)
            self._file.write("".join(line + "\n" for line in lines).encode())
        except OSError as e:     # the rows go on; a recovery lacks the events
            log.error("session sidecar %s: %s (events are kept for the file's end only)",
                      self.path, e)
            self._failed = True

    def close(self, remove: bool) -> None:
        if self._file is not None:
            self._file.close()
            if remove:
                self.path.unlink(missing_ok=True)


class _ChunkFile:
    """The partial file, written chunk by chunk (the writer process's side)."""

    def __init__(self, partial: Path, n: int, with_truth: bool) -> None:
        self.partial, self._n, self._truth = partial, n, with_truth
        self._writer: pq.ParquetWriter | None = None
        self._sink: BinaryIO | None = None
        self.error: str | None = None
        self.rows_written = 0

    def write(self, chunk: RecordChunk) -> None:
        """One chunk as one row group (nothing after a failure)."""
        if self.error is not None:
            return
        try:
            table = pa.table(session_columns(chunks_to_log([chunk], self._truth, "", [], {})))
            if self._writer is None:
                self._sink = os.fdopen(create_new(self.partial), "wb")
                self._writer = pq.ParquetWriter(self._sink, table.schema)
            self._writer.write_table(table)
            self.rows_written += chunk.rows
        except (OSError, ValueError, pa.ArrowException) as e:   # ValueError: bad rows
            log.error("session file %s: %s: %s (the recording stops here)", self.partial,
                      type(e).__name__, e)
            self.error = f"{type(e).__name__}: {e}"

    def finish(self, path: Path, metadata: dict[bytes, bytes]) -> str | None:
        """The metadata written, the file closed and moved to ``path``; the failure, if any."""
        if self.error is None and self._writer is None:   # no rows: an empty session
            self.write(RecordChunk(0, self._n, self._truth))
        if self.error is not None or self._writer is None:
            return self.error
        try:
            self._writer.add_key_value_metadata(metadata)
            self._close()
            if path.is_symlink():
                raise OSError(f"{path} is a symbolic link: not written over")
            self.partial.replace(path)
        except (OSError, pa.ArrowException) as e:
            self.error = f"{type(e).__name__}: {e}"
        return self.error

    def abandon(self) -> None:
        """Close the rows written so far (the partial file stays, readable as Parquet)."""
        if self._writer is not None:
            try:
                self._close()
            except (OSError, pa.ArrowException) as e:
                log.error("session file %s: %s", self.partial, e)

    def _close(self) -> None:
        """The Parquet writer closed (its footer written), then the file (flushed)."""
        assert self._writer is not None and self._sink is not None
        try:
            self._writer.close()
        finally:
            self._sink.close()
