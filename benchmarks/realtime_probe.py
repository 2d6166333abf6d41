"""Probes of the real-time loop's worst case: compilation, garbage collection and allocation
in the loop's servo periods (used by ``benchmarks/guiding.py``).

* **Compiles**: every Numba dispatcher of ``leadthrough`` and the signatures it has loaded in
  this process (compiled, or loaded from the on-disk cache: both cost milliseconds). The loop
  loads everything at set-up (``warm_up``); a signature that appears during the periods means
  a period paid for it.
* **Collects**: the cyclic garbage collector's runs (``gc.callbacks``) during the periods.
* **Allocates**: :class:`ProbeDriver` wraps a driver and, at each read (once per servo
  period), reads ``tracemalloc``'s traced memory: the memory the periods kept (the traced
  memory after the last period against after the first) and, per period, the most it had
  allocated on top of its start (transient: Python objects and NumPy buffers created and freed
  within the period), and Numba's own allocator's count
  (``numba.core.runtime.rtsys``, its statistics switched on by the probe). The dispatcher wraps
  every array argument of a compiled call made from Python in a small allocation of its own
  (freed when the call returns); :func:`compiled_allocations` calls the loop's compiled
  functions from compiled code, where no argument is wrapped, to count what they allocate
  themselves.
"""

from __future__ import annotations

import gc
import sys
import tracemalloc
from typing import Any

import numpy as np
from numba import njit
from numba.core.registry import CPUDispatcher

from leadthrough.drivers.protocol import Driver, DriverFeedback, WrappedDriver


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


def compiled_allocations(parts: Any, repeats: int = 1000) -> dict[str, float]:
    """Allocations per call made inside the loop's compiled functions (the estimator's two
    halves, the guiding cycle, the interpolator's steps), called ``repeats`` times from
    compiled code on copies of the records of ``parts`` (a ``LoopParts``, reset)."""
    from leadthrough.control.guiding_cycle import guiding_cycle
    from leadthrough.control.interpolation import next_command, start_segment
    from leadthrough.estimation.estimator_step import finish_sample, read_sample

    est, ctl, interp = parts
    e_in, e_out = est.make_input(), est.make_output()
    e_in.q[:] = est.record["q_filtered"][0]
    c_in, c_out = ctl.make_input(), ctl.make_output()
    c_in.q[:] = ctl.record["q_cmd"][0]
    n = e_in.q.size
    rnea, jacobian, unused = np.zeros(n), np.zeros((6, n)), np.zeros((n, n))
    calls = {
        "read_sample": (read_sample, (e_in.record, est.record.copy(), e_out.record)),
        "finish_sample": (finish_sample, (rnea, unused, unused, rnea, jacobian,
                                          est.record.copy(), e_out.record)),
        "guiding_cycle": (guiding_cycle, (c_in.record, ctl.record.copy(),
                                          ctl._ik.record.copy(), ctl._safety.record.copy(),
                                          ctl._safety.event_ring.copy(), c_out.record)),
        "start_segment": (start_segment, (interp.record.copy(), c_in.q, np.zeros(n))),
        "next_command": (next_command, (interp.record.copy(), np.zeros(n), np.zeros(n))),
    }
    out = {}
    for name, (function, args) in calls.items():
        repeat = _repeater(function)
        repeat(1, *args)
        counts = []
        for k in (repeats, 2 * repeats):      # the difference cancels the outer call's own
            before = nrt_allocations()
            repeat(k, *args)
            counts.append(nrt_allocations() - before)
        out[name] = (counts[1] - counts[0]) / repeats
    return out


def _repeater(function: Any) -> Any:
    """A compiled loop calling ``function`` k times with the same arguments."""
    @njit
    def repeat(k: int, *args: Any) -> None:
        for _ in range(k):
            function(*args)
    return repeat


class ProbeDriver(WrappedDriver):
    """A driver that probes every servo period of the loop it serves (see the module doc).

    The first read is the loop's set-up (resets, warm-up); from the second on, each read ends
    one period and starts the next.

    Args:
        driver: The driver doing the work.
        periods: Servo periods to keep figures for.
        trace_memory: Measure allocation with ``tracemalloc`` (slow: not for timing runs).
    """

    def __init__(self, driver: Driver, periods: int, trace_memory: bool = False) -> None:
        super().__init__(driver)
        self._reads = 0
        self._trace = trace_memory
        self.net = np.zeros(periods, dtype=np.int64)
        self.transient = np.zeros(periods, dtype=np.int64)
        self.collections = 0
        self.signatures_before: dict[str, int] = {}
        self.nrt_before = 0
        self._start = 0

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
            self.net[k - 2] = current          # the traced memory at the end of the period
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
        # memory kept: the traced memory after the last period against after the first (the
        # probe's own bookkeeping is the same at both ends)
        kept = int(self.net[periods - 1] - self.net[0]) if periods > 1 else 0
        return {"periods": periods, "new_signatures": new, "collections": self.collections,
                "nrt_allocations": nrt_allocations() - self.nrt_before,
                "kept": kept, "transient": self.transient[:periods]}

    def _collected(self, phase: str, info: dict[str, int]) -> None:
        # the loop pauses the collector: a collection while it is paused is one in a period
        # (after the loop it runs again until finish() is called, and those do not count)
        if phase == "start" and not gc.isenabled():
            self.collections += 1
