"""One client connection of the emulated RTDE server: the handshake and recipes.

A :class:`RtdeSession` answers REQUEST_PROTOCOL_VERSION (version 2 only), GET_URCONTROL_VERSION,
the output and input setups (NOT_FOUND for variables the emulator does not produce or know,
IN_USE for input variables another connection writes), START and PAUSE, and decodes the input
DATA_PACKAGEs into register writes. Data packages of the output recipe are built by the
controller (:mod:`leadthrough.sim.emulators.ur_rtde`) from its state. Protocol:
:mod:`leadthrough.drivers.ur_rtde.protocol` (sources cited there).
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Mapping
from typing import Any

from leadthrough.drivers.ur_rtde.protocol import (
    INPUT_TYPES,
    PROTOCOL_VERSION,
    ControllerVersion,
    FrameReader,
    MessageType,
    Recipe,
    TextMessage,
    decode_setup_inputs,
    decode_setup_outputs,
    decode_version_request,
    encode_accepted,
    encode_setup_reply,
    frame,
)
from leadthrough.errors import DataError
from leadthrough.sim.emulators.answer_timing import recv_stamped

__all__ = ["RtdeSession"]


class RtdeSession:
    """A connected RTDE client.

    Args:
        sock: The accepted, non-blocking socket.
        version: What GET_URCONTROL_VERSION answers.
        rate: The controller's cycle rate [Hz] (500 e-Series, 125 CB3).
        produced: Output variables the controller can fill, {name: type}.
        owners: Input variable -> owning session, shared by all sessions.
        write: Called with {input name: value}, the package's receive time [s,
            ``CLOCK_REALTIME``] and whether that time is its own (see
            :mod:`~leadthrough.sim.emulators.answer_timing`) for each input data package.
    """

    def __init__(self, sock: socket.socket, version: ControllerVersion, rate: float,
                 produced: Mapping[str, str], owners: dict[str, RtdeSession],
                 write: Callable[[dict[str, Any], float, bool], None]) -> None:
        self.sock, self.version, self.rate = sock, version, rate
        self.produced, self.owners, self.write = produced, owners, write
        self.reader = FrameReader()
        self.output: Recipe | None = None
        self.divider = 1
        self.inputs: dict[int, Recipe] = {}
        self.started = False
        self.open = True
        self.requested_outputs: list[str] = []

    def output_package(self, values: Mapping[str, Any]) -> bytes:
        """A DATA_PACKAGE of the output recipe (call only once it is set up)."""
        if self.output is None:
            raise DataError("no output recipe", source="RTDE emulator", field="recipe",
                            expected="CONTROL_PACKAGE_SETUP_OUTPUTS first")
        return frame(MessageType.DATA_PACKAGE, self.output.encode(values))

    def close(self) -> None:
        """Close the connection and release its input variables."""
        if self.open:
            self.open = False
            self.sock.close()
            for name in [n for n, s in self.owners.items() if s is self]:
                del self.owners[name]

    def receive(self) -> None:
        """Read what arrived and answer every complete request (the requests that arrived
        before the client closed the connection included).

        Each read carries the kernel's receive time of its newest segment (TCP merges the
        segments that wait unread): the last frame it completes has that time as its own,
        the earlier ones only as an upper bound."""
        gone = False
        while self.open:
            try:
                data, _, rx, exact = recv_stamped(self.sock)
            except BlockingIOError:
                break
            except OSError:
                gone = True
                break
            if not data:
                gone = True
                break
            self.reader.feed(data)
            self._handle_complete(rx, exact)
        if gone:
            self.close()

    def _handle_complete(self, rx: float, exact: bool) -> None:
        """Answer the frames the last read completed."""
        try:
            frames = []
            while (msg := self.reader.next()) is not None:
                frames.append(msg)
            for i, (mtype, payload) in enumerate(frames):
                if not self.open:
                    break
                self._handle(mtype, payload, rx, exact and i == len(frames) - 1)
        except DataError as e:
            self._text(f"protocol error: {e}", level=0)
            self.close()

    def _reply(self, mtype: int, payload: bytes = b"") -> None:
        try:
            self.sock.sendall(frame(mtype, payload))
        except OSError:
            self.close()

    def _text(self, message: str, level: int = 1) -> None:
        self._reply(MessageType.TEXT_MESSAGE, TextMessage(message, "leadthrough emulator",
                                                          level).encode())

    def _handle(self, mtype: int, payload: bytes, rx: float = 0.0, exact: bool = False) -> None:
        if mtype == MessageType.REQUEST_PROTOCOL_VERSION:
            self._reply(mtype, encode_accepted(decode_version_request(payload)
                                               == PROTOCOL_VERSION))
        elif mtype == MessageType.GET_URCONTROL_VERSION:
            self._reply(mtype, self.version.encode())
        elif mtype == MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS:
            self._setup_outputs(payload)
        elif mtype == MessageType.CONTROL_PACKAGE_SETUP_INPUTS:
            self._setup_inputs(payload)
        elif mtype == MessageType.CONTROL_PACKAGE_START:
            self.started = self.output is not None
            self._reply(mtype, encode_accepted(self.started))
        elif mtype == MessageType.CONTROL_PACKAGE_PAUSE:
            self.started = False
            self._reply(mtype, encode_accepted(True))
        elif mtype == MessageType.DATA_PACKAGE and payload:
            recipe = self.inputs.get(payload[0])
            if recipe is None:
                self._text(f"unknown input recipe id {payload[0]}")
            elif self.started:
                self.write(recipe.decode(payload), rx, exact)
        elif mtype != MessageType.TEXT_MESSAGE:
            self._text(f"unknown message type {mtype}")

    def _setup_outputs(self, payload: bytes) -> None:
        frequency, names = decode_setup_outputs(payload)
        self.requested_outputs = names
        types = [self.produced.get(n, "NOT_FOUND") for n in names]
        if not 0 < frequency <= self.rate:
            self._text(f"output frequency {frequency} Hz outside 0 < f <= {self.rate:g} Hz")
            self._reply(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, encode_setup_reply(0, types))
            return
        if "NOT_FOUND" in types:
            self._reply(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, encode_setup_reply(0, types))
            return
        self.output = Recipe(1, tuple(names), tuple(types))
        self.divider = max(1, round(self.rate / frequency))
        self._reply(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, encode_setup_reply(1, types))

    def _setup_inputs(self, payload: bytes) -> None:
        names = decode_setup_inputs(payload)
        types = []
        for n in names:
            owner = self.owners.get(n)
            types.append("IN_USE" if owner is not None and owner is not self
                         else INPUT_TYPES.get(n, "NOT_FOUND"))
        if "IN_USE" in types or "NOT_FOUND" in types:
            self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, encode_setup_reply(0, types))
            return
        recipe_id = len(self.inputs) + 2  # 1 is the output recipe
        self.inputs[recipe_id] = Recipe(recipe_id, tuple(names), tuple(types))
        for n in names:
            self.owners[n] = self
        self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS,
                    encode_setup_reply(recipe_id, types))
