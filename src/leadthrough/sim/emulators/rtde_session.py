"""One client connection of the emulated RTDE server: the handshake and recipes.

A :class:`RtdeSession` answers REQUEST_PROTOCOL_VERSION (version 2 only), GET_URCONTROL_VERSION,
the output and input setups, START and PAUSE, and decodes the input DATA_PACKAGEs into writes
of the controller's input variables. Data packages of the output recipe are built by the
controller (:mod:`leadthrough.sim.emulators.ur_rtde`) from its state. Protocol:
:mod:`leadthrough.drivers.ur_rtde.protocol` (sources cited there).

It follows a real controller where independent clients depend on it:

* **Input recipe ids** are numbered per connection, 1, 2, 3, ... in the order of the
  successful CONTROL_PACKAGE_SETUP_INPUTS requests, apart from the output recipe (id 1 of its
  own). Universal Robots' RTDE guide: "each input recipe that has been successfully
  configured will get a unique recipe id". SDU Robotics' ``ur_rtde`` (PyPI ``ur-rtde`` 1.6.5)
  hard-codes the ids a real controller gives: ``RTDEIOInterface`` sends 16 input setups
  (``rtde_io_interface.cpp`` ``setupRecipes``) and then writes register 18 with recipe 7,
  double register 18 with recipe 12 and the speed slider with recipe 4;
  ``RTDEControlInterface`` sends its output setup first, then 23 input setups it addresses as
  recipes 1-23 (``RTDE::RobotCommand::Recipe::RECIPE_1 = 1``). A refused setup answers id 0 and
  takes no id (assumption: the guide gives ids to successful setups only; ``ur_rtde``'s
  numbering holds only when every setup succeeds, which it does here). At most 255 input
  recipes per connection (the id is a uint8); a further setup is refused with id 0.
* **The same variable in several recipes of one connection** is accepted: every recipe of
  ``ur_rtde`` repeats its command register (``input_int_register_23`` for the I/O interface,
  ``input_int_register_0`` for the control interface), which works on real controllers.
  **IN_USE** answers a variable another connection writes (the RTDE guide; ``ur_rtde``'s
  ``rtde.cpp`` raises "One of the RTDE input registers are already in use!" on it), and the
  variable is free again when that connection closes. **NOT_FOUND** answers a name that is not
  an input of the guide's list (:data:`CONTROLLER_INPUTS`); a setup with a NOT_FOUND or IN_USE
  type gets id 0.
* **Input packages before START** are applied: ``ur_rtde``'s ``RTDEIOInterface`` never sends
  CONTROL_PACKAGE_START (observed on the wire with 1.6.5: protocol version, 16 input setups,
  then data packages; PAUSE on disconnect), and its setters are the library's documented way to
  set a real robot's registers, outputs and speed slider. (UR's own Python client refuses to
  send before START on its side, ``rtde.py`` ``send``: a client rule, not the controller's.)
  START still needs an output recipe (there is nothing to send without one).
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Mapping
from typing import Any

from leadthrough.drivers.ur_rtde.protocol import (
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

__all__ = ["CONTROLLER_INPUTS", "MAX_INPUT_RECIPES", "RtdeSession"]

MAX_INPUT_RECIPES = 255
"""Input recipes one connection may set up (the recipe id is a uint8, 0 means refused)."""

CONTROLLER_INPUTS: dict[str, str] = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    **{f"input_bit_register_{i}": "BOOL" for i in range(64, 128)},
    **{f"input_int_register_{i}": "INT32" for i in range(48)},
    **{f"input_double_register_{i}": "DOUBLE" for i in range(48)},
    "external_force_torque": "VECTOR6D",
}
"""The input variables of Universal Robots' RTDE guide (e-Series 5.x list), {name: type}:
speed slider, standard / configurable / tool digital outputs (mask and value), standard
analog outputs (mask, type 0 current / 1 voltage, values as fractions), the boolean input
registers 0-63 as two words and 64-127 one by one, the integer and double registers 0-47
and the external force-torque input. The guide's register ranges: integer and double 0-23
for fieldbus / PLC use, 24-47 for external RTDE clients; boolean 64-127 for RTDE clients."""


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
        self.next_input_id = 1
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
            else:  # before START too, as a real controller (module doc)
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
                         else CONTROLLER_INPUTS.get(n, "NOT_FOUND"))
        if "IN_USE" in types or "NOT_FOUND" in types:
            self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, encode_setup_reply(0, types))
            return
        if self.next_input_id > MAX_INPUT_RECIPES:
            self._text(f"more than {MAX_INPUT_RECIPES} input recipes on one connection")
            self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS, encode_setup_reply(0, types))
            return
        recipe_id = self.next_input_id  # per connection, in order (module doc)
        self.next_input_id += 1
        self.inputs[recipe_id] = Recipe(recipe_id, tuple(names), tuple(types))
        for n in names:
            self.owners[n] = self
        self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS,
                    encode_setup_reply(recipe_id, types))
