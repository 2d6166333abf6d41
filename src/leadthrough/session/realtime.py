"""Optional real-time set-up of the process that runs the loop (Linux): SCHED_FIFO priority,
memory locked (no page faults in the loop), CPU affinity.

Each step is asked for separately and reported: a step the OS refuses (no ``CAP_SYS_NICE``,
an ``RLIMIT_MEMLOCK`` too small, a CPU that does not exist, not Linux) gives a clear message
saying what to change, and the loop runs without it. Follows ``sched_setscheduler(2)``,
``mlockall(2)`` and ``sched_setaffinity(2)``; the PREEMPT_RT project's "HOWTO build a simple RT
application" (https://wiki.linuxfoundation.org/realtime/documentation/howto/applications/
application_base) for the order: lock memory, set the policy, then start the cycle.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from dataclasses import dataclass

__all__ = ["MAX_FIFO_PRIORITY", "RealtimeRequest", "setup_realtime"]

_MCL_CURRENT, _MCL_FUTURE = 1, 2
#: SCHED_FIFO's highest priority (``sched_get_priority_max(2)`` on Linux; the lowest is 1).
MAX_FIFO_PRIORITY = 99


@dataclass(frozen=True)
class RealtimeRequest:
    """What to ask of the OS.

    Attributes:
        priority: SCHED_FIFO priority 1–99 (None: the normal scheduler).
        lock_memory: ``mlockall(MCL_CURRENT | MCL_FUTURE)``.
        cpus: CPUs to run on (None: any).
    """

    priority: int | None = None
    lock_memory: bool = False
    cpus: tuple[int, ...] | None = None


def setup_realtime(request: RealtimeRequest) -> list[str]:
    """Apply ``request`` to this process; returns one line per step, done or refused (with
    what to change). Never raises for a refusal of the OS."""
    lines = []
    if request.lock_memory:
        lines.append(_lock_memory())
    if request.priority is not None:
        lines.append(_fifo(request.priority))
    if request.cpus is not None:
        lines.append(_affinity(request.cpus))
    return lines


def _lock_memory() -> str:
    name = ctypes.util.find_library("c")
    if name is None:
        return "memory not locked: no C library found (mlockall is Linux/POSIX)"
    libc = ctypes.CDLL(name, use_errno=True)
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        return (f"memory not locked: mlockall refused ({os.strerror(err)}); raise the "
                f"memlock limit (ulimit -l unlimited, or memlock in "
                f"/etc/security/limits.conf) or give the process CAP_IPC_LOCK")
    return "memory locked (mlockall MCL_CURRENT|MCL_FUTURE)"


def _fifo(priority: int) -> str:
    if not 1 <= priority <= MAX_FIFO_PRIORITY:
        return f"SCHED_FIFO not set: priority {priority} outside 1-{MAX_FIFO_PRIORITY}"
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO not set: this OS has no sched_setscheduler (Linux only)"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return (f"SCHED_FIFO {priority} not set: not permitted; run with CAP_SYS_NICE "
                f"(setcap cap_sys_nice+ep on the interpreter, or an rtprio limit in "
                f"/etc/security/limits.conf); the loop runs at normal priority")
    except OSError as e:
        return f"SCHED_FIFO {priority} not set: {e}; the loop runs at normal priority"
    return f"SCHED_FIFO priority {priority}"


def _affinity(cpus: tuple[int, ...]) -> str:
    if not hasattr(os, "sched_setaffinity"):
        return "CPU affinity not set: this OS has no sched_setaffinity (Linux only)"
    try:
        os.sched_setaffinity(0, set(cpus))
    except (OSError, ValueError) as e:     # ValueError: a negative CPU number
        return (f"CPU affinity not set: {e} (CPUs {list(cpus)}; this machine has "
                f"{os.cpu_count()})")
    return f"CPU affinity {sorted(cpus)}"
