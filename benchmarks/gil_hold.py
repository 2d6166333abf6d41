"""How long the loop's thread waits for the interpreter lock while a session streams to disk.

The loop's thread sleeps in its driver's ``recv`` and, when a packet comes, must take the
interpreter lock before it can answer; another thread of the process running Python code or a
long C call that keeps the lock (SciPy, NumPy on small arrays, building Arrow tables) delays
the answer. The session file is written by a process of its own
(:class:`~leadthrough.session.session_file.SessionFileSink`), which converts and writes a chunk
every 10 s. This script stands in for the loop with a thread that sleeps 1 ms and measures how
much later than asked it runs again, in one run, under:

* ``idle``: no other thread (the machine's own wake-up jitter);
* ``writer``: chunks of 10 000 rows (a 10 s chunk at 1 kHz) handed to the session file's
  writer process back to back, 10 ms apart (the hand-over runs in a thread of this process,
  as the loop's ``take`` would; the writer cannot keep up at that pace and the sink drops the
  rows of the chunks it has no room for, with a warning: the hand-overs go on as in a loop);
* ``in thread``: the same conversion and writing done by a thread of this process, as the
  session file did until 2026-11-28 (its share of the loop's timing was the reason for the
  process);
* ``one call``: the orientations of a 10 000-row chunk converted in one SciPy call in a thread.

    python benchmarks/gil_hold.py [--chunks 100] [--rt-priority 50]

It prints the wake-up delay's median, p99 and maximum [ms] per case, and the switch interval
the loop sets (:data:`~leadthrough.session.loop.GIL_SWITCH_S`).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy.spatial.transform import Rotation

from leadthrough.session.loop import GIL_SWITCH_S
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk, chunks_to_log
from leadthrough.session.session_file import SessionFileSink
from leadthrough.session_format import session_columns


def _probe(work: Callable[[], None], priority: int | None) -> np.ndarray:
    """Run ``work`` in a thread; meanwhile sleep 1 ms at a time (at SCHED_FIFO ``priority``
    if given, as the loop with ``--rt-priority``; ``work`` stays in the normal scheduler);
    the delays [ms]."""
    done = threading.Event()

    def run() -> None:
        try:
            work()
        finally:
            done.set()

    delays: list[float] = []
    thread = threading.Thread(target=run)
    thread.start()
    if priority is not None:   # this thread only (Linux: a thread's own policy)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    while not done.is_set():
        t = time.perf_counter()
        time.sleep(1e-3)
        delays.append((time.perf_counter() - t - 1e-3) * 1e3)
    if priority is not None:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    thread.join()
    return np.array(delays)


def _writer(chunks: int, folder: Path) -> Callable[[], None]:
    rot = Rotation.random(DEFAULT_CHUNK_ROWS, rng=1).as_matrix()
    q = np.random.default_rng(0).normal(size=(DEFAULT_CHUNK_ROWS, 6))
    sink = SessionFileSink(folder / "probe.parquet", 6)   # started before the probe

    def work() -> None:   # as the loop's thread: the chunk handed over (its rows filled once:
        filled = set()    # the loop fills a row per period, not 10 000 at once)
        chunk = sink.empty()
        for _ in range(chunks):
            if id(chunk) not in filled:
                chunk.q[:] = q
                chunk.rot[:] = rot
                filled.add(id(chunk))
            chunk.rows = DEFAULT_CHUNK_ROWS
            chunk = sink.take(chunk)
            time.sleep(0.01)
        sink.finish("probe", [], {})
    return work


def _in_thread(chunks: int, folder: Path) -> Callable[[], None]:
    chunk = RecordChunk(DEFAULT_CHUNK_ROWS, 6, False)
    chunk.q[:] = np.random.default_rng(0).normal(size=(DEFAULT_CHUNK_ROWS, 6))
    chunk.rot[:] = Rotation.random(DEFAULT_CHUNK_ROWS, rng=1).as_matrix()
    chunk.rows = DEFAULT_CHUNK_ROWS

    def table() -> pa.Table:
        return pa.table(session_columns(chunks_to_log([chunk], False, "", [], {})))

    def work() -> None:   # the former writer thread's work, chunk after chunk
        first = table()
        with pq.ParquetWriter(folder / "thread.parquet", first.schema) as writer:
            writer.write_table(first)
            for _ in range(chunks - 1):
                time.sleep(0.01)
                writer.write_table(table())
    return work


def _one_call(chunks: int) -> Callable[[], None]:
    rot = Rotation.random(DEFAULT_CHUNK_ROWS, rng=1).as_matrix()

    def work() -> None:
        for _ in range(chunks):
            Rotation.from_matrix(rot).as_quat()
            time.sleep(0.01)
    return work


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--chunks", type=int, default=100, help="chunks per case")
    parser.add_argument("--rt-priority", type=int, default=None, metavar="P",
                        help="the sleeping thread at SCHED_FIFO P (needs CAP_SYS_NICE)")
    args = parser.parse_args()
    switch = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_S)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            p = args.rt_priority
            cases = {"idle": _probe(lambda: time.sleep(0.01 * args.chunks), p),
                     "writer": _probe(_writer(args.chunks, Path(tmp)), p),
                     "in thread": _probe(_in_thread(args.chunks, Path(tmp)), p),
                     "one call": _probe(_one_call(args.chunks), p)}
    finally:
        sys.setswitchinterval(switch)
    print(f"switch interval {GIL_SWITCH_S * 1e3:.1f} ms; a thread sleeping 1 ms at a time, "
          f"delay behind the asked wake-up [ms]:")
    for name, d in cases.items():
        print(f"  {name:9s} median {np.median(d):.3f}  p99 {np.percentile(d, 99):.3f}  "
              f"max {d.max():.3f}  ({d.size} sleeps)")


if __name__ == "__main__":
    main()
