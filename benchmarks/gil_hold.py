"""How long the loop's thread waits for the interpreter lock while a session streams to disk.

The loop's thread sleeps in its driver's ``recv`` and, when a packet comes, must take the
interpreter lock before it can answer; another thread of the process running Python code or a
long C call that keeps the lock (SciPy, NumPy on small arrays, building Arrow tables) delays
the answer. The session file's writer thread
(:class:`~leadthrough.session.session_file.SessionFileSink`) converts and writes a chunk every
10 s. This script stands in for the loop with a thread that sleeps 1 ms and measures how much
later than asked it runs again, in one run, under:

* ``idle``: no other thread (the machine's own wake-up jitter);
* ``writer``: the session file's writer converting and writing 10 000-row chunks (a 10 s chunk
  at 1 kHz) back to back, 10 ms apart;
* ``one call``: the orientations of a 10 000-row chunk converted in one SciPy call, as the
  writer did before :data:`~leadthrough.session.recorder.QUATERNION_SLICE_ROWS`.

    python benchmarks/gil_hold.py [--chunks 100]

It prints the wake-up delay's median, p99 and maximum [ms] per case, and the switch interval
the loop sets (:data:`~leadthrough.session.loop.GIL_SWITCH_S`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from leadthrough.session.loop import GIL_SWITCH_S
from leadthrough.session.recorder import DEFAULT_CHUNK_ROWS, RecordChunk
from leadthrough.session.session_file import SessionFileSink


def _probe(work: Callable[[], None]) -> np.ndarray:
    """Run ``work`` in a thread; meanwhile sleep 1 ms at a time; the delays [ms]."""
    done = threading.Event()

    def run() -> None:
        try:
            work()
        finally:
            done.set()

    delays: list[float] = []
    thread = threading.Thread(target=run)
    thread.start()
    while not done.is_set():
        t = time.perf_counter()
        time.sleep(1e-3)
        delays.append((time.perf_counter() - t - 1e-3) * 1e3)
    thread.join()
    return np.array(delays)


def _writer(chunks: int, folder: Path) -> Callable[[], None]:
    rot = Rotation.random(DEFAULT_CHUNK_ROWS, rng=1).as_matrix()
    q = np.random.default_rng(0).normal(size=(DEFAULT_CHUNK_ROWS, 6))

    def work() -> None:   # as the loop's thread: a few copies, then the chunk handed over
        sink = SessionFileSink(folder / "probe.parquet", 6)
        chunk = RecordChunk(DEFAULT_CHUNK_ROWS, 6, False)
        for _ in range(chunks):
            chunk.q[:] = q
            chunk.rot[:] = rot
            chunk.rows = DEFAULT_CHUNK_ROWS
            chunk = sink.take(chunk)
            time.sleep(0.01)
        sink.finish("probe", [], {})
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
    args = parser.parse_args()
    switch = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_S)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            cases = {"idle": _probe(lambda: time.sleep(0.01 * args.chunks)),
                     "writer": _probe(_writer(args.chunks, Path(tmp))),
                     "one call": _probe(_one_call(args.chunks))}
    finally:
        sys.setswitchinterval(switch)
    print(f"switch interval {GIL_SWITCH_S * 1e3:.1f} ms; a thread sleeping 1 ms at a time, "
          f"delay behind the asked wake-up [ms]:")
    for name, d in cases.items():
        print(f"  {name:9s} median {np.median(d):.3f}  p99 {np.percentile(d, 99):.3f}  "
              f"max {d.max():.3f}  ({d.size} sleeps)")


if __name__ == "__main__":
    main()
