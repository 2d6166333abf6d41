"""State the loop's process publishes to the pendant's process in shared memory, lock-free.

Three kinds of state, each in a block of :mod:`multiprocessing.shared_memory` that the pendant
creates and the loop's process attaches to by name:

* :class:`SeqlockRecord`: the latest snapshot, a fixed array of numbers written every controller
  cycle and a byte string (pickled) rewritten only when it changes. A sequence lock (Linux
  kernel, ``include/linux/seqlock.h``; Lameter, "Effective synchronization on Linux/NUMA
  systems", 2005): the writer makes the counter odd, writes, makes it even; a reader copies and
  keeps the copy only when the counter was even and unchanged around it. The writer never
  waits; a reader retries. Each part also carries its CRC-32, checked by the reader, so that a
  copy torn on a processor that reorders stores (this code has no memory barriers) is refused
  too;
* :class:`PeriodRing`: the timing of the last servo periods (written by the loop, a counter
  advanced after each entry);
* the live recording's rows (:mod:`leadthrough.pendant.live_recording`), a ring of the loop
  recorder's rows in a block.
"""

from __future__ import annotations

import contextlib
import time
import zlib
from multiprocessing import shared_memory

import numpy as np
from numpy.typing import NDArray

__all__ = ["PeriodRing", "SeqlockRecord", "SharedBlock"]

_HEAD = 4          # sequence, blob length, numbers' CRC, blob's CRC (int64 each)


class SharedBlock:
    """A block of shared memory: created (``name=None``) or attached by name.

    Args:
        size: Bytes (to create).
        name: The block's name (to attach).
    """

    def __init__(self, size: int = 0, name: str | None = None) -> None:
        self.owner = name is None
        self.shm = shared_memory.SharedMemory(name=name, create=self.owner, size=max(size, 8))

    @property
    def name(self) -> str:
        """The block's name, for the other process."""
        return self.shm.name

    def close(self, unlink: bool | None = None) -> None:
        """Unmap the block; the creator also removes it (default)."""
        with contextlib.suppress(BufferError):   # arrays still view it: unmapped at exit
            self.shm.close()
        if self.owner if unlink is None else unlink:
            with contextlib.suppress(FileNotFoundError):
                self.shm.unlink()


class SeqlockRecord:
    """The latest of a series of records: ``numbers`` float64 and up to ``blob_bytes`` bytes.

    Args:
        block: Its memory (at least :meth:`size` bytes).
        numbers: Numbers per record.
        blob_bytes: Capacity of the byte string.
    """

    def __init__(self, block: SharedBlock, numbers: int, blob_bytes: int) -> None:
        buf = block.shm.buf
        self._head = np.ndarray((_HEAD,), np.int64, buf, 0)
        self._numbers = np.ndarray((numbers,), np.float64, buf, 8 * _HEAD)
        self._blob = np.ndarray((blob_bytes,), np.uint8, buf, 8 * (_HEAD + numbers))
        self._cache: tuple[int, int, bytes] | None = None

    @staticmethod
    def size(numbers: int, blob_bytes: int) -> int:
        """Bytes a record of this shape needs."""
        return 8 * (_HEAD + numbers) + blob_bytes

    def write(self, numbers: NDArray[np.float64], blob: bytes | None = None) -> None:
        """Publish ``numbers`` and, unless None, a new ``blob`` (one writer only; never waits).

        Raises:
            ValueError: ``blob`` longer than the capacity.
        """
        if blob is not None and len(blob) > self._blob.size:
            raise ValueError(f"record of {len(blob)} bytes, capacity {self._blob.size}")
        head = self._head
        head[0] += 1                                      # odd: being written
        self._numbers[:] = numbers
        head[2] = zlib.crc32(self._numbers.data)
        if blob is not None:
            self._blob[:len(blob)] = np.frombuffer(blob, np.uint8)
            head[1] = len(blob)
            head[3] = zlib.crc32(blob)
        head[0] += 1                                      # even: complete

    def read(self, tries: int = 1000) -> tuple[int, NDArray[np.float64], bytes] | None:
        """The latest complete record: (sequence, numbers, blob); None if nothing was written
        yet or no complete copy was had in ``tries`` attempts (a writer that died mid-write)."""
        head = self._head
        for _ in range(tries):
            seq = int(head[0])
            if seq == 0:
                return None
            if seq % 2 == 0:
                numbers = self._numbers.copy()
                length, crc_n, crc_b = int(head[1]), int(head[2]), int(head[3])
                blob = self._blob_copy(length, crc_b)
                if int(head[0]) == seq and zlib.crc32(numbers.data) == crc_n and blob is not None:
                    return seq, numbers, blob
            time.sleep(0)
        return None

    def _blob_copy(self, length: int, crc: int) -> bytes | None:
        """The blob (a cached copy while its CRC is unchanged), or None if torn."""
        if not 0 <= length <= self._blob.size:
            return None
        cache = self._cache
        if cache is not None and cache[:2] == (length, crc):
            return cache[2]
        blob = self._blob[:length].tobytes()
        if zlib.crc32(blob) != crc:
            return None
        self._cache = (length, crc, blob)
        return blob


class PeriodRing:
    """The timing of the last ``size`` servo periods: work and completion [µs].

    Args:
        block: Its memory (at least :meth:`nbytes` bytes).
        size: Periods kept.
    """

    def __init__(self, block: SharedBlock, size: int) -> None:
        buf = block.shm.buf
        self._count = np.ndarray((1,), np.int64, buf, 0)
        self.work_us = np.ndarray((size,), np.float64, buf, 8)
        self.done_us = np.ndarray((size,), np.float64, buf, 8 * (1 + size))
        self.size = size

    @staticmethod
    def nbytes(size: int) -> int:
        """Bytes a ring of ``size`` periods needs."""
        return 8 * (1 + 2 * size)

    def store(self, i: int, work_us: float, done_us: float) -> None:
        """Period ``i`` (0, 1, ...; the writer's only)."""
        k = i % self.size
        self.work_us[k] = work_us
        self.done_us[k] = done_us
        self._count[0] = i + 1

    @property
    def count(self) -> int:
        """Periods stored so far."""
        return int(self._count[0])

    def last(self, count: int | None) -> tuple[NDArray[np.int64], NDArray[np.float64],
                                               NDArray[np.float64]]:
        """Numbers, work and completion of the last ``count`` periods (default and at most
        the ring's size), oldest first (copies)."""
        run = self.count
        keep = min(run, self.size) if count is None else min(run, self.size, count)
        idx = np.arange(run - keep, run)
        k = idx % self.size
        return idx, self.work_us[k], self.done_us[k]
