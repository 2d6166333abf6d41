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
"""

from __future__ import annotations

import socket
import time
from collections.abc import Sequence

from leadthrough.drivers.kuka_rsi.messages import RobotMessage, SensorMessage
from leadthrough.drivers.link import (
    LinkErrorKind,
    LinkStatus,
    SequenceTracker,
    Transport,
    decode_datagrams,
)
from leadthrough.errors import DriverError

__all__ = ["DEFAULT_PORT", "RsiClient"]

DEFAULT_PORT = 49152


class RsiClient(Transport):
    """The sensor-PC side of an RSI exchange.

    Args:
        host: Local address to listen on.
        port: Local UDP port (the ``PORT`` of the Ethernet configuration; 0: any free port).
        sentype: ``Type`` of the answers (the configuration's ``SENTYPE``).
        precision: Decimals of the corrections sent.
        cycle_ms: RSI cycle [ms] (4; 12 on KR C2), the IPOC step.
    """

    def __init__(self, host: str = "0.0.0.0", port: int = DEFAULT_PORT,
                 sentype: str = "ImFree", precision: int = 6, cycle_ms: int = 4) -> None:
        super().__init__()
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
            DriverError: The port cannot be bound.
        """
        self.close()
        self._link, self._last, self._robot, self.reference = LinkStatus(), None, None, None
        self._ipoc = SequenceTracker(step=self.cycle_ms, bits=64)
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

        Args:
            timeout: Longest wait [s] (0: poll).

        Returns:
            The newest document, or None (timeout or socket error, see :attr:`error`).
        """
        if self._sock is None or self._link.error is not None:
            return None
        newest: RobotMessage | None = None
        stats = self._link.stats
        for msg, addr in decode_datagrams(self._sock, timeout, self._link,
                                          RobotMessage.decode):
            self._ipoc.update(msg.ipoc, stats)
            stats.received += 1
            if newest is not None:
                stats.skipped += 1
            newest, self._robot = msg, addr
        if newest is not None:
            if self.reference is None:
                start = newest.axis_setpoint or newest.axis_actual
                self.reference = tuple(start)
            self._last, self._t_last = newest, time.monotonic()
        return newest

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
        data = SensorMessage(self._last.ipoc, tuple(correction_deg), self.sentype,
                             stop).encode(self.precision)
        try:
            self._sock.sendto(data, self._robot)
        except OSError as e:
            self._link.fail(LinkErrorKind.SOCKET, str(e))
            return False
        self._link.stats.sent += 1
        return True
