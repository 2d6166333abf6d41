"""Universal Robots RTDE client transport (TCP 30004) for the external-control program.

:meth:`RtdeClient.open` runs the handshake (protocol version 2, controller version, output
recipe at the controller's frequency, input recipe of the joint-target and watchdog
registers, start); then :meth:`RtdeClient.receive` returns the newest :class:`RtdeState`
within its timeout and :meth:`RtdeClient.send` writes a :class:`ServoCommand` into the
registers that the URScript program (:mod:`leadthrough.drivers.ur_rtde.script`) reads. A
closed connection is :attr:`RtdeClient.error`; a protective stop shows in the state's
``safety_mode`` / ``safety_status_bits``; missed data packages show as jumps of the controller
``timestamp`` (``stats.missed``).

No bad message raises out of :meth:`RtdeClient.receive`: a data package the recipe refuses, or
whose ``timestamp`` is not finite (``NONFINITE``), beyond :data:`MAX_TIMESTAMP_S` or negative
(``FIELD``) or not after the last one (``STALE``), a text
message that does not parse, and a message of a type the protocol does not define are each
counted by their
:class:`~leadthrough.drivers.wire.BadPacket` code (``stats.bad``) and dropped. Only a corrupt
header (a size below 3: the TCP stream can no longer be split) breaks the link (``PROTOCOL``).
Text messages are kept in a ring of the newest :data:`MAX_TEXT_MESSAGES`
(:attr:`RtdeClient.messages`; ``messages_dropped`` counts the older ones).
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from leadthrough.drivers.link import (
    LinkErrorKind,
    LinkStats,
    LinkStatus,
    Transport,
    decode_packet,
)
from leadthrough.drivers.ur_rtde.protocol import (
    DEFAULT_PORT,
    PROTOCOL_VERSION,
    ControllerVersion,
    FrameReader,
    MessageType,
    Recipe,
    TextMessage,
    decode_accepted,
    decode_setup_reply,
    encode_setup_inputs,
    encode_setup_outputs,
    encode_version_request,
    frame,
)
from leadthrough.drivers.wire import BadPacket, PacketError, check_finite
from leadthrough.errors import DataError, DriverError

__all__ = ["DEFAULT_OUTPUTS", "MAX_TEXT_MESSAGES", "RtdeClient", "RtdeState", "ServoCommand"]

#: The largest ``timestamp`` taken [s] (about 30 years of controller uptime).
MAX_TIMESTAMP_S = 1e9
#: Text messages kept (the newest).
MAX_TEXT_MESSAGES = 64
_KNOWN_TYPES = frozenset(int(t) for t in MessageType)

DEFAULT_OUTPUTS: tuple[str, ...] = (
    "timestamp", "actual_q", "actual_current", "actual_digital_input_bits", "robot_mode",
    "safety_mode", "safety_status_bits", "runtime_state", "output_int_register_0")


@dataclass(frozen=True)
class RtdeState:
    """One output data package.

    Attributes:
        timestamp: Controller time since start [s].
        q: ``actual_q`` [rad], 6 values.
        current: ``actual_current`` [A], 6 values.
        values: Every variable of the output recipe by name.
    """

    timestamp: float
    q: tuple[float, ...]
    current: tuple[float, ...]
    values: dict[str, Any]

    @property
    def protective_stop(self) -> bool:
        """``safety_mode`` 3 (PROTECTIVE_STOP) or bit 2 of ``safety_status_bits``."""
        bits = int(self.values.get("safety_status_bits", 0))
        return self.values.get("safety_mode") == 3 or bool(bits & 4)


@dataclass(frozen=True)
class ServoCommand:
    """What the URScript program reads each cycle.

    Attributes:
        q: Joint targets [rad], 6 finite values.
        counter: Watchdog counter (change it every cycle).
        mode: 0 hold, 1 servo, 2 stop.
    """

    q: tuple[float, ...]
    counter: int
    mode: int = 1


class RtdeClient(Transport):
    """An RTDE connection set up for :class:`ServoCommand` s.

    Args:
        host: Controller address.
        port: RTDE port (30004).
        outputs: Output recipe (must contain ``timestamp``, ``actual_q``, ``actual_current``).
        frequency: Output frequency [Hz]; None: the controller's (500 e-Series, 125 CB3).
        register_offset: First register of the program (0 or 24).
        timeout: Handshake timeout per request [s].
    """

    def __init__(self, host: str, port: int = DEFAULT_PORT,
                 outputs: Sequence[str] = DEFAULT_OUTPUTS, frequency: float | None = None,
                 register_offset: int = 0, timeout: float = 1.0) -> None:
        super().__init__()
        self.host, self.port, self.timeout = host, port, timeout
        self.outputs = tuple(outputs)
        self.frequency = frequency
        r = register_offset
        self.inputs = (*(f"input_double_register_{r + i}" for i in range(6)),
                       f"input_int_register_{r}", f"input_int_register_{r + 1}")
        self.controller_version: ControllerVersion | None = None
        #: The newest text messages of the controller (at most :data:`MAX_TEXT_MESSAGES`).
        self.messages: deque[TextMessage] = deque(maxlen=MAX_TEXT_MESSAGES)
        #: Text messages pushed out of :attr:`messages` by newer ones.
        self.messages_dropped = 0
        self._sock: socket.socket | None = None
        self._reader = FrameReader()
        self._out: Recipe | None = None
        self._in: Recipe | None = None
        self._last_t: float | None = None

    # ------------------------------------------------------------------------- handshake
    def open(self) -> None:
        """Connect and run the handshake; the controller then streams data packages.

        Raises:
            DriverError: No connection, or the controller refused a request (naming the
                variable it did not know or that another client writes).
        """
        self.close()
        self._reader, self._link, self._last_t = FrameReader(), LinkStatus(), None
        try:
            self._sock = socket.create_connection((self.host, self.port), self.timeout)
            self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError as e:
            raise DriverError(f"cannot connect to RTDE: {e}", field="host:port",
                               value=f"{self.host}:{self.port}",
                               expected="a reachable UR controller") from e
        try:
            self._handshake()
        except (DriverError, DataError):
            self.close()
            raise

    def _handshake(self) -> None:
        ok = self._request(MessageType.REQUEST_PROTOCOL_VERSION, encode_version_request())
        if not decode_accepted(ok, "RTDE protocol version reply"):
            raise DriverError("protocol version refused", field="protocol_version",
                               value=PROTOCOL_VERSION, expected="a controller speaking v2")
        version = ControllerVersion.decode(self._request(MessageType.GET_URCONTROL_VERSION))
        self.controller_version = version
        if self.frequency is None:
            self.frequency = 500.0 if version.major >= 5 else 125.0
        self._out = self._setup(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, self.outputs,
                                encode_setup_outputs(self.frequency, self.outputs))
        self._in = self._setup(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, self.inputs,
                               encode_setup_inputs(self.inputs))
        started = self._request(MessageType.CONTROL_PACKAGE_START)
        if not decode_accepted(started, "RTDE start reply"):
            raise DriverError("start refused", field="state", value="setup",
                               expected="the controller to start synchronisation")

    def _setup(self, mtype: MessageType, names: tuple[str, ...], payload: bytes) -> Recipe:
        recipe_id, types = decode_setup_reply(self._request(mtype, payload))
        for name, t in zip(names, types, strict=False):
            if t in ("NOT_FOUND", "IN_USE"):
                raise DriverError(f"variable {t}", field=name, value=t,
                                   expected="a variable the controller offers and nobody "
                                   "else writes")
        if recipe_id == 0 or len(types) != len(names):
            raise DriverError("recipe refused", field="recipe", value=(recipe_id, types),
                               expected=f"an id > 0 and {len(names)} types")
        return Recipe(recipe_id, names, tuple(types))

    def _request(self, mtype: MessageType, payload: bytes = b"") -> bytes:
        """Send a request, return the payload of the answer of the same type."""
        sock = self._require_open()
        sock.sendall(frame(mtype, payload))
        deadline = time.monotonic() + self.timeout
        while True:
            msg = self._reader.next()
            if msg is not None:
                if msg[0] == mtype:
                    return msg[1]
                if msg[0] == MessageType.TEXT_MESSAGE:
                    self._text(msg[1])
                continue
            left = deadline - time.monotonic()
            if left <= 0 or not self._fill(left):
                raise DriverError(f"no answer from {self.host}:{self.port}", field="request",
                                   value=mtype.name,
                                   expected=f"an answer within {self.timeout} s (a UR "
                                            "controller's RTDE interface at that address)")

    def _fill(self, timeout: float) -> bool:
        """Read what arrives within ``timeout``; False on timeout or a closed connection."""
        sock = self._require_open()
        try:
            ready, _, _ = select.select([sock], [], [], max(timeout, 0.0))
            if not ready:
                return False
            data = sock.recv(65536)
        except OSError as e:
            # a reset is the peer closing with our commands still unread (its kernel answers
            # them with RST): closed, as in send_command; anything else is the socket's
            kind = LinkErrorKind.CLOSED if isinstance(e, ConnectionError) else (
                LinkErrorKind.SOCKET)
            self._link.fail(kind, str(e))
            return False
        if not data:
            self._link.fail(LinkErrorKind.CLOSED, "the controller closed the connection")
            return False
        self._reader.feed(data)
        return True

    def _require_open(self) -> socket.socket:
        if self._sock is None:
            raise DriverError("the RTDE client is not open", field="state", value="closed",
                               expected="open() first")
        return self._sock

    def close(self) -> None:
        """Pause synchronisation (best effort) and close the connection."""
        if self._sock is None:
            return
        with contextlib.suppress(OSError):
            self._sock.sendall(frame(MessageType.CONTROL_PACKAGE_PAUSE))
        self._sock.close()
        self._sock = None

    # ------------------------------------------------------------------------------ loop
    def receive(self, timeout: float) -> RtdeState | None:
        """The newest data package that arrived within ``timeout``, or None.

        Args:
            timeout: Longest wait [s] (0: poll).

        Returns:
            The newest state, or None (timeout, or the link failed: see :attr:`error`).
        """
        recipe = self._out
        if self._sock is None or recipe is None or self._link.error is not None:
            return None
        deadline = time.monotonic() + timeout
        newest = self._drain(recipe)
        while newest is None and self._link.error is None:
            left = deadline - time.monotonic()
            if left <= 0 or not self._fill(left):
                break
            newest = self._drain(recipe)
        if newest is None and self._link.error is None:
            self._link.stats.timeouts += 1
        return newest

    def feed(self, data: bytes) -> RtdeState | None:
        """Take ``data`` as bytes received from the controller (after the handshake) and
        decode every complete message: the newest data package, or None. Never raises for
        what the bytes hold (module doc); a corrupt header latches :attr:`error`."""
        if self._out is None or self._link.error is not None:
            return None
        self._reader.feed(data)
        return self._drain(self._out)

    def _text(self, payload: bytes) -> None:
        text = decode_packet(payload, TextMessage.decode, self._link.stats)
        if text is not None:
            if len(self.messages) == self.messages.maxlen:
                self.messages_dropped += 1
            self.messages.append(text)

    def _drain(self, recipe: Recipe) -> RtdeState | None:
        """Decode every complete message buffered; return the newest data package."""
        stats, newest = self._link.stats, None
        while True:
            try:
                msg = self._reader.next()
            except DataError as e:
                self._link.fail(LinkErrorKind.PROTOCOL, str(e))
                return newest
            if msg is None:
                return newest
            mtype, payload = msg
            if mtype == MessageType.TEXT_MESSAGE:
                self._text(payload)
                continue
            if mtype != MessageType.DATA_PACKAGE:
                if mtype not in _KNOWN_TYPES:
                    stats.refuse(BadPacket.UNKNOWN_TYPE)
                continue
            state = decode_packet(payload, lambda p: self._state(recipe, p), stats)
            if state is None:
                continue
            self._count(state.timestamp, stats)
            if newest is not None:
                stats.skipped += 1
            newest = state

    def _state(self, recipe: Recipe, payload: bytes) -> RtdeState:
        """A data package as a state; a timestamp not finite, or before the last one, is
        refused (PacketError)."""
        values = recipe.decode(payload)
        t = float(values["timestamp"])
        if not math.isfinite(t):
            raise PacketError("not finite", code=BadPacket.NONFINITE,
                              source="RTDE data package", field="timestamp", value=t,
                              expected="a finite controller time [s]")
        if not 0.0 <= t <= MAX_TIMESTAMP_S:
            raise PacketError("out of range", code=BadPacket.FIELD,
                              source="RTDE data package", field="timestamp", value=t,
                              expected=f"0..{MAX_TIMESTAMP_S:g} s since the controller started")
        if self._last_t is not None and t <= self._last_t:
            raise PacketError("not after the last one", code=BadPacket.STALE,
                              source="RTDE data package", field="timestamp", value=t,
                              expected=f"> {self._last_t} s")
        return RtdeState(t, values["actual_q"], values["actual_current"], values)

    def _count(self, t: float, stats: LinkStats) -> None:
        period = 1.0 / (self.frequency or 500.0)
        if self._last_t is not None:
            missing = round((t - self._last_t) / period) - 1   # bounded: t <= 1e9 s
            if missing > 0:
                stats.gaps += 1
                stats.missed += missing
                stats.last_gap = missing
        self._last_t = t
        stats.received += 1

    def send(self, command: ServoCommand) -> bool:
        """Write the command into the program's input registers.

        Returns:
            True if sent; False if the link has failed (see :attr:`error`).

        Raises:
            DriverError: Not open.
            DataError: Not 6 finite targets, or a counter / mode outside int32 (nothing sent).
        """
        sock = self._require_open()
        if self._in is None or self._link.error is not None:
            return False
        check_finite("RTDE servo command", "q", command.q, 6)
        names = self._in.names
        values = dict(zip(names[:6], command.q, strict=True))
        values[names[6]], values[names[7]] = command.counter, command.mode
        data = frame(MessageType.DATA_PACKAGE, self._in.encode(values))
        try:
            sock.sendall(data)
        except OSError as e:
            kind = LinkErrorKind.CLOSED if isinstance(e, ConnectionError) else (
                LinkErrorKind.SOCKET)
            self._link.fail(kind, str(e))
            return False
        self._link.stats.sent += 1
        return True
