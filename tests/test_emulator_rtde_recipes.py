"""The emulated UR controller's RTDE recipes follow a real controller's rules, on real loopback
sockets with the RTDE wire format written from UR's RTDE guide: input recipe ids per
connection from 1 in the order of successful setups, a refused setup id 0 (NOT_FOUND for a
name outside the guide's input list, IN_USE for a variable another connection writes), the same
variable in several recipes of one connection, input packages applied before START, and the
input registers readable as outputs of the same name."""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from leadthrough.drivers.ur_rtde.protocol import (
    FrameReader,
    MessageType,
    Recipe,
    decode_setup_reply,
    encode_setup_inputs,
    encode_setup_outputs,
    encode_version_request,
    frame,
)
from leadthrough.robot.description import Robot, load_robot
from leadthrough.sim.emulators import start
from leadthrough.sim.emulators.rtde_session import CONTROLLER_INPUTS, MAX_INPUT_RECIPES
from leadthrough.sim.emulators.runner import RunningEmulator
from leadthrough.sim.emulators.scenario import EmulatorOptions

POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)


class RawRtde:
    """A bare RTDE connection: each request waits for the answer of its own type."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self.reader = FrameReader()
        assert self.request(MessageType.REQUEST_PROTOCOL_VERSION, encode_version_request()) \
            == b"\x01"

    def request(self, mtype: int, payload: bytes = b"") -> bytes:
        self.sock.sendall(frame(mtype, payload))
        return self.wait(mtype)

    def wait(self, mtype: int) -> bytes:
        while True:
            while (msg := self.reader.next()) is not None:
                if msg[0] == mtype:
                    return msg[1]
            data = self.sock.recv(65536)
            assert data, "the emulator closed the connection"
            self.reader.feed(data)

    def setup_inputs(self, names: list[str]) -> tuple[int, list[str]]:
        return decode_setup_reply(self.request(MessageType.CONTROL_PACKAGE_SETUP_INPUTS,
                                               encode_setup_inputs(names)))

    def setup_outputs(self, names: list[str], frequency: float = 500.0) -> tuple[int, list[str]]:
        return decode_setup_reply(self.request(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
                                               encode_setup_outputs(frequency, names)))

    def send(self, recipe: Recipe, values: dict[str, Any]) -> None:
        self.sock.sendall(frame(MessageType.DATA_PACKAGE, recipe.encode(values)))

    def close(self) -> None:
        self.sock.close()


@pytest.fixture(scope="module")
def ur5() -> Robot:
    return load_robot("ur5")


@contextmanager
def _emulator(robot: Robot) -> Iterator[RunningEmulator]:
    with start("ur-rtde", robot, seed=3, port=0, options=EmulatorOptions(q0=POSE)) as emu:
        yield emu


def _int(i: int) -> str:
    return f"input_int_register_{i}"


def _double(i: int) -> str:
    return f"input_double_register_{i}"


def test_input_recipe_ids_count_per_connection_from_one(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        a = RawRtde(emu.port)
        assert a.setup_outputs(["timestamp", "actual_q"])[0] == 1   # the output recipe's own id
        assert a.setup_inputs([_int(18)]) == (1, ["INT32"])         # inputs count from 1 apart
        assert a.setup_inputs([_int(19), "bogus"]) == (0, ["INT32", "NOT_FOUND"])
        assert a.setup_inputs([_int(19)])[0] == 2                   # a refusal takes no id
        # the same variable in another recipe of the same connection (ur_rtde's command register)
        assert a.setup_inputs([_int(18), "speed_slider_mask", "speed_slider_fraction"]) == (
            3, ["INT32", "UINT32", "DOUBLE"])
        b = RawRtde(emu.port)
        assert b.setup_inputs([_int(30)])[0] == 1                   # per connection
        assert b.setup_inputs([_int(31), _int(18)]) == (0, ["INT32", "IN_USE"])  # a's register
        a.close()
        deadline = time.monotonic() + 5.0
        while True:  # a's variables are free once the emulator saw it close
            reply = b.setup_inputs([_int(18)])
            if reply[0] or time.monotonic() > deadline:
                break
            time.sleep(0.005)
        assert reply == (2, ["INT32"])
        b.close()


def test_at_most_255_input_recipes_per_connection(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        c = RawRtde(emu.port)
        ids = [c.setup_inputs([_int(40)])[0] for _ in range(MAX_INPUT_RECIPES + 1)]
        c.close()
    assert ids == [*range(1, 256), 0]


@pytest.mark.parametrize(("name", "expected"), [
    ("speed_slider_mask", "UINT32"), ("speed_slider_fraction", "DOUBLE"),
    ("standard_digital_output_mask", "UINT8"), ("standard_digital_output", "UINT8"),
    ("configurable_digital_output_mask", "UINT8"), ("configurable_digital_output", "UINT8"),
    ("tool_digital_output_mask", "UINT8"), ("tool_digital_output", "UINT8"),
    ("standard_analog_output_mask", "UINT8"), ("standard_analog_output_type", "UINT8"),
    ("standard_analog_output_0", "DOUBLE"), ("standard_analog_output_1", "DOUBLE"),
    ("input_bit_registers0_to_31", "UINT32"), ("input_bit_registers32_to_63", "UINT32"),
    ("input_bit_register_64", "BOOL"), ("input_bit_register_127", "BOOL"),
    ("input_int_register_0", "INT32"), ("input_int_register_47", "INT32"),
    ("input_double_register_0", "DOUBLE"), ("input_double_register_47", "DOUBLE"),
    ("external_force_torque", "VECTOR6D"),
    # not inputs of the guide's list: answered NOT_FOUND
    ("input_int_register_48", "NOT_FOUND"), ("input_double_register_48", "NOT_FOUND"),
    ("input_bit_register_63", "NOT_FOUND"), ("input_bit_register_128", "NOT_FOUND"),
    ("speed_slider", "NOT_FOUND"), ("actual_q", "NOT_FOUND"), ("", "NOT_FOUND"),
])
def test_the_guide_inputs_have_their_types(name: str, expected: str) -> None:
    assert CONTROLLER_INPUTS.get(name, "NOT_FOUND") == expected


def test_every_guide_input_is_accepted_on_the_wire_and_others_are_not(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        c = RawRtde(emu.port)
        names = list(CONTROLLER_INPUTS)
        assert c.setup_inputs(names) == (1, [CONTROLLER_INPUTS[n] for n in names])
        assert c.setup_inputs(["input_int_register_5", "input_int_register_48",
                               "input_bit_register_0"]) == (0, ["INT32", "NOT_FOUND",
                                                                "NOT_FOUND"])
        c.close()


def test_input_packages_before_start_are_applied_and_read_back_as_outputs(ur5: Robot) -> None:
    names = ["input_bit_register_64", "input_bit_register_127", "input_bit_registers0_to_31",
             "input_bit_registers32_to_63", _int(47), _double(0)]
    values = {"input_bit_register_64": True, "input_bit_register_127": True,
              "input_bit_registers0_to_31": 0x80000001, "input_bit_registers32_to_63": 6,
              _int(47): -123456, _double(0): -2.75}
    with _emulator(ur5) as emu:
        writer = RawRtde(emu.port)
        recipe_id, types = writer.setup_inputs(names)
        recipe = Recipe(recipe_id, tuple(names), tuple(types))
        writer.send(recipe, values)            # no output recipe, no START on this connection
        reader = RawRtde(emu.port)
        out_names = ["timestamp", *names, "input_bit_register_65", _int(46), _double(1)]
        out_id, out_types = reader.setup_outputs(out_names, 125.0)
        out = Recipe(out_id, tuple(out_names), tuple(out_types))
        assert reader.request(MessageType.CONTROL_PACKAGE_START) == b"\x01"
        got = out.decode(reader.wait(MessageType.DATA_PACKAGE))
        deadline = time.monotonic() + 5.0
        while got[_int(47)] != values[_int(47)] and time.monotonic() < deadline:
            got = out.decode(reader.wait(MessageType.DATA_PACKAGE))  # sent before the write
        writer.close()
        reader.close()
    assert {n: got[n] for n in names} == values
    assert (got["input_bit_register_65"], got[_int(46)], got[_double(1)]) == (False, 0, 0.0)


# ur_rtde 1.6.5's RTDEControlInterface, as it sends its setups (recorded on the wire): its
# output recipe, then 23 input recipes that it addresses as recipes 1-23. Each is written as
# (integer registers 0..i-1 or listed, double registers 0..d-1); the last adds the external
# force-torque input.
_CONTROL_OUTPUTS = ["timestamp", "robot_status_bits", "safety_status_bits", "runtime_state",
                    *(f"output_int_register_{i}" for i in range(3)),
                    *(f"output_double_register_{i}" for i in range(6))]
_CONTROL_INPUTS: list[list[str]] = [
    [_int(0), *map(_double, range(8)), _int(1)],
    [_int(0), *map(_double, range(11))],
    [*map(_int, range(8)), *map(_double, range(18))],
    [_int(0)],
    [_int(0), *map(_double, range(9))],
    [_int(0), *map(_double, range(6))],
    [_int(0), *map(_double, range(4))],
    [_int(0), _double(0)],
    [_int(0), _int(1)],
    [_int(0), *map(_double, range(14))],
    [_int(0)],
    [_int(0), *map(_double, range(12))],
    [_int(0), *map(_double, range(8))],
    [_int(0), *map(_double, range(14))],
    [_int(0), _int(1)],
    [_int(0), *map(_double, range(13))],
    [*map(_int, range(7)), *map(_double, range(6))],
    [_int(0), _int(1), *map(_double, range(7))],
    [_int(0), _double(0), _int(1)],
    [_int(0), *map(_double, range(10))],
    [_int(0), *map(_double, range(6)), _int(1)],
    [_int(0), *map(_double, range(18))],
    [_int(0), "external_force_torque"],
]


def test_rtde_control_interface_recipes_get_the_ids_it_assumes(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        c = RawRtde(emu.port)
        out_id, out_types = c.setup_outputs(_CONTROL_OUTPUTS)
        answers = [c.setup_inputs(names) for names in _CONTROL_INPUTS]
        c.close()
    assert out_id == 1 and "NOT_FOUND" not in out_types
    assert [recipe_id for recipe_id, _ in answers] == list(range(1, 24))
    assert all("NOT_FOUND" not in t and "IN_USE" not in t for _, t in answers)
    assert answers[-1][1] == ["INT32", "VECTOR6D"]


def test_a_package_of_an_unknown_recipe_changes_nothing(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        c = RawRtde(emu.port)
        assert c.setup_inputs([_int(5)])[0] == 1
        c.sock.sendall(frame(MessageType.DATA_PACKAGE, struct.pack(">Bi", 2, 99)))
        text = c.wait(MessageType.TEXT_MESSAGE)
        out_id, out_types = c.setup_outputs(["timestamp", _int(5)], 125.0)
        assert c.request(MessageType.CONTROL_PACKAGE_START) == b"\x01"
        got = Recipe(out_id, ("timestamp", _int(5)), tuple(out_types)).decode(
            c.wait(MessageType.DATA_PACKAGE))
        c.close()
    assert b"unknown input recipe id 2" in text
    assert got[_int(5)] == 0
