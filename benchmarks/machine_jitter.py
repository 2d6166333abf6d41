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

Beside a session (``benchmarks/long_session.py``) it runs as a probe: pinned to one CPU
(``--cpu``), at a priority above the loop's, it writes each wake-up later than
``--threshold-ms`` as [asked wake-up, actual wake-up] in wall-clock time (``CLOCK_REALTIME``,
the emulators' answer timing's clock) to ``--events``: stretches in which nothing of ours could
run on that CPU (a stretch starts at the asked wake-up: a stall that began during the sleep
counts from there). It says ``machine_jitter: probing`` on stderr once SIGTERM ends it
early, with the figures and the file written.

    python benchmarks/machine_jitter.py [--seconds 120] [--rt-priority 50] [--cpu C]
        [--events FILE] [--threshold-ms 1]

Prints the delay's median, p99, p99.99 and maximum [ms], the wake-ups later than 1, 2 and 4 ms,
and the steal time [s] over the run.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from array import array
from pathlib import Path
from types import FrameType

import numpy as np


def steal_seconds() -> float:
    """CPU time the hypervisor took from this machine since boot, all CPUs [s] (Linux
    ``/proc/stat``, the ``cpu`` line's 8th value, in clock ticks; NaN where unreadable)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def load_stalls(path: Path) -> list[tuple[float, float]]:
    """A probe's ``--events`` file: its stalls as (asked wake-up, actual wake-up) [s, wall
    clock]."""
    return [(float(a), float(b)) for a, b in json.loads(path.read_text())["stalls"]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="how long to measure [s]")
    ap.add_argument("--rt-priority", type=int, default=50, metavar="P",
                    help="SCHED_FIFO priority of the sleeping thread (0: ordinary scheduling)")
    ap.add_argument("--cpu", type=int, default=None, metavar="C", help="run on CPU C only")
    ap.add_argument("--events", type=Path, default=None, metavar="FILE",
                    help="write the late wake-ups' wall-clock stretches here (JSON)")
    ap.add_argument("--threshold-ms", type=float, default=1.0,
                    help="a wake-up later than this is written to --events [ms]")
    args = ap.parse_args()
    if args.seconds <= 0:
        ap.error(f"--seconds must be > 0, got {args.seconds}")
    if args.cpu is not None:
        try:
            os.sched_setaffinity(0, {args.cpu})
        except (OSError, AttributeError) as e:
            print(f"--cpu {args.cpu} refused ({e}): this machine has CPUs "
                  f"{sorted(os.sched_getaffinity(0))}", file=sys.stderr)
            sys.exit(2)
    if args.rt_priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
        except (OSError, AttributeError) as e:
            print(f"SCHED_FIFO {args.rt_priority} refused ({e}): needs CAP_SYS_NICE; run "
                  f"with --rt-priority 0 for ordinary scheduling", file=sys.stderr)
            sys.exit(2)
    stop = False

    def _stop(signum: int, frame: FrameType | None) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, _stop)
    print("machine_jitter: probing", file=sys.stderr, flush=True)  # SIGTERM ends it from here
    steal0 = steal_seconds()
    delays = array("d")
    stalls: list[tuple[float, float]] = []
    threshold = args.threshold_ms * 1e-3
    start = time.perf_counter()
    end = start + args.seconds
    while not stop and time.perf_counter() < end:
        wall, t = time.time(), time.perf_counter()
        time.sleep(1e-3)
        delay = time.perf_counter() - t - 1e-3
        delays.append(delay * 1e3)
        if delay > threshold:
            stalls.append((round(wall + 1e-3, 6), round(wall + 1e-3 + delay, 6)))
    seconds = time.perf_counter() - start
    steal = steal_seconds() - steal0
    d = np.frombuffer(delays, dtype=np.float64)
    policy = f"SCHED_FIFO {args.rt_priority}" if args.rt_priority else "ordinary scheduling"
    where = f" on CPU {args.cpu}" if args.cpu is not None else ""
    figures = ("nothing measured (stopped before the first)" if d.size == 0 else
               f"delay behind the asked wake-up [ms]: median {np.median(d):.3f}, p99 "
               f"{np.percentile(d, 99):.3f}, p99.99 {np.percentile(d, 99.99):.3f}, max "
               f"{d.max():.3f}; later than 1 ms: {int(np.sum(d > 1))}, 2 ms: "
               f"{int(np.sum(d > 2))}, 4 ms: {int(np.sum(d > 4))}")
    print(f"{d.size} sleeps of 1 ms over {seconds:.0f} s ({policy}{where}), {figures}; "
          f"steal {steal:.2f} s", flush=True)
    if args.events is not None:
        args.events.write_text(json.dumps({"cpu": args.cpu, "threshold_ms": args.threshold_ms,
                                           "seconds": seconds, "stalls": stalls}))


if __name__ == "__main__":
    main()
