"""``leadthrough emulate`` in a process of its own, as the tests and benchmarks run it: started,
waited for until it says it is ready, stopped with its report; and a loopback address on which
an interface's fixed port is free (so that runs side by side do not collide)."""

from __future__ import annotations

import select
import socket
import subprocess
import sys

import numpy as np

from leadthrough.errors import SimulationError

__all__ = ["READY_LINE", "emulator_report", "free_loopback_address", "spawn_emulator",
           "stop_emulator", "timing_summary", "wait_ready"]

#: The first line ``leadthrough emulate`` prints once its sockets are open.
READY_LINE = "leadthrough: emulating"


def spawn_emulator(kind: str, robot: str, host: str, port: int, *extra: str,
                   wait: bool = True, timeout: float = 60.0) -> subprocess.Popen[str]:
    """Start ``leadthrough emulate KIND --robot R --host H --port P EXTRA...``.

    Args:
        kind: ``fanuc-j519``, ``ur-rtde`` or ``kuka-rsi``.
        robot: Robot name or file.
        host: Address to listen on (RSI: the client's).
        port: Port (RSI: the client's).
        extra: Further arguments of ``emulate``.
        wait: Wait for the ready line (:func:`wait_ready`).
        timeout: Longest wait [s].

    Raises:
        SimulationError: No ready line within ``timeout`` (the process is killed).
    """
    proc = subprocess.Popen(
        [sys.executable, "-m", "leadthrough", "emulate", kind, "--robot", robot,
         "--host", host, "--port", str(port), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if wait:
        wait_ready(proc, timeout)
    return proc


def wait_ready(proc: subprocess.Popen[str], timeout: float = 60.0) -> None:
    """Wait for a spawned emulator's ready line.

    Raises:
        SimulationError: None within ``timeout`` [s] (the process is killed).
    """
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    line = proc.stdout.readline() if ready else ""
    if not line.startswith(READY_LINE):
        proc.kill()
        raise SimulationError(f"the emulator did not start: {line!r} {proc.communicate()}",
                              field="emulate", value=proc.args,
                              expected=f"'{READY_LINE} ...' within {timeout:g} s")


def stop_emulator(proc: subprocess.Popen[str], timeout: float = 20.0) -> str:
    """SIGTERM a spawned emulator; returns what it printed (its report)."""
    proc.terminate()
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def emulator_report(text: str) -> dict[str, str]:
    """The ``key: value`` lines of an emulator's printed report."""
    return dict(line.split(": ", 1) for line in text.splitlines() if ": " in line)


def timing_summary(report: dict[str, str]) -> str:
    """An emulator report's answer timing (its ``timing.*`` keys,
    :mod:`~leadthrough.sim.emulators.answer_timing`) in one line: answers in time, late and
    never, with the emulator's own lag apart, its late sends and skipped cycles, and the first
    late or missing answers."""
    def f(name: str) -> str:
        return report.get(f"timing.{name}", "?")

    return (f"attribution: {f('statuses')} statuses timed; answers in time {f('in_time')}, "
            f"late {f('late')} (with the emulator's lag {f('late_with_lag')}), never "
            f"{f('never')} (with its lag {f('never_with_lag')}); emulator: statuses sent late "
            f"{f('sends_late')}, cycles skipped {f('cycles_skipped')} "
            f"({report.get('resyncs', '?')} resyncs); stale answers {f('stale')}; worst answer "
            f"{f('worst_answer_ms')} ms; late/missing answers: {f('events')}")


def free_loopback_address(port: int) -> str:
    """A 127.x.y.z address on which TCP ``port`` is free.

    Raises:
        SimulationError: None found in 50 tries.
    """
    rng = np.random.default_rng()
    for _ in range(50):
        host = "127.{}.{}.{}".format(*rng.integers(1, 255, size=3))
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((host, port))
                return host
            except OSError:
                continue
    raise SimulationError("no free loopback address", field="port", value=port,
                          expected="a port free on some 127.x.y.z address")
