"""Helpers shared by the wire-protocol tests (not a test module)."""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

T = TypeVar("T")

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


def spawn_emulator(kind: str, robot: str, host: str, port: int,
                   *extra: str) -> subprocess.Popen[str]:
    """Start ``leadthrough emulate`` in its own process and wait for its ready line.

    Raises:
        RuntimeError: No ready line within 60 s (the process is killed).
    """
    proc = subprocess.Popen(
        [sys.executable, "-m", "leadthrough", "emulate", kind, "--robot", robot,
         "--host", host, "--port", str(port), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], 60.0)
    line = proc.stdout.readline() if ready else ""
    if not line.startswith("leadthrough: emulating"):
        proc.kill()
        raise RuntimeError(f"emulator {kind} did not start: {line!r} {proc.communicate()}")
    return proc


def stop_process(proc: subprocess.Popen[str]) -> str:
    """SIGTERM a spawned emulator; returns what it printed (its report)."""
    proc.terminate()
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def free_loopback_address(port: int) -> str:
    """A 127.x.y.z address on which ``port`` is free (a fixed port without collisions)."""
    rng = np.random.default_rng()
    for _ in range(50):
        host = "127.{}.{}.{}".format(*rng.integers(1, 255, size=3))
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((host, port))
                return host
            except OSError:
                continue
    raise RuntimeError(f"no free loopback address for port {port}")
