"""FANUC Stream Motion (J519) client transport: the external device's UDP socket.

:class:`StreamMotionClient` sends the start packet on :meth:`~StreamMotionClient.open`, then
the loop calls :meth:`~StreamMotionClient.receive` (newest status packet or None, never longer
than its timeout) and answers each status with :meth:`~StreamMotionClient.send` (a command
built by :meth:`~StreamMotionClient.make_command` carries the last status' sequence number and
the I/O read request). Lost status packets show as gaps in the sequence (``stats.missed``); a
closed controller port as :attr:`~StreamMotionClient.error`. The wire format is in
:mod:`leadthrough.drivers.fanuc_j519.packets`.

The socket is connected to the controller's address and port, so the kernel drops datagrams
from any other sender before they reach the client; a packet the codec refuses is counted by
its :class:`~leadthrough.drivers.wire.BadPacket` code (``stats.bad``) and dropped, never raised
(:func:`~leadthrough.drivers.link.decode_datagrams`).
"""

from __future__ import annotations

import contextlib
import socket
import time
from collections.abc import Sequence

from leadthrough.drivers.fanuc_j519.limits import LimitKind
from leadthrough.drivers.fanuc_j519.packets import (
    DEFAULT_PORT,
    CommandPacket,
    IoType,
    LimitAnswer,
    LimitQuery,
    StartPacket,
    StatusPacket,
    StopPacket,
    decode_robot_packet,
)
from leadthrough.drivers.link import (
    PARSE_BUDGET_S,
    LinkErrorKind,
    LinkStatus,
    SequenceTracker,
    Transport,
    decode_datagrams,
)
from leadthrough.errors import DriverError

__all__ = ["StreamMotionClient"]


class StreamMotionClient(Transport):
    """The PC side of a J519 stream.

    Args:
        host: Controller address.
        port: Controller port (60015).
        read_io: (type, index, mask) of the I/O the controller reports in ``read_io_value``
            (default: 16 digital inputs from DI[1]).
    """

    def __init__(self, host: str, port: int = DEFAULT_PORT,
                 read_io: tuple[int, int, int] = (IoType.DI, 1, 0xFFFF)) -> None:
        super().__init__()
        self.host, self.port = host, port
        self.read_io = read_io
        self._sock: socket.socket | None = None
        self._seq = SequenceTracker()
        self._last: StatusPacket | None = None
        self.limits: dict[tuple[int, LimitKind], LimitAnswer] = {}

    # ------------------------------------------------------------------------------ state
    @property
    def last_status(self) -> StatusPacket | None:
        """The newest status packet received."""
        return self._last

    # ------------------------------------------------------------------------------ setup
    def open(self) -> None:
        """Create the socket and send the start packet (the controller then streams status).

        Raises:
            DriverError: The socket cannot be created or the start packet not sent.
        """
        self.close()
        self._link, self._seq, self._last = LinkStatus(), SequenceTracker(), None
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.connect((self.host, self.port))
            sock.send(StartPacket().encode())
        except OSError as e:
            raise DriverError(f"cannot start the J519 stream: {e}", field="host:port",
                               value=f"{self.host}:{self.port}",
                               expected="a reachable J519 controller") from e
        self._sock = sock

    def close(self) -> None:
        """Send the stop packet (best effort) and close the socket."""
        if self._sock is None:
            return
        with contextlib.suppress(OSError):
            self._sock.send(StopPacket().encode())
        self._sock.close()
        self._sock = None

    def query_limits(self, axes: Sequence[int], timeout: float = 1.0) -> dict[
            tuple[int, LimitKind], LimitAnswer]:
        """Ask for the velocity, acceleration and jerk tables of ``axes`` (before streaming).

        Args:
            axes: Axis numbers 1-9.
            timeout: Longest wait for all answers [s].

        Returns:
            {(axis, kind): answer}; also kept in :attr:`limits`.

        Raises:
            DriverError: Not open, or some answers did not arrive in time.
        """
        sock = self._require_open()
        wanted = {(a, k) for a in axes for k in LimitKind}
        try:
            for axis, kind in sorted(wanted):
                sock.send(LimitQuery(axis, kind).encode())
        except OSError as e:
            raise DriverError(f"cannot query the J519 limits: {e}", field="host:port",
                              value=f"{self.host}:{self.port}",
                              expected="a J519 controller listening there") from e
        deadline = time.monotonic() + timeout
        while not wanted <= self.limits.keys() and time.monotonic() < deadline:
            self.receive(deadline - time.monotonic())
            if self._link.error is not None:
                raise DriverError(f"J519 controller unreachable: {self._link.error.detail}",
                                  field="host:port", value=f"{self.host}:{self.port}",
                                  expected="a J519 controller listening there")
        missing = sorted(wanted - self.limits.keys())
        if missing:
            raise DriverError("no limit answer", field="axis/threshold_type", value=missing,
                              expected=f"answers within {timeout} s")
        return {key: self.limits[key] for key in sorted(wanted)}

    def _require_open(self) -> socket.socket:
        if self._sock is None:
            raise DriverError("the J519 client is not open", field="state", value="closed",
                               expected="open() first")
        return self._sock

    # ------------------------------------------------------------------------------ loop
    def receive(self, timeout: float) -> StatusPacket | None:
        """The newest status packet that arrived within ``timeout``, or None.

        Older queued status packets are decoded too (their sequence numbers count, so
        superseded packets are not mistaken for lost ones); malformed packets are counted
        and dropped; limit answers are stored in :attr:`limits`.

        Args:
            timeout: Longest wait [s] (0: poll).

        Returns:
            The newest status, or None (timeout, or the link failed: see :attr:`error`).
        """
        if self._sock is None or self._link.error is not None:
            return None
        newest: StatusPacket | None = None
        stats = self._link.stats
        deadline = time.monotonic() + timeout
        spent0 = stats.decode_s
        # packets that were all refused do not end the wait (a flood of them must not make the
        # caller's cycle return early without a status)
        answers = len(self.limits)
        while newest is None and len(self.limits) == answers and self._link.error is None:
            budget = PARSE_BUDGET_S - (stats.decode_s - spent0)
            for packet, _ in decode_datagrams(self._sock, deadline - time.monotonic(),
                                              self._link, decode_robot_packet,
                                              budget_s=budget):
                if isinstance(packet, LimitAnswer):
                    self.limits[(packet.axis, packet.kind)] = packet
                    continue
                self._seq.update(packet.sequence, stats)
                stats.received += 1
                if newest is not None:
                    stats.skipped += 1
                newest = packet
            if time.monotonic() >= deadline:
                break
        if newest is not None:
            self._last = newest
        return newest

    def make_command(self, joints_deg: Sequence[float], last: bool = False) -> CommandPacket:
        """A joint command answering the newest status packet.

        Args:
            joints_deg: Joint targets [deg], 1-9 values.
            last: Mark the final command of the motion (``last_data``).

        Raises:
            DriverError: No status packet received yet (no sequence number to answer).
        """
        if self._last is None:
            raise DriverError("no status packet yet", field="sequence_no",
                               expected="receive() a status before commanding")
        io_type, io_index, io_mask = self.read_io
        return CommandPacket(sequence=self._last.sequence, positions=tuple(joints_deg),
                             last_data=last, read_io_type=io_type, read_io_index=io_index,
                             read_io_mask=io_mask)

    def send(self, command: CommandPacket) -> bool:
        """Send a command packet.

        Args:
            command: The command (encoding checks it: finite positions, fields in range).

        Returns:
            True if sent; False if the link has failed (see :attr:`error`).

        Raises:
            DriverError: Not open.
            DataError: The command cannot be encoded (nothing is sent).
        """
        sock = self._require_open()
        if self._link.error is not None:
            return False
        data = command.encode()
        try:
            sock.send(data)
        except ConnectionRefusedError:
            self._link.fail(LinkErrorKind.CLOSED, "the controller's port is closed")
            return False
        except OSError as e:
            self._link.fail(LinkErrorKind.SOCKET, str(e))
            return False
        self._link.stats.sent += 1
        return True
