"""Bookkeeping shared by the real-controller transports: link errors as values, counters,
sequence-gap tracking and reading the newest datagram without blocking past a deadline.

In the hot path a transport never raises for what the network does: a timeout is ``None``, a
closed or broken socket sets :attr:`LinkStatus.error` (a :class:`LinkError` value) and the next
``receive`` returns ``None`` at once. Exceptions are kept for misuse (sending before ``open``)
and for handshakes, which run before the loop starts.

A packet the codec refuses is counted by its :class:`~leadthrough.drivers.wire.BadPacket` code
(:attr:`LinkStats.bad`) and dropped; it never raises out of ``receive``. A codec failing in a way
it does not name (a defect, never expected) is counted as ``UNEXPECTED`` and logged once, so that
not even a defect of a decoder turns a packet into an exception in the loop. Each ``receive``
takes at most :data:`MAX_DATAGRAMS` datagrams from the socket and spends at most
:data:`PARSE_BUDGET_S` decoding them: a flood costs the loop a bounded time per cycle, the rest
is counted (``BUDGET``) and dropped.
"""

from __future__ import annotations

import logging
import select
import socket
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TypeVar

from leadthrough.drivers.wire import BadPacket, packet_code
from leadthrough.errors import DataError

__all__ = ["MAX_DATAGRAMS", "PARSE_BUDGET_S", "LinkError", "LinkErrorKind", "LinkStats",
           "LinkStatus", "SequenceTracker", "Transport", "decode_datagrams", "decode_packet",
           "drain_datagrams"]

P = TypeVar("P")
log = logging.getLogger("leadthrough.drivers")

#: Datagrams one ``receive`` takes from the socket at most (the rest wait for the next).
MAX_DATAGRAMS = 256
#: Decoding time one ``receive`` spends at most [s], counted as this thread's CPU time (so a
#: preemption of the loop by another process does not spend it): past it the datagrams left
#: are dropped unparsed (``BadPacket.BUDGET``). A valid packet decodes in tens of µs and a
#: refused one in a few (the codecs refuse at once what their protocol never sends, and cap the
#: size); a cycle is 2-12 ms. The budget is a backstop, half an RSI cycle. (A garbage
#: collection during a decode spends it too: the loop runs with the collector off.)
PARSE_BUDGET_S = 2e-3


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
        bad: Packets refused, by :class:`~leadthrough.drivers.wire.BadPacket` code (foreign
            senders, sequence errors and spent budgets included; codec refusals are also in
            ``malformed``).
        decode_s: This thread's CPU time spent decoding packets in total [s]
            (``time.thread_time``: the parse's own cost, not the time another process or
            thread held the CPU meanwhile).
        decode_max_s: The longest decoding of one packet, CPU time [s].
    """

    received: int = 0
    sent: int = 0
    timeouts: int = 0
    malformed: int = 0
    skipped: int = 0
    gaps: int = 0
    missed: int = 0
    last_gap: int = 0
    bad: Counter[BadPacket] = field(default_factory=Counter)
    decode_s: float = 0.0
    decode_max_s: float = 0.0

    def refuse(self, code: BadPacket) -> None:
        """Count one packet refused for ``code``."""
        self.bad[code] += 1


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
                    size: int = 4096, limit: int = MAX_DATAGRAMS,
                    ) -> list[tuple[bytes, tuple[str, int]]]:
    """Wait up to ``timeout`` for a datagram, then take every datagram already queued.

    The caller decodes them all (so that sequence numbers of superseded packets are not
    mistaken for losses) and keeps the newest.

    Args:
        sock: A UDP socket (its blocking mode is left as found).
        timeout: Longest wait for the first datagram [s] (0: poll).
        status: Counters (``timeouts``) and the latched error.
        size: Receive buffer size [bytes] (a longer datagram is cut to it).
        limit: Datagrams taken at most (the rest stay queued for the next call).

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
        while len(out) < limit:
            try:
                out.append(sock.recvfrom(size, socket.MSG_DONTWAIT))
            except BlockingIOError:
                return out
        return out
    except ConnectionRefusedError:
        status.fail(LinkErrorKind.CLOSED, "the peer's port is closed (ICMP port unreachable)")
        return out
    except OSError as e:
        status.fail(LinkErrorKind.SOCKET, str(e))
        return out


_logged_defects: set[str] = set()


def decode_packet(data: bytes, decode: Callable[[bytes], P], stats: LinkStats) -> P | None:
    """Decode one packet; a refusal is counted by its code (``bad``, ``malformed``) and gives
    None, never an exception (a codec's own defect is counted as ``UNEXPECTED``, logged once
    per kind of exception). The CPU time spent is added to ``decode_s``.

    Args:
        data: The packet.
        decode: The codec; raises :class:`~leadthrough.errors.DataError` on bad input.
        stats: Counters.

    Returns:
        The decoded packet, or None if refused.
    """
    t0 = time.thread_time()
    try:
        return decode(data)
    except DataError as e:
        stats.refuse(packet_code(e))
        stats.malformed += 1
        return None
    except Exception as e:  # a defect of the codec: counted, never raised into the loop
        stats.refuse(BadPacket.UNEXPECTED)
        stats.malformed += 1
        name = f"{getattr(decode, '__qualname__', decode)}: {type(e).__name__}"
        if name not in _logged_defects:
            _logged_defects.add(name)
            log.error("decoder defect (packet dropped, counted): %s: %s", name, e)
        return None
    finally:
        spent = time.thread_time() - t0
        stats.decode_s += spent
        stats.decode_max_s = max(stats.decode_max_s, spent)


def decode_datagrams(sock: socket.socket, timeout: float, status: LinkStatus,
                     decode: Callable[[bytes], P], size: int = 4096,
                     budget_s: float = PARSE_BUDGET_S,
                     accept: Callable[[tuple[str, int]], bool] | None = None,
                     ) -> Iterator[tuple[P, tuple[str, int]]]:
    """:func:`drain_datagrams`, then decode each (:func:`decode_packet`), oldest first:
    datagrams from a sender that ``accept`` refuses are dropped unparsed (``FOREIGN``), refused
    ones are counted by code and dropped; once ``budget_s`` of decoding is spent the rest are
    dropped unparsed (``BUDGET``), except the drain's newest datagram (one more decode of at
    most ``size`` bytes): the controller waits for the answer to it.

    A generator: ``accept`` is asked for each datagram when it is reached, so a caller that
    fixes its peer on a packet has the rest of the same drain judged by it.

    Args:
        sock: A UDP socket.
        timeout: Longest wait for the first datagram [s].
        status: Counters (``timeouts``, ``malformed``, ``bad``) and the latched error.
        decode: The codec; raises :class:`~leadthrough.errors.DataError` on bad input.
        size: Receive buffer size [bytes].
        budget_s: Decoding CPU time this call may spend [s].
        accept: Whether a sender is the controller (None: every sender).

    Yields:
        The decoded packets with their senders, oldest first.
    """
    stats = status.stats
    spent0 = stats.decode_s
    drained = drain_datagrams(sock, timeout, status, size)
    newest = len(drained) - 1
    for k, (data, addr) in enumerate(drained):
        if accept is not None and not accept(addr):
            stats.refuse(BadPacket.FOREIGN)
            continue
        if stats.decode_s - spent0 > budget_s and k != newest:
            stats.refuse(BadPacket.BUDGET)
            continue
        packet = decode_packet(data, decode, stats)
        if packet is not None:
            yield packet, addr
