"""Probes of the real-time loop's worst case: compilation, garbage collection and allocation
in the loop's servo periods (used by ``benchmarks/guiding.py``).

* **Compiles**: every Numba dispatcher of ``leadthrough`` and the signatures it has loaded in
  this process (compiled, or loaded from the on-disk cache: both cost milliseconds). The loop
  loads everything at set-up (``warm_up``); a signature that appears during the periods means
  a period paid for it.
* **Collects**: the cyclic garbage collector's runs (``gc.callbacks``) during the periods.
* **Allocates**: :class:`ProbeDriver` wraps a driver and, at each read (once per servo
  period), reads ``tracemalloc``'s traced memory: per period the memory it left allocated
  (net) and the most it had allocated on top of its start (transient: Python objects and NumPy
  buffers created and freed within the period), and Numba's own allocator's count (compiled
  code: ``numba.core.runtime.rtsys``, its statistics switched on by the probe).
"""

from __future__ import annotations

import gc
import sys
import tracemalloc
from typing import Any

import numpy as np
from numba.core.registry import CPUDispatcher

from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand


def loaded_signatures() -> dict[str, int]:
    """Signatures loaded so far by each Numba dispatcher of ``leadthrough`` (name: count)."""
    out: dict[str, int] = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("leadthrough"):
            continue
        for attr, obj in vars(module).items():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name:
                out[f"{name}.{attr}"] = len(obj.overloads)
    return out


def nrt_allocations() -> int:
    """Allocations made by compiled code since the statistics were switched on."""
    from numba.core.runtime import _nrt_python, rtsys
    if not _nrt_python.memsys_stats_enabled():
        _nrt_python.memsys_enable_stats()
    return int(rtsys.get_allocation_stats().alloc)


class ProbeDriver:
    """A driver that probes every servo period of the loop it serves (see the module doc).

    The first read is the loop's set-up (resets, warm-up); from the second on, each read ends
    one period and starts the next.

    Args:
        driver: The driver doing the work.
        periods: Servo periods to keep figures for.
        trace_memory: Measure allocation with ``tracemalloc`` (slow: not for timing runs).
    """

    def __init__(self, driver: Driver, periods: int, trace_memory: bool = False) -> None:
        self._driver = driver
        self._reads = 0
        self._trace = trace_memory
        self.net = np.zeros(periods, dtype=np.int64)
        self.transient = np.zeros(periods, dtype=np.int64)
        self.collections = 0
        self.signatures_before: dict[str, int] = {}
        self.nrt_before = 0
        self._start = 0

    @property
    def n(self) -> int:
        return self._driver.n

    @property
    def dt(self) -> float:
        return self._driver.dt

    @property
    def simulated(self) -> bool:
        return self._driver.simulated

    def make_feedback(self) -> DriverFeedback:
        return self._driver.make_feedback()

    def make_command(self) -> JointCommand:
        return self._driver.make_command()

    def write(self, cmd: JointCommand) -> None:
        self._driver.write(cmd)

    def step(self) -> None:
        self._driver.step()

    def read(self, fb: DriverFeedback) -> bool:
        fresh = self._driver.read(fb)
        k = self._reads
        if k == 1:                  # the first period starts: set-up is over
            self.signatures_before = loaded_signatures()
            self.nrt_before = nrt_allocations()
            gc.callbacks.append(self._collected)
            if self._trace:
                tracemalloc.start()
                self._start = tracemalloc.get_traced_memory()[0]
        elif k >= 2 and self._trace and k - 2 < self.net.size:
            current, peak = tracemalloc.get_traced_memory()
            self.net[k - 2] = current - self._start
            self.transient[k - 2] = peak - self._start
        if k >= 1 and self._trace:
            tracemalloc.reset_peak()
            self._start = tracemalloc.get_traced_memory()[0]
        self._reads = k + 1
        return fresh

    def finish(self) -> dict[str, Any]:
        """Stop probing; the figures of the periods."""
        if self._collected in gc.callbacks:
            gc.callbacks.remove(self._collected)
        if self._trace and tracemalloc.is_tracing():
            tracemalloc.stop()
        after = loaded_signatures()
        new = {k: after[k] - self.signatures_before.get(k, 0) for k in after
               if after[k] != self.signatures_before.get(k, 0)}
        periods = max(0, min(self._reads - 2, self.net.size))
        return {"periods": periods, "new_signatures": new, "collections": self.collections,
                "nrt_allocations": nrt_allocations() - self.nrt_before,
                "net": self.net[:periods], "transient": self.transient[:periods]}

    def _collected(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self.collections += 1
