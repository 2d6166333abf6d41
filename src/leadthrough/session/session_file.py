"""A session recorded to its Parquet file as it runs: memory stays bounded for hours.

:class:`SessionFileSink` is a :class:`~leadthrough.session.recorder.ChunkSink`: each full chunk
of the loop's recording (:mod:`leadthrough.session.recorder`, 10 s at 1 kHz) is handed to a
writer thread that appends it to the file as one Parquet row group
(``pyarrow.parquet.ParquetWriter``, https://arrow.apache.org/docs/python/parquet.html); the
loop's thread only swaps chunks (a few chunks are recycled between the two threads, so the
memory is a handful of chunks whatever the session's length). At the end the events (marks,
transitions, the loop's notes) and settings go into the file's key-value metadata and the file
is moved into place: the result reads with :func:`~leadthrough.session.record.load_session`
like one written by :func:`~leadthrough.session.record.save_session`.

Until the end the rows are in ``<path>.partial`` (a Parquet file has its index at its end: a
process killed outright leaves a partial file that is not readable as a session; Ctrl-C, a stop
request and every fault end the session normally and write the file).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from leadthrough.errors import DataError
from leadthrough.session.record import SessionEvent, session_columns, session_metadata
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk, chunks_to_log

__all__ = ["SessionFileSink"]

log = logging.getLogger("leadthrough.session")
_SPARE_CHUNKS = 3


class SessionFileSink:
    """Streams a session's chunks to ``path`` (see the module doc).

    Args:
        path: The session's ``.parquet`` file (its folder must exist).
        n: Number of joints.
        with_truth: Chunks carry the simulator's applied wrench.
        chunk_rows: Rows per chunk.

    Raises:
        DataError: Wrong suffix or missing folder.
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
        self._spare: queue.SimpleQueue[RecordChunk] = queue.SimpleQueue()
        for _ in range(_SPARE_CHUNKS):
            self._spare.put(RecordChunk(chunk_rows, n, with_truth))
        self._full: queue.SimpleQueue[RecordChunk | None] = queue.SimpleQueue()
        self._writer: pq.ParquetWriter | None = None
        self._error: BaseException | None = None
        #: Rows written to the file so far.
        self.rows_written = 0
        #: Chunks allocated beyond the recycled ones (the writer fell behind).
        self.extra_chunks = 0
        self._thread = threading.Thread(target=self._write_all, name="leadthrough-recorder",
                                        daemon=True)
        self._thread.start()

    def take(self, chunk: RecordChunk) -> RecordChunk:
        """Queue ``chunk`` for writing; an empty chunk to fill next (a recycled one)."""
        self._full.put(chunk)
        try:
            return self._spare.get_nowait()
        except queue.Empty:
            self.extra_chunks += 1
            return RecordChunk(self._rows, self._n, self._truth)

    def finish(self, robot: str, events: list[SessionEvent], settings: dict[str, object]
               ) -> None:
        """Write what is queued, the events and settings, and move the file into place.

        Raises:
            DataError: The file could not be written (the rows written so far stay in the
                partial file).
        """
        self._full.put(None)
        self._thread.join()
        if self._error is not None:
            raise DataError(f"the session file could not be written ({self._error})",
                            source=self.partial, expected="a writable folder") from self._error
        if self._writer is None:     # no rows at all: an empty session, as save_session writes
            self._write(RecordChunk(0, self._n, self._truth))
        assert self._writer is not None
        self._writer.add_key_value_metadata(session_metadata(robot, self._n, events, settings))
        self._writer.close()
        self.partial.replace(self.path)

    def _write_all(self) -> None:
        """The writer thread: each queued chunk into the file, the chunk back to the spares."""
        while True:
            chunk = self._full.get()
            if chunk is None:
                return
            if self._error is None:
                try:
                    self._write(chunk)
                except (OSError, pa.ArrowException) as e:
                    log.error("session file %s: %s (the recording stops here)", self.partial, e)
                    self._error = e
            chunk.rows = 0
            self._spare.put(chunk)

    def _write(self, chunk: RecordChunk) -> None:
        """One chunk as one row group. Each step holds the interpreter lock briefly and offers
        it between steps (``sleep(0)``): the loop's thread, waking for a packet, waits for
        the lock while this thread runs Python code (see
        :data:`~leadthrough.session.recorder.QUATERNION_SLICE_ROWS`)."""
        log = chunks_to_log([chunk], self._truth, "", [], {})
        time.sleep(0)
        columns = session_columns(log)
        time.sleep(0)
        table = pa.table(columns)
        time.sleep(0)
        if self._writer is None:
            self._writer = pq.ParquetWriter(self.partial, table.schema)
        self._writer.write_table(table)
        self.rows_written += chunk.rows

