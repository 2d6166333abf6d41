"""The independent ``ur_rtde`` client (SDU Robotics, PyPI ``ur-rtde``): its ``RTDEIOInterface``
writes the registers, speed slider and outputs it names on ``leadthrough emulate ur-rtde``,
read back on the emulator's side through the outputs a real controller echoes them on.

``RTDEIOInterface`` (1.6.5) sets up 16 input recipes and addresses them by the ids a real
controller gives (1-16 in order), sends no START, and writes with data packages; the emulator
runs in a process of its own (``ur_rtde``'s constructors hold the GIL while they wait for
answers). The read-back asks the emulator for the input registers as outputs, as the RTDE guide
lists them (``input_int_register_X``, ``input_double_register_X``), with our RTDE client, and for
the speed slider, digital and analog outputs with ``ur_rtde``'s own ``RTDEReceiveInterface``.

``RTDEIOInterface`` 1.6.5 has no setter of the boolean registers: their recipes and read-back
are tested on the wire in ``test_emulator_rtde_recipes.py``.

The package is a test dependency (``test`` extra): if it is missing this test fails.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import rtde_io
import rtde_receive

from leadthrough.drivers.ur_rtde.client import DEFAULT_OUTPUTS, RtdeClient
from wire_helpers import emulated_ur5

INTS = {18: 1818, 19: -19, 22: 2_000_000_022}
DOUBLES = {18: 18.5, 20: -0.25, 22: 1e6}
REGISTERS = ([f"input_int_register_{i}" for i in range(18, 24)]
             + [f"input_double_register_{i}" for i in range(18, 23)])


@pytest.fixture
def emulator_host() -> Iterator[str]:
    with emulated_ur5() as host:
        yield host


def _controller_outputs(host: str, names: list[str], until: Any) -> dict[str, Any]:
    """The emulator's outputs ``names``, once ``until(values)`` holds (or after 5 s)."""
    client = RtdeClient(host, outputs=(*DEFAULT_OUTPUTS, *names), register_offset=0)
    client.open()
    try:
        deadline = time.monotonic() + 5.0
        values: dict[str, Any] = {}
        while time.monotonic() < deadline:
            state = client.receive(1.0)
            if state is not None:
                values = state.values
                if until(values):
                    break
    finally:
        client.close()
    return values


def test_rtde_io_interface_writes_the_registers_it_names(emulator_host: str) -> None:
    io = rtde_io.RTDEIOInterface(emulator_host)
    try:
        for i, v in INTS.items():
            assert io.setInputIntRegister(i, v)
        for i, d in DOUBLES.items():
            assert io.setInputDoubleRegister(i, d)
        assert io.setSpeedSlider(0.3)
        assert io.setStandardDigitalOut(3, True)
        assert io.setConfigurableDigitalOut(2, True)
        assert io.setToolDigitalOut(1, True)
        assert io.setAnalogOutputVoltage(1, 0.4)
        got = _controller_outputs(
            emulator_host, REGISTERS,
            until=lambda v: v["input_double_register_22"] == DOUBLES[22])  # sent last of those
        recv = rtde_receive.RTDEReceiveInterface(
            emulator_host, -1.0, ["timestamp", "target_speed_fraction",
                                  "actual_digital_output_bits", "standard_analog_output1"])
        try:
            time.sleep(0.1)
            assert recv.isConnected()
            slider, bits = recv.getTargetSpeedFraction(), recv.getActualDigitalOutputBits()
            analog1, do3 = recv.getStandardAnalogOutput1(), recv.getDigitalOutState(3)
        finally:
            recv.disconnect()
    finally:
        io.disconnect()
    # each register the client named, and no other (formerly register 18 landed in 21)
    assert {i: got[f"input_int_register_{i}"] for i in range(18, 23)} == {
        18: 1818, 19: -19, 20: 0, 21: 0, 22: 2_000_000_022}
    assert {i: got[f"input_double_register_{i}"] for i in range(18, 23)} == {
        18: 18.5, 19: 0.0, 20: -0.25, 21: 0.0, 22: 1e6}
    # the slider went to the slider (formerly to a register recipe), the outputs to theirs
    assert slider == 0.3
    assert bits == (1 << 3) | (1 << (8 + 2)) | (1 << (16 + 1)) and do3
    assert analog1 == 0.4
    # ur_rtde's command register, in every recipe: the code of a command it sent
    # (RTDE::RobotCommand::Type: 22 SET_SPEED_SLIDER, 23 SET_STD_ANALOG_OUT, 48
    # SET_CONF_DIGITAL_OUT, 49 SET_INPUT_INT_REGISTER, 50 SET_INPUT_DOUBLE_REGISTER, ...)
    assert got["input_int_register_23"] in (13, 14, 22, 23, 48, 49, 50)
