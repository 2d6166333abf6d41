"""The machine probe beside a long session (issue 25, must show 5): ``machine_jitter.py``
writes its late wake-ups as wall-clock stretches, and ``long_session.py`` tells the client's
late answers that overlap one of them from those that overlap none."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

from long_session import longest_stall, match_stalls  # noqa: E402
from machine_jitter import load_stalls  # noqa: E402

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="CPU affinity is Linux's")


def _probe(*args: str) -> subprocess.Popen[str]:
    """A probe at ordinary scheduling, once it says it is probing (its first line)."""
    proc = subprocess.Popen([sys.executable, str(BENCHMARKS / "machine_jitter.py"),
                             "--rt-priority", "0", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    first = proc.stdout.readline()
    assert first.strip() == "machine_jitter: probing", first
    return proc


def _a_cpu() -> int:
    return min(os.sched_getaffinity(0))


@linux_only
def test_the_probe_writes_its_late_wake_ups_on_the_wall_clock(tmp_path: Path) -> None:
    """With a threshold of 0 every wake-up of a 1 ms sleep is late (a sleep never returns
    early): the file lists one stretch per sleep, each starting 1 ms after the one before
    began at the earliest, of positive length, in order, within the run's wall-clock time."""
    events, cpu = tmp_path / "cpu.json", _a_cpu()
    before = time.time()
    proc = _probe("--seconds", "0.5", "--cpu", str(cpu), "--events", str(events),
                  "--threshold-ms", "0")
    out, _ = proc.communicate(timeout=60)
    after = time.time()
    assert proc.returncode == 0, out
    stalls = load_stalls(events)
    sleeps = int(out.split(" sleeps of 1 ms")[0])
    assert len(stalls) == sleeps and 10 <= sleeps <= 500
    assert all(before < a < b < after for a, b in stalls)
    assert all(b0 <= a1 - 1e-3 + 1e-5 for (_, b0), (a1, _) in itertools.pairwise(stalls))
    assert f"on CPU {cpu}" in out


@linux_only
def test_sigterm_ends_the_probe_with_its_figures_and_file(tmp_path: Path) -> None:
    """The session ends its probes with SIGTERM: the probe stops within a second, prints its
    figures and writes its file (here with no stretch: a threshold of 1 s)."""
    events = tmp_path / "cpu.json"
    proc = _probe("--seconds", "120", "--events", str(events), "--threshold-ms", "1000")
    time.sleep(0.2)
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert time.monotonic() - sent < 5.0
    assert proc.returncode == 0 and "sleeps of 1 ms" in out
    assert load_stalls(events) == []


def test_late_answers_are_matched_against_the_stalls_of_each_cpu() -> None:
    """A window overlapping a stall of CPU 1 is the machine's (counted on CPU 1); one that
    only touches a stall's end, or lies between stalls, overlaps none; one spanning stalls of
    both CPUs counts on both."""
    stalls = {0: [(10.0, 10.002), (20.0, 20.005)], 1: [(11.0, 11.003), (20.001, 20.002)]}
    windows = [(11.002, 11.006),   # inside CPU 1's stall
                (10.002, 10.006),  # starts where CPU 0's stall ended: no overlap
                (15.0, 15.004),    # between stalls
                (19.999, 20.003)]  # both CPUs
    own, per_cpu = match_stalls(windows, stalls)
    assert own == [(10.002, 10.006), (15.0, 15.004)]
    assert per_cpu == {0: 1, 1: 2}
    assert match_stalls(windows, {}) == (windows, {})


def test_a_late_answer_names_the_longest_stall_it_overlaps() -> None:
    """The report gives, for a late answer the machine explains, the longest stall of any CPU
    within its window, so that a 0.1 ms stall is not read as explaining a 4 ms delay."""
    stalls = {0: [(10.0, 10.0012), (10.003, 10.0079)], 1: [(10.001, 10.0035)]}
    cpu, length = longest_stall((10.0005, 10.0045), stalls) or (None, 0.0)
    assert cpu == 0 and length == pytest.approx(0.0049)
    assert longest_stall((10.0005, 10.0009), stalls) == pytest.approx((0, 0.0012))
    assert longest_stall((12.0, 12.004), stalls) is None
