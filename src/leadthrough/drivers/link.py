"""Bookkeeping shared by the real-controller transports: link errors as values, counters,
sequence-gap tracking and reading the newest datagram without blocking past a deadline.

In the hot path a transport never raises for what the network does: a timeout is ``None``, a
closed or broken socket sets :attr:`LinkStatus.error` (a :class:`LinkError` value) and the next
``receive`` returns ``None`` at once. Exceptions are kept for misuse (sending before ``open``)
and for handshakes, which run before the loop starts.
"""

from __future__ import annotations

import select
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TypeVar

from leadthrough.errors import DataError

__all__ = ["LinkError", "LinkErrorKind", "LinkStats", "LinkStatus", "SequenceTracker",
           "Transport", "decode_datagrams", "drain_datagrams"]

P = TypeVar("P")


class LinkErrorKind(StrEnum):
    """What broke the link."""

    CLOSED = "closed"          # the peer closed the connection (TCP) or the socket was closed
    SOCKET = "socket"          # an OS-level socket error
    PROTOCOL = "protocol"      # the peer sent something the codec rejected, or refused a request
    STOPPED = "stopped"        # the controller stopped the exchange (watchdog, limit, RSI off)


@dataclass(frozen=True)
class LinkError:
    """A link failure, reported as a value.

    Attributes:
        kind: What broke.
        detail: Human-readable detail (the OS error, the codec message, ...).
    """

    kind: LinkErrorKind
    detail: str


@dataclass
class LinkStats:
    """Counters of one transport since :meth:`open`.

    Attributes:
        received: Valid status packets received.
        sent: Commands sent.
        timeouts: ``receive`` calls that returned ``None`` because nothing arrived in time.
        malformed: Packets dropped because the codec rejected them.
        skipped: Valid packets superseded by a newer one before they were read.
        gaps: Sequence jumps seen (each a run of lost packets).
        missed: Sequence numbers missing in total (lost packets).
        last_gap: Size of the latest jump (0: none yet).
    """

    received: int = 0
    sent: int = 0
    timeouts: int = 0
    malformed: int = 0
    skipped: int = 0
    gaps: int = 0
    missed: int = 0
    last_gap: int = 0


@dataclass
class LinkStatus:
    """State shared by the transports: counters and the latched error, if any."""

    stats: LinkStats = field(default_factory=LinkStats)
    error: LinkError | None = None

    def fail(self, kind: LinkErrorKind, detail: str) -> None:
        """Latch the first error (later ones are consequences)."""
        if self.error is None:
            self.error = LinkError(kind, detail)


class Transport:
    """Base of the client transports: their counters and latched link error."""

    def __init__(self) -> None:
        self._link = LinkStatus()

    @property
    def stats(self) -> LinkStats:
        """Counters since ``open`` (``missed``: packets missing by sequence number)."""
        return self._link.stats

    @property
    def error(self) -> LinkError | None:
        """The link failure, if any (a closed port or connection, a socket error)."""
        return self._link.error


class SequenceTracker:
    """Counts the gaps in a sequence of packet numbers (modulo ``2**bits``).

    Args:
        step: Increment between consecutive packets (1 for a counter, the cycle in ms for a
            millisecond time stamp such as KUKA's IPOC).
        bits: Width of the counter (it wraps to 0 after ``2**bits - 1``).
    """

    def __init__(self, step: int = 1, bits: int = 32) -> None:
        self.step = step
        self.modulus = 1 << bits
        self.last: int | None = None

    def update(self, seq: int, stats: LinkStats) -> int:
        """Record ``seq``; count a gap in ``stats`` if numbers were skipped.

        Args:
            seq: The new packet's number.
            stats: Counters to update (``gaps``, ``missed``, ``last_gap``).

        Returns:
            How many packets are missing before this one (0 when in order; a repeated or
            older number also returns 0).
        """
        last, self.last = self.last, seq
        if last is None:
            return 0
        ahead = (seq - last) % self.modulus
        if ahead == 0 or ahead >= self.modulus // 2:  # repeated or older packet
            return 0
        missing = ahead // self.step - 1
        if missing > 0:
            stats.gaps += 1
            stats.missed += missing
            stats.last_gap = missing
        return max(missing, 0)


def drain_datagrams(sock: socket.socket, timeout: float, status: LinkStatus,
                    size: int = 4096) -> list[tuple[bytes, tuple[str, int]]]:
    """Wait up to ``timeout`` for a datagram, then take every datagram already queued.

    The caller decodes them all (so that sequence numbers of superseded packets are not
    mistaken for losses) and keeps the newest.

    Args:
        sock: A UDP socket (its blocking mode is left as found).
        timeout: Longest wait for the first datagram [s] (0: poll).
        status: Counters (``timeouts``) and the latched error.
        size: Receive buffer size [bytes].

    Returns:
        The datagrams with their senders, oldest first; empty on a timeout or a socket error
        (then latched in ``status.error``).
    """
    out: list[tuple[bytes, tuple[str, int]]] = []
    try:
        ready, _, _ = select.select([sock], [], [], max(timeout, 0.0))
        if not ready:
            status.stats.timeouts += 1
            return out
        while True:
            try:
                out.append(sock.recvfrom(size, socket.MSG_DONTWAIT))
            except BlockingIOError:
                return out
    except ConnectionRefusedError:
        status.fail(LinkErrorKind.CLOSED, "the peer's port is closed (ICMP port unreachable)")
        return out
    except OSError as e:
        status.fail(LinkErrorKind.SOCKET, str(e))
        return out


def decode_datagrams(sock: socket.socket, timeout: float, status: LinkStatus,
                     decode: Callable[[bytes], P]) -> list[tuple[P, tuple[str, int]]]:
    """:func:`drain_datagrams`, then decode each; malformed ones are counted and dropped.

    Args:
        sock: A UDP socket.
        timeout: Longest wait for the first datagram [s].
        status: Counters (``timeouts``, ``malformed``) and the latched error.
        decode: The codec; raises :class:`~leadthrough.errors.DataError` on bad input.

    Returns:
        The decoded packets with their senders, oldest first.
    """
    out = []
    for data, addr in drain_datagrams(sock, timeout, status):
        try:
            out.append((decode(data), addr))
        except DataError:
            status.stats.malformed += 1
    return out
