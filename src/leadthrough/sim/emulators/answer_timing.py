"""Whose fault is a late command: the client's answer timed against the controller's actual
send, apart from the emulator's own lag.

A real controller counts a command late when it has not arrived by its deadline, one cycle
after the controller sent its status packet. The emulator is a Python process stepped at
1 ms that can itself fall behind the wall clock; its cycle check (the controller's count,
``missed_cycles``) cannot tell a client that answered late from an emulator that sent late or
read late. :class:`AnswerTiming` does, from timestamps alone:

* each timed status is stamped (``CLOCK_REALTIME``) just before the send system call and
  just after it returned (on loopback the datagram reaches the peer's socket in between),
  with how late the emulator sent it behind its own schedule;
* each answer carries the **kernel's receive timestamp** (``SO_TIMESTAMPNS``, read with
  ``recvmsg``: :func:`enable_rx_stamps`, :func:`recv_stamped`), the time it reached the
  emulator's socket whenever the emulator got round to reading it. An answer is **late** when
  that time is after the status's send + one cycle; **never** when no answer to the status came
  within :data:`HORIZON_S`;
* a late or missing answer **coincides with the emulator's lag** when the status went out more
  than ``tolerance`` behind schedule, or the emulator's loop was behind (:meth:`lagged`,
  :meth:`resynced`) between the send and the answer (the deadline for a missing one), or the
  answer is late only when timed from before the send call (it came within a cycle of the
  call's return: the emulator was held up inside it), or the answer's time is only an upper
  bound (``exact=False``: see below). Those are not shown to be the client's;
* the emulator's own misses are counted apart: statuses sent more than ``tolerance`` late and
  cycle slots skipped by its resynchronisations;
* the late or missing answers that do not coincide with the emulator's lag keep their
  wall-clock windows (``client_windows``: from the send to the answer, or to the deadline of a
  missing one), so that a machine's own stalls measured beside the session
  (``benchmarks/machine_jitter.py``) can be matched against them.

Pairing an answer with its status: J519 and RSI answers carry the status's sequence number /
IPOC (``key``). RTDE answers carry nothing of the status (the program sees a watchdog counter
change); a client that reads the newest package answers the newest status it has, so a counter
change answers the latest status sent before it arrived, and older unanswered statuses count
as never answered.

RTDE is TCP: ``SO_TIMESTAMPNS`` works there too on Linux, but TCP merges segments that wait in
the receive queue into one buffer whose timestamp is the newest segment's. A read that returns
one frame has that frame's arrival time; a read that returns several (the emulator read late)
gives an upper bound for all but the last, passed as ``exact=False``.
"""

from __future__ import annotations

import math
import socket
import struct
import sys
import time
from collections import OrderedDict, deque
from dataclasses import dataclass

__all__ = ["HORIZON_S", "SO_TIMESTAMPNS", "WINDOWS_KEPT", "AnswerTiming", "TimingCounts",
           "enable_rx_stamps", "recv_stamped"]

#: Linux's ``SO_TIMESTAMPNS`` (= ``SCM_TIMESTAMPNS``; asm-generic value, x86 and ARM), which
#: Python's ``socket`` module does not export.
SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@qq")
#: A status not answered within this long [s] is never answered (a later answer is stale).
HORIZON_S = 0.5
_EVENTS_KEPT = 20
#: How many of the client's late or missing answers keep their windows (the first ones).
WINDOWS_KEPT = 5000


def enable_rx_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp every received packet (Linux); False where it cannot."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def recv_stamped(sock: socket.socket, bufsize: int = 65536
                 ) -> tuple[bytes, tuple[str, int] | None, float, bool]:
    """One ``recvmsg`` with the kernel's receive timestamp.

    Returns:
        (data, sender address, receive time [s, ``CLOCK_REALTIME``], exact): ``exact`` is
        False when the kernel gave no timestamp and the time is when it was read.

    Raises:
        BlockingIOError: Nothing queued (non-blocking socket).
        OSError: As ``recvmsg``.
    """
    data, ancillary, _, addr = sock.recvmsg(bufsize, socket.CMSG_SPACE(_TIMESPEC.size))
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
            sec, nsec = _TIMESPEC.unpack(payload[:_TIMESPEC.size])
            return data, addr, sec + nsec * 1e-9, True
    return data, addr, time.time(), False


@dataclass(frozen=True)
class TimingCounts:
    """Answer timing of a session (see the module doc; times in ms).

    Attributes:
        statuses: Timed statuses (sent while the client streamed, the faults' drops not
            included).
        in_time: Answered within a cycle of the actual send.
        late: Answered after the deadline (whether or not the emulator took it in time).
        never: No answer within :data:`HORIZON_S` (the run that ended the stream excluded).
        late_with_lag, never_with_lag: Of ``late`` / ``never``, those that coincide with the
            emulator's own lag (not shown to be the client's).
        sends_late: Statuses the emulator sent more than the tolerance behind its schedule.
        cycles_skipped: Cycle slots its resynchronisations dropped.
        stale: Answers to no pending status (duplicates, or past the horizon).
        worst_answer_ms: Longest time from a send to its answer [ms].
        events: The first late or missing answers: ``t=<sim s> <status> +<ms>`` (answer time
            after the send; ``never``) and ``lag`` when they coincide with the emulator's lag.
        client_windows: The first :data:`WINDOWS_KEPT` late or missing answers that do not
            coincide with the emulator's lag, as (send, end) [s, ``CLOCK_REALTIME``], end the
            answer's arrival (late) or the send + one cycle (never): where the client, or the
            machine that runs it, was held up.
    """

    statuses: int = 0
    in_time: int = 0
    late: int = 0
    never: int = 0
    late_with_lag: int = 0
    never_with_lag: int = 0
    sends_late: int = 0
    cycles_skipped: int = 0
    stale: int = 0
    worst_answer_ms: float = 0.0
    events: tuple[str, ...] = ()
    client_windows: tuple[tuple[float, float], ...] = ()


@dataclass
class _Status:
    label: float   # simulated time of the send [s], for the events
    sent: float    # wall clock (CLOCK_REALTIME) just before the send [s]
    lag: float     # how late the emulator sent it behind its schedule [s]
    done: float    # wall clock just after the send call returned [s]


class AnswerTiming:
    """Counts answers against the actual sends (see the module doc).

    Args:
        cycle: Controller cycle [s]: the answer's deadline after the send.
        tolerance: Emulator lag that counts as its own [s] (default 1 ms, one step of its
            loop).
    """

    def __init__(self, cycle: float, tolerance: float = 1e-3) -> None:
        self.cycle, self.tolerance = cycle, tolerance
        self._pending: OrderedDict[int, _Status] = OrderedDict()
        self._lags: deque[tuple[float, float]] = deque()
        self._last_answered = -math.inf  # send time of the latest answered status [s]
        self.statuses = self.in_time = self.late = self.never = 0
        self.late_with_lag = self.never_with_lag = 0
        self.sends_late = self.cycles_skipped = self.stale = 0
        self.worst = 0.0
        self.events: list[str] = []
        self.client_windows: list[tuple[float, float]] = []

    # ------------------------------------------------------------------------ the emulator
    def sent(self, key: int, at: float, lag: float, label: float = 0.0,
             done: float | None = None) -> None:
        """A timed status left.

        Args:
            key: Its sequence number / IPOC / cycle index (unique among the pending).
            at: Wall clock just before the send system call [s, ``CLOCK_REALTIME``].
            lag: How late that was behind the emulator's schedule [s].
            label: Simulated time, for the events [s].
            done: Wall clock just after the call returned [s] (None: ``at``).
        """
        self.expire(at)
        self.statuses += 1
        if lag > self.tolerance:
            self.sends_late += 1
        self._pending[key] = _Status(label, at, lag, at if done is None else done)

    def lagged(self, start: float, end: float) -> None:
        """The emulator's loop was behind its schedule from ``start`` to ``end``
        [s, ``CLOCK_REALTIME``] (call it only for lags beyond the tolerance)."""
        if self._lags and start <= self._lags[-1][1]:
            start = min(start, self._lags[-1][0])
            self._lags.pop()
        self._lags.append((start, end))
        while self._lags and self._lags[0][1] < end - 2 * HORIZON_S:
            self._lags.popleft()

    def resynced(self, start: float, lag: float) -> None:
        """The loop dropped a lag of ``lag`` [s] that began at ``start`` instead of catching
        up: the cycle slots in it were skipped."""
        self.cycles_skipped += int(lag // self.cycle)
        self.lagged(start, start + lag)

    # ---------------------------------------------------------------------------- answers
    def answer(self, rx: float, key: int | None = None, exact: bool = True) -> None:
        """An answer reached the socket at ``rx`` [s, ``CLOCK_REALTIME``].

        Args:
            rx: Kernel receive time (or an upper bound: ``exact`` False).
            key: The status it answers; None: the latest status sent before ``rx`` (RTDE).
            exact: ``rx`` is the answer's own arrival time.
        """
        if key is None:
            key = next((k for k in reversed(self._pending) if self._pending[k].sent <= rx),
                       None)
        status = self._pending.pop(key, None) if key is not None else None
        if key is None or status is None:
            self.stale += 1
            return
        response = rx - status.sent
        self.worst = max(self.worst, response)
        self._last_answered = max(self._last_answered, status.sent)
        if response <= self.cycle:
            self.in_time += 1
            return
        self.late += 1
        lag = not exact or rx - status.done <= self.cycle or self._coincides(status, rx)
        self.late_with_lag += lag
        self._event(status, key, f"+{response * 1e3:.1f} ms", lag)
        if not lag:
            self._client_window(status.sent, rx)

    def expire(self, now: float) -> None:
        """Statuses not answered within :data:`HORIZON_S` of ``now`` are never answered."""
        while self._pending:
            key, status = next(iter(self._pending.items()))
            if status.sent + HORIZON_S > now:
                break
            del self._pending[key]
            self._never(key, status)

    def ended(self) -> None:
        """The stream ended: the statuses sent after the last answered one are the stop's
        (not counted); older unanswered ones were never answered."""
        for key, status in list(self._pending.items()):
            if status.sent < self._last_answered:
                self._never(key, status)
        self._pending.clear()

    def counts(self) -> TimingCounts:
        """The session so far (pending statuses not counted)."""
        return TimingCounts(
            statuses=self.statuses, in_time=self.in_time, late=self.late, never=self.never,
            late_with_lag=self.late_with_lag, never_with_lag=self.never_with_lag,
            sends_late=self.sends_late, cycles_skipped=self.cycles_skipped, stale=self.stale,
            worst_answer_ms=round(self.worst * 1e3, 3), events=tuple(self.events),
            client_windows=tuple(self.client_windows))

    # ---------------------------------------------------------------------------- helpers
    def _never(self, key: int, status: _Status) -> None:
        self.never += 1
        lag = self._coincides(status, status.sent + self.cycle)
        self.never_with_lag += lag
        self._event(status, key, "never", lag)
        if not lag:
            self._client_window(status.sent, status.sent + self.cycle)

    def _client_window(self, start: float, end: float) -> None:
        if len(self.client_windows) < WINDOWS_KEPT:
            self.client_windows.append((round(start, 6), round(end, 6)))

    def _coincides(self, status: _Status, until: float) -> bool:
        """The status went out late, or the loop lagged between its send and ``until``."""
        if status.lag > self.tolerance:
            return True
        return any(start <= until and end >= status.sent for start, end in self._lags)

    def _event(self, status: _Status, key: int, what: str, lag: bool) -> None:
        if len(self.events) < _EVENTS_KEPT:
            self.events.append(f"t={status.label:.3f} #{key} {what}{' lag' if lag else ''}")
