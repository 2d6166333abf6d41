"""Can this machine keep a servo period? How late a real-time thread wakes, nothing else running.

Before a controller's late answers are blamed on the loop, this measures the machine alone: a
thread at ``SCHED_FIFO`` priority P (as ``leadthrough guide --rt-priority P`` runs the loop)
sleeps 1 ms at a time for ``--seconds`` and records how much later than asked it runs again;
the time the hypervisor took from this virtual machine over the run is read from
``/proc/stat`` ("steal", ``proc(5)``; 0 on bare metal). A wake-up later than the servo period
(4 ms at RSI's cycle, 2 ms at an e-Series UR's) is a period the loop could not have answered in
time whatever it does. ``cyclictest`` (rt-tests, https://wiki.linuxfoundation.org/realtime/
documentation/howto/tools/cyclictest/start) is the standard tool for the same question, in C;
this needs nothing beyond Python, and measures a Python thread, as the loop is one.

    python benchmarks/machine_jitter.py [--seconds 120] [--rt-priority 50]

Prints the delay's median, p99, p99.99 and maximum [ms], the wake-ups later than 1, 2 and 4 ms,
and the steal time [s] over the run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def steal_seconds() -> float:
    """CPU time the hypervisor took from this machine since boot, all CPUs [s] (Linux
    ``/proc/stat``, the ``cpu`` line's 8th value, in clock ticks; NaN where unreadable)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="how long to measure [s]")
    ap.add_argument("--rt-priority", type=int, default=50, metavar="P",
                    help="SCHED_FIFO priority of the sleeping thread (0: ordinary scheduling)")
    args = ap.parse_args()
    if args.seconds <= 0:
        ap.error(f"--seconds must be > 0, got {args.seconds}")
    if args.rt_priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
        except (OSError, AttributeError) as e:
            print(f"SCHED_FIFO {args.rt_priority} refused ({e}): needs CAP_SYS_NICE; run "
                  f"with --rt-priority 0 for ordinary scheduling", file=sys.stderr)
            sys.exit(2)
    steal0 = steal_seconds()
    delays: list[float] = []
    end = time.perf_counter() + args.seconds
    while time.perf_counter() < end:
        t = time.perf_counter()
        time.sleep(1e-3)
        delays.append((time.perf_counter() - t - 1e-3) * 1e3)
    steal = steal_seconds() - steal0
    d = np.array(delays)
    policy = f"SCHED_FIFO {args.rt_priority}" if args.rt_priority else "ordinary scheduling"
    print(f"{d.size} sleeps of 1 ms over {args.seconds:g} s ({policy}), delay behind the asked "
          f"wake-up [ms]: median {np.median(d):.3f}, p99 {np.percentile(d, 99):.3f}, p99.99 "
          f"{np.percentile(d, 99.99):.3f}, max {d.max():.3f}; later than 1 ms: "
          f"{int(np.sum(d > 1))}, 2 ms: {int(np.sum(d > 2))}, 4 ms: {int(np.sum(d > 4))}; "
          f"steal {steal:.2f} s")


if __name__ == "__main__":
    main()
