"""KUKA RSI client transport: the sensor PC's UDP socket (the robot sends first).

:class:`RsiClient` binds the port of the Ethernet configuration and waits for the robot's
``<Rob>`` documents; :meth:`~RsiClient.receive` returns the newest one within its timeout and
:meth:`~RsiClient.send` answers it with axis corrections and the same IPOC, to the address it
came from. The answer must leave within the RSI cycle (4 ms) or the robot counts it late.

Corrections are absolute (``RSI_ON(#ABSOLUTE)`` in the shipped KRL program): the robot goes
to start + AK, where start is the axis setpoint at ``RSI_ON``, i.e. ``ASPos`` of the first
document (:attr:`~RsiClient.reference`); :meth:`~RsiClient.correction_for` turns joint targets
into corrections. Lost documents show as IPOC jumps (``stats.missed``); a robot that stopped
RSI sends nothing more (``receive`` returns None, :attr:`~RsiClient.silent_for` grows).

Who is the robot: the client takes ``<Rob>`` documents from one sender only, the robot's
address and port. With ``robot_address`` (the ``--robot-address HOST[:PORT]`` option) that
sender is fixed beforehand (a port left out is fixed by the first valid document from that
host); without it, **the first valid document fixes it** for the rest of the session (until
the next :meth:`~RsiClient.open`): a process that sends a valid document before the robot
does becomes the peer and the robot's own documents are then the foreign ones (the robot,
unanswered, counts late answers and stops RSI after its ``Timeout``). :attr:`~RsiClient.peer`
says who was taken; on a shared network or computer give ``robot_address``. Documents from
any other sender are dropped before they are parsed, counted as ``BadPacket.FOREIGN``; they
are never answered.

The IPOC must advance by whole cycles: by one, or by a few when documents were lost (at most
``max_gap`` cycles: RSI's own ``Timeout`` of late answers, past which the robot has stopped).
A document that steps back or repeats an IPOC (``BadPacket.STALE``: delivered late behind a
newer one) or jumps further or by a fraction of a cycle (``BadPacket.SEQUENCE``) is a bad
packet, dropped; :data:`SEQUENCE_RUN` of them in a row (the robot's
stream is not the one the session follows any more) latch a ``PROTOCOL`` link error, after
which :meth:`~RsiClient.answer_stop` still ends RSI with a ``Stop`` answer to the newest
document of the robot. Every refused document is counted by its code (``stats.bad``), and no
bad document raises out of :meth:`~RsiClient.receive`.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Sequence

from leadthrough.drivers.kuka_rsi.messages import MAX_DOCUMENT_BYTES, RobotMessage, SensorMessage
from leadthrough.drivers.link import (
    PARSE_BUDGET_S,
    LinkErrorKind,
    LinkStatus,
    SequenceTracker,
    Transport,
    decode_datagrams,
)
from leadthrough.drivers.wire import BadPacket
from leadthrough.errors import DriverError

__all__ = ["DEFAULT_PORT", "MAX_GAP", "SEQUENCE_RUN", "RsiClient", "parse_address"]

DEFAULT_PORT = 49152
#: Cycles an IPOC may advance by at most (lost documents): the shipped context's ``Timeout``.
MAX_GAP = 100
#: Documents of the robot in a row with a bad IPOC that latch a ``PROTOCOL`` link error.
SEQUENCE_RUN = 5


def parse_address(text: str) -> tuple[str, int | None]:
    """``HOST[:PORT]`` (the ``--robot-address`` option) as (host, port or None).

    Raises:
        DriverError: An empty host or a port outside 1..65535.
    """
    host, sep, port = text.strip().rpartition(":")
    if not sep:
        host, port = port, ""
    if not host or (port and not (port.isdigit() and 0 < int(port) < 65536)) or (
            sep and not port):
        raise DriverError("not an address", field="robot_address", value=text,
                          expected="HOST or HOST:PORT, PORT 1..65535")
    return host, int(port) if port else None


class RsiClient(Transport):
    """The sensor-PC side of an RSI exchange.

    Args:
        host: Local address to listen on.
        port: Local UDP port (the ``PORT`` of the Ethernet configuration; 0: any free port).
        sentype: ``Type`` of the answers (the configuration's ``SENTYPE``).
        precision: Decimals of the corrections sent.
        cycle_ms: RSI cycle [ms] (4; 12 on KR C2), the IPOC step.
        robot_address: The robot's (host, port); port None: fixed by the first valid
            document from host; None: both fixed by the first valid document (module doc).
        max_gap: Cycles the IPOC may advance by at most (lost documents).
    """

    def __init__(self, host: str = "0.0.0.0", port: int = DEFAULT_PORT,
                 sentype: str = "ImFree", precision: int = 6, cycle_ms: int = 4,
                 robot_address: tuple[str, int | None] | None = None,
                 max_gap: int = MAX_GAP) -> None:
        super().__init__()
        self.robot_address = robot_address
        self.max_gap = max_gap
        self._robot_host: str | None = None
        self._pending: tuple[int, tuple[str, int]] | None = None  # (IPOC, sender) of the
        self._bad_run = 0                                          # newest bad-IPOC document
        self.host, self.port = host, port
        self.sentype, self.precision, self.cycle_ms = sentype, precision, cycle_ms
        self._sock: socket.socket | None = None
        self._ipoc = SequenceTracker(step=cycle_ms, bits=64)
        self._last: RobotMessage | None = None
        self._robot: tuple[str, int] | None = None
        self._t_last = 0.0
        self.reference: tuple[float, ...] | None = None

    @property
    def address(self) -> tuple[str, int]:
        """The bound (address, port); the port is the real one when 0 was asked."""
        if self._sock is None:
            return (self.host, self.port)
        host, port = self._sock.getsockname()[:2]
        return (str(host), int(port))

    @property
    def peer(self) -> tuple[str, int] | None:
        """The robot's (address, port) the documents are taken from (None: not fixed yet)."""
        return self._robot

    @property
    def bound(self) -> bool:
        """Whether the port is bound (``open`` was called and not closed since)."""
        return self._sock is not None

    @property
    def last_message(self) -> RobotMessage | None:
        """The newest ``<Rob>`` document received."""
        return self._last

    @property
    def silent_for(self) -> float:
        """Time since the last document [s] (inf before the first)."""
        return time.monotonic() - self._t_last if self._last is not None else float("inf")

    def open(self) -> None:
        """Bind the UDP port.

        Raises:
            DriverError: The port cannot be bound, or ``robot_address`` does not resolve.
        """
        self.close()
        self._link, self._last, self._robot, self.reference = LinkStatus(), None, None, None
        self._ipoc = SequenceTracker(step=self.cycle_ms, bits=64)
        self._pending, self._bad_run, self._robot_host = None, 0, None
        if self.robot_address is not None:
            host, port = self.robot_address
            try:
                self._robot_host = socket.gethostbyname(host)
            except OSError as e:
                raise DriverError(f"cannot resolve the robot's address: {e}",
                                  field="robot_address", value=host,
                                  expected="an IPv4 address or a resolvable name") from e
            if port is not None:
                self._robot = (self._robot_host, port)
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind((self.host, self.port))
        except OSError as e:
            raise DriverError(f"cannot bind the RSI port: {e}", field="host:port",
                               value=f"{self.host}:{self.port}", expected="a free UDP port") from e
        self._sock = sock

    def close(self) -> None:
        """Close the socket (the robot then counts late answers and stops RSI)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def receive(self, timeout: float) -> RobotMessage | None:
        """The newest ``<Rob>`` document that arrived within ``timeout``, or None.

        Documents from another sender than the robot, refused by the codec, with a bad IPOC,
        or past the cycle's parse budget are counted (``stats.bad``) and dropped (module doc).

        Args:
            timeout: Longest wait [s] (0: poll).

        Returns:
            The newest document, or None (timeout, socket error or a broken IPOC stream, see
            :attr:`error`).
        """
        if self._sock is None or self._link.error is not None:
            return None
        newest: RobotMessage | None = None
        stats = self._link.stats
        spent0 = stats.decode_s
        deadline = time.monotonic() + timeout
        # datagrams that were all dropped (foreign, refused) do not end the wait: a flood of
        # them must not make the caller's cycle return early without a document
        while newest is None and self._link.error is None:
            newest = self._take(self._sock, deadline - time.monotonic(), spent0, newest)
            if time.monotonic() >= deadline:
                break
        if newest is not None:
            if self.reference is None:
                start = newest.axis_setpoint or newest.axis_actual
                self.reference = tuple(start)
            self._last, self._t_last = newest, time.monotonic()
        return newest

    def _take(self, sock: socket.socket, timeout: float, spent0: float,
              newest: RobotMessage | None) -> RobotMessage | None:
        """One drain of ``sock``: the newest document of the robot taken, or ``newest``."""
        stats = self._link.stats
        for msg, addr in decode_datagrams(sock, timeout, self._link, RobotMessage.decode,
                                          MAX_DOCUMENT_BYTES + 1,
                                          PARSE_BUDGET_S - (stats.decode_s - spent0),
                                          self._from_robot):
            if not self._in_sequence(msg, addr):
                continue
            self._ipoc.update(msg.ipoc, stats)
            stats.received += 1
            if newest is not None:
                stats.skipped += 1
            newest, self._robot, self._pending = msg, addr, None
        return newest

    def _from_robot(self, addr: tuple[str, int]) -> bool:
        """Whether ``addr`` is the robot: its address and port once fixed (by
        ``robot_address`` or the first valid document), its host if only that was given."""
        robot = self._robot
        return not ((robot is not None and addr != robot) or (
            self._robot_host is not None and addr[0] != self._robot_host))

    def _in_sequence(self, msg: RobotMessage, addr: tuple[str, int]) -> bool:
        """Whether ``msg``'s IPOC follows the last one taken by whole cycles, at most
        ``max_gap`` (else counted; a run latches the link error, see the module doc)."""
        last = self._ipoc.last
        if last is None:
            return True
        ahead = msg.ipoc - last
        if 0 < ahead <= self.max_gap * self.cycle_ms and ahead % self.cycle_ms == 0:
            self._bad_run = 0
            return True
        self._link.stats.refuse(BadPacket.SEQUENCE if ahead > 0 else BadPacket.STALE)
        self._pending = (msg.ipoc, addr)
        self._bad_run += 1
        if self._bad_run >= SEQUENCE_RUN:
            self._link.fail(LinkErrorKind.PROTOCOL,
                            f"{self._bad_run} documents in a row with an IPOC that does not "
                            f"follow {last} by whole cycles of {self.cycle_ms} ms (the newest "
                            f"{msg.ipoc})")
        return False

    def correction_for(self, target_deg: Sequence[float]) -> tuple[float, ...]:
        """Absolute corrections AK = target - reference [deg].

        Raises:
            DriverError: No document received yet (no reference).
        """
        if self.reference is None:
            raise DriverError("no reference yet", field="ASPos",
                               expected="receive() the first <Rob> document first")
        return tuple(float(t) - r for t, r in zip(target_deg, self.reference, strict=True))

    def send(self, correction_deg: Sequence[float], stop: bool = False) -> bool:
        """Answer the newest document with corrections AK [deg] and its IPOC (``stop``: with
        ``<Stop>1</Stop>``, the session's last answer).

        Returns:
            True if sent; False if nothing to answer yet or the link failed.

        Raises:
            DriverError: Not open.
            DataError: Not 6 finite corrections (nothing is sent).
        """
        if self._sock is None:
            raise DriverError("the RSI client is not open", field="state", value="closed",
                               expected="open() first")
        if self._last is None or self._robot is None or self._link.error is not None:
            return False
        return self._answer(self._last.ipoc, correction_deg, stop)

    def _answer(self, ipoc: int, correction_deg: Sequence[float], stop: bool) -> bool:
        """Send the answer to the document ``ipoc`` to the robot; False if the send failed
        (the link then broken)."""
        if self._sock is None or self._robot is None:      # (the callers checked already)
            return False
        data = SensorMessage(ipoc, tuple(correction_deg), self.sentype,
                             stop).encode(self.precision)
        try:
            self._sock.sendto(data, self._robot)
        except OSError as e:
            self._link.fail(LinkErrorKind.SOCKET, str(e))
            return False
        self._link.stats.sent += 1
        return True

    def answer_stop(self, correction_deg: Sequence[float]) -> bool:
        """After a ``PROTOCOL`` link error (a broken IPOC stream), the session's last answer:
        ``<Stop>1</Stop>`` with ``correction_deg`` [deg] to the newest document of the robot
        (one with a bad IPOC included: the robot waits for its answer). On a healthy link use
        :meth:`send` with ``stop=True``.

        Returns:
            True if sent; False if the link is healthy or broken otherwise (socket, closed),
            nothing was received from the robot, or the send failed.
        """
        err = self._link.error
        if self._sock is None or self._robot is None or err is None or (
                err.kind is not LinkErrorKind.PROTOCOL):
            return False
        if self._pending is not None:
            ipoc = self._pending[0]
        elif self._last is not None:
            ipoc = self._last.ipoc
        else:
            return False
        return self._answer(ipoc, correction_deg, True)
