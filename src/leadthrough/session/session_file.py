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
:func:`~leadthrough.session_format.load_session` like one written by
:func:`~leadthrough.session_format.save_session`.

Why a process: a writer thread of the loop's own process converted and wrote a chunk every 10 s
while holding Python's interpreter lock in steps of up to a few ms, and the loop's thread,
woken by the controller's packet, waited for it (measured: the loop's longest cycle 4.0 ms with
the writer thread, 0.8 ms without it, 4 minutes at 2 ms; ``benchmarks/gil_hold.py``). The
loop's side never waits on the writer: it sends without blocking and reads the returned chunks
only when they are there; when none is back (the writer a minute behind), the rows are dropped
and counted (:attr:`SessionFileSink.dropped_rows`), never waited for.

Until the end the rows are in ``<path>.partial`` (a Parquet file has its index at its end),
and the session's metadata (robot, joints, settings) and its events, each as it comes (a mark
as it is made), in ``<path>.partial.jsonl`` (one JSON object a line: the first the metadata,
then one event a line; :data:`SIDECAR_SUFFIX`). Ctrl-C, a stop request and every fault end the
session normally and write the file (the sidecar is then removed). A loop's process killed
outright (SIGKILL, a power cut of the process) leaves both: its writer process, in a session of
its own, sees the link end and closes the rows it has into the partial file, and
``leadthrough recover <path>.partial -o <path>``
(:func:`~leadthrough.session.session_file.recover_session`) joins them into a session file
that reads like any other. (A writer process killed too leaves a partial file without its
index, which no Parquet reader reads: recover says so.) If the writer process dies or cannot
write, the recording stops there, the loop goes on, and :meth:`SessionFileSink.finish` raises.

Neither the session file nor its partial files are written through or over a symbolic link,
and a partial file left by an earlier session is not overwritten (recover it, or remove it):
both are refused before the session starts.
"""

from __future__ import annotations

import json
import logging
import math
import os
import socket
import subprocess
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import leadthrough
from leadthrough.errors import DataError
from leadthrough.fileio import atomic_write, refuse_symlink, require_file
from leadthrough.labels import check_label
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk
from leadthrough.session.writer_link import (
    SIDECAR_SUFFIX,
    MessageReader,
    open_chunk_memory,
    recv_message,
    send_message,
)
from leadthrough.session_format import (
    FORMAT_VERSION,
    SessionEvent,
    load_session,
    session_metadata,
)

__all__ = ["POOL_CHUNKS", "SIDECAR_SUFFIX", "RecoveredSession", "SessionFileSink",
           "recover_session"]

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
        robot: The robot's name, for the sidecar (what a recovery needs; None: a recovery
            must be told it).
        settings: The session's settings as known at the start, for the sidecar (JSON).

    Raises:
        DataError: Wrong suffix, missing folder, a symbolic link at the file's or a partial
            file's place, a partial file of an earlier session in the way, too few chunks,
            settings that are not JSON, or the writer process did not start.
    """

    def __init__(self, path: str | Path, n: int, with_truth: bool = False,
                 chunk_rows: int = DEFAULT_CHUNK_ROWS, chunks: int = POOL_CHUNKS, *,
                 robot: str | None = None, settings: dict[str, object] | None = None) -> None:
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
        #: The sidecar of metadata and events (removed once the file is finished).
        self.sidecar = self.partial.with_name(self.partial.name + SIDECAR_SUFFIX)
        refuse_symlink(self.path)
        for left in (self.partial, self.sidecar):
            if left.is_symlink() or left.exists():
                raise DataError("a partial file of an earlier session is in the way",
                                source=left, expected="no file there: recover the session "
                                f"(leadthrough recover {self.partial} -o <file>) or remove it")
        try:
            header = json.dumps({"format": FORMAT_VERSION, "robot": robot, "n": n,
                                 "settings": settings or {}})
        except (TypeError, ValueError) as e:
            raise DataError(f"the session's settings are not JSON ({e})", source=self.path,
                            field="settings", value=settings,
                            expected="str, int, float, bool, None, lists, dicts") from e
        #: The events noted so far (:meth:`note_events`), and at the end all of them.
        self.events: list[SessionEvent] = []
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
        self._send(("meta", header))

    def note_events(self, events: list[SessionEvent]) -> None:
        """New events of the session (a mark, a transition), handed to the writer for the
        sidecar as they come; never waits (one short message)."""
        self.events.extend(events)
        if self._failure is None:
            self._send(("events", [json.dumps(asdict(e)) for e in events]))

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
        self.events = list(events)
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
        if self._failure is None and self.path.is_symlink():   # one appeared meanwhile
            self._fail(f"{self.path} became a symbolic link during the session: not written "
                       "over")
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


@dataclass(frozen=True)
class RecoveredSession:
    """What :func:`recover_session` wrote.

    Attributes:
        path: The session file.
        robot: Its robot.
        rows: Servo periods recovered.
        events: Events recovered (marks, transitions, the loop's notes).
        marks: Marks among them.
        sidecar: Whether the partial file's sidecar was there (without it: no events).
        dropped_line: A last sidecar line cut off mid-write, dropped (the process was killed
            while writing it).
        dropped_events: Labels of the events after the last recovered row, dropped (the rows
            of the chunk being filled when the process died are lost, up to
            :data:`~leadthrough.session.recorder.DEFAULT_CHUNK_ROWS` periods).
    """

    path: Path
    robot: str
    rows: int
    events: int
    marks: int
    sidecar: bool
    dropped_line: bool
    dropped_events: list[str]


def recover_session(partial: str | Path, path: str | Path, robot: str | None = None
                    ) -> RecoveredSession:
    """A session cut short (its process killed), written as a normal session file.

    Reads the rows the writer process closed into ``partial`` (``<session>.parquet.partial``)
    and the metadata and events of its sidecar (``<partial>.jsonl``), checks them (the
    columns of a session, the joints, the robot, every mark label), and writes ``path``
    atomically: it reads with :func:`~leadthrough.session_format.load_session` (checked before
    it is moved into place) like one finished normally, its settings noting the recovery. The
    partial file and its sidecar are removed once ``path`` is in place.

    Args:
        partial: The partial file.
        path: The session file to write (``.parquet``).
        robot: The robot's name, needed only when the sidecar is missing (else checked
            against it).

    Returns:
        What was recovered.

    Raises:
        DataError: ``partial`` missing or unreadable as Parquet (the writer process was killed
            too: the file lacks its index), not a session's rows, a sidecar line that is not
            one of a session's, a robot that differs from the sidecar's, or no robot to be
            had; ``path`` not a ``.parquet`` file, a symbolic link, or the partial file.
        LabelError: A mark label in the sidecar that is not a label.
    """
    partial, path = Path(partial), Path(path)
    require_file(partial, "partial session file",
                 "the <session>.parquet.partial file a session cut short left")
    sidecar = partial.with_name(partial.name + SIDECAR_SUFFIX)
    if path.suffix.lower() not in (".parquet", ".pq"):
        raise DataError("unsupported session file type", source=path, field="suffix",
                        value=path.suffix or "(none)", expected=".parquet")
    for given in (partial, sidecar):
        if path.resolve() == given.resolve():
            raise DataError("the output would overwrite the partial session", source=path,
                            field="-o", value=str(path), expected="another file")
    table = _read_partial_rows(partial)
    names = table.column_names
    n = sum(1 for c in names if c.startswith("q_") and c[2:].isdigit())
    header, events, dropped = (_read_sidecar(sidecar) if sidecar.is_file()
                               else ({}, [], False))
    if header:
        if int(header["n"]) != n:
            raise DataError("the sidecar's joints do not match the rows", source=sidecar,
                            field="n", value=header["n"], expected=f"{n} (the rows' q_ columns)")
        if robot is not None and header.get("robot") not in (None, robot):
            raise DataError("the sidecar names another robot", source=sidecar, field="robot",
                            value=header.get("robot"), expected=f"'{robot}' (as given)")
        robot = robot if header.get("robot") is None else str(header["robot"])
    if robot is None:
        raise DataError("no robot to be had: the sidecar with the session's robot is "
                        + ("missing" if not sidecar.is_file() else "without one"),
                        source=sidecar, field="robot",
                        expected="--robot NAME (the robot the session ran on)")
    # the rows of the chunk being filled when the process died are lost: a mark made then
    # names a pose the recording lacks (teach would take another sample for it)
    times = table.column("t").to_numpy() if "t" in names and table.num_rows else np.zeros(0)
    last = float(times[-1]) if times.size else -math.inf
    late = [e for e in events if e.t > last]
    events = sorted((e for e in events if e.t <= last), key=lambda e: e.t)
    settings = {**dict(header.get("settings") or {}), "recovered_from": partial.name,
                "recovered_rows": table.num_rows, "recovered_events": len(events),
                "recovered_events_dropped": len(late)}
    table = table.replace_schema_metadata(session_metadata(robot, n, events, settings))

    def write(tmp: Path) -> None:
        pq.write_table(table, tmp)
        load_session(tmp)        # a session file in every respect, or nothing is written

    atomic_write(path, write)
    for left in (partial, sidecar):
        left.unlink(missing_ok=True)
    return RecoveredSession(path=path, robot=robot, rows=table.num_rows, events=len(events),
                            marks=sum(e.kind == "mark" for e in events),
                            sidecar=bool(header), dropped_line=dropped,
                            dropped_events=[e.label for e in late])


def _read_partial_rows(partial: Path) -> pa.Table:
    """The rows a session's writer closed into its partial file.

    Raises:
        DataError: Not readable as Parquet (no footer: the writer was killed too).
    """
    try:
        return pq.read_table(partial)
    except (OSError, pa.ArrowException) as e:
        raise DataError(f"not readable as Parquet ({e}): its rows were never closed (the "
                        "session writer process was killed too), or it is not a session's",
                        source=partial, expected="the partial file of a session whose loop's "
                        "process ended (its writer closes the rows it has)") from e


def _read_sidecar(sidecar: Path) -> tuple[dict[str, Any], list[SessionEvent], bool]:
    """The header, the events and whether a last line cut off mid-write was dropped.

    Raises:
        DataError: A line that is not a session's header or event.
        LabelError: A mark label that is not a label.
    """
    raw = sidecar.read_bytes()
    lines = raw.split(b"\n")
    dropped = bool(lines[-1])      # no newline after the last: cut off mid-write
    lines = lines[:-1]
    if not lines:
        raise DataError("empty sidecar", source=sidecar,
                        expected="the session's metadata on its first line")
    header: dict[str, Any] = {}
    events: list[SessionEvent] = []
    for k, line in enumerate(lines, 1):
        try:
            obj = json.loads(line.decode("utf-8"))
            if k == 1:
                if not (isinstance(obj, dict) and obj.get("format") == FORMAT_VERSION
                        and isinstance(obj.get("n"), int) and isinstance(
                            obj.get("settings", {}), dict)
                        and isinstance(obj.get("robot"), str | None)):
                    raise ValueError("not a session's metadata")
                header = obj
                continue
            event = SessionEvent(**obj)
            if not (isinstance(event.t, int | float) and math.isfinite(event.t)
                    and all(isinstance(x, str) for x in (event.kind, event.label,
                                                         event.cause))):
                raise ValueError("not a session's event")
        except (ValueError, TypeError, UnicodeDecodeError) as e:
            raise DataError(f"malformed sidecar line ({e})", source=sidecar,
                            field=f"line {k}", value=line[:80].decode("utf-8", "replace"),
                            expected="the session's metadata (line 1), then one event a "
                                     "line {t, kind, label, cause}") from e
        if event.kind == "mark":
            check_label(event.label, source=sidecar, field=f"line {k} label")
        events.append(SessionEvent(float(event.t), event.kind, event.label, event.cause))
    return header, events, dropped
