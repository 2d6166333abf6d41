"""Helpers shared by the wire-protocol tests (not a test module)."""

from __future__ import annotations

import contextlib
import subprocess
import time
from collections.abc import Callable, Iterator
from typing import TypeVar

import numpy as np

from leadthrough.sim.emulators.process import (  # (also re-exported)
    free_loopback_address,
    spawn_emulator,
    stop_emulator,
)

T = TypeVar("T")


@contextlib.contextmanager
def emulated_ur5() -> Iterator[str]:
    """``leadthrough emulate ur-rtde --robot ur5`` in its own process on a free loopback
    address (RTDE port 30004); yields the address, stops the process after."""
    host = free_loopback_address(30004)
    proc = spawn_emulator("ur-rtde", "ur5", host, 30004)
    try:
        yield host
    finally:
        stop_process(proc)


def wait_for_line(proc: subprocess.Popen[str], start: str, timeout: float) -> str:
    """Read a process's stderr until a line starts with ``start`` (or it ends, or ``timeout``
    [s] has passed, checked after each line); assert that one did. Returns the lines read."""
    assert proc.stderr is not None
    deadline = time.monotonic() + timeout
    lines = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        lines.append(line)
        if line.startswith(start) or (not line and proc.poll() is not None):
            break
    assert lines[-1].startswith(start), "".join(lines)
    return "".join(lines)


POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)
DIRECTION = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])


def min_jerk(start: np.ndarray, delta: np.ndarray, t: float, duration: float) -> np.ndarray:
    """Minimum-jerk interpolation from ``start`` by ``delta`` over ``duration`` at ``t``."""
    s = min(max(t / duration, 0.0), 1.0)
    return start + (10 * s**3 - 15 * s**4 + 6 * s**5) * delta


def exchange(receive: Callable[[float], T | None], duration: float,
             respond: Callable[[T, list[T]], None] | None = None,
             stop: Callable[[], bool] = lambda: False) -> list[T]:
    """Receive for ``duration`` s of wall time; answer each packet with ``respond(packet,
    received so far)``; end early when ``stop()``. Returns the packets received."""
    out: list[T] = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < duration and not stop():
        packet = receive(0.1)
        if packet is None:
            continue
        out.append(packet)
        if respond is not None:
            respond(packet, out)
    return out


def hexbytes(text: str) -> bytes:
    """Bytes from hex text with spaces and newlines (golden packets are written that way)."""
    return bytes.fromhex("".join(text.split()))


# one implementation for the tests and the benchmarks (the package's)
stop_process = stop_emulator
