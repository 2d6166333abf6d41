"""Universal Robots RTDE: golden messages from the RTDE guide's tables, the codec's errors,
the URScript program's parameters, and our client against the emulated controller over
loopback (trajectory, protective stop, watchdog, E-stop, closed socket, lost packages)."""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from leadthrough.drivers.link import LinkErrorKind
from leadthrough.drivers.protocol import ControllerState
from leadthrough.drivers.ur_rtde.client import RtdeClient, RtdeState, ServoCommand
from leadthrough.drivers.ur_rtde.driver import controller_state
from leadthrough.drivers.ur_rtde.protocol import (
    ControllerVersion,
    FrameReader,
    MessageType,
    Recipe,
    TextMessage,
    decode_setup_outputs,
    encode_accepted,
    encode_setup_outputs,
    encode_setup_reply,
    encode_version_request,
    frame,
)
from leadthrough.drivers.ur_rtde.script import ServoScriptParameters, servo_script, upload_script
from leadthrough.errors import DataError, DriverError
from leadthrough.robot import Robot, load_robot
from leadthrough.sim.emulators import (
    EmulatorOptions,
    FaultPlan,
    InputSchedule,
    RunningEmulator,
    Window,
    start,
)
from wire_helpers import DIRECTION, POSE, exchange, hexbytes, min_jerk

# ------------------------------------------------------------------ golden messages (by hand)
# header: uint16 size (header included), uint8 type; big-endian
GOLDEN_VERSION_REQUEST = hexbytes("0005 56 0002")             # 'V', protocol version 2
GOLDEN_ACCEPTED = hexbytes("0004 56 01")
GOLDEN_CONTROLLER_VERSION = hexbytes("0013 76 00000005 0000000b 00000006 00000000")  # 5.11.6.0
# 'O': float64 500.0, "timestamp,actual_q"
GOLDEN_SETUP_OUTPUTS = hexbytes("001d 4f 407f400000000000"
                                "74696d657374616d702c61637475616c5f71")
GOLDEN_SETUP_REPLY = hexbytes("0013 4f 01 444f55424c452c564543544f523644")  # 1, DOUBLE,VECTOR6D
# 'U', recipe 1: timestamp 1.5, actual_q (0.5 -0.5 1 -1 2 0.25), robot_mode 7 (INT32),
# runtime_state 2 (UINT32), actual_digital_input_bits 3 (UINT64), safety_status_bits 4
GOLDEN_DATA = hexbytes("""
0050 55 01 3ff8000000000000
3fe0000000000000 bfe0000000000000 3ff0000000000000 bff0000000000000 4000000000000000
3fd0000000000000
00000007 00000002 0000000000000003 00000004
""")
OUT_RECIPE = Recipe(1, ("timestamp", "actual_q", "robot_mode", "runtime_state",
                        "actual_digital_input_bits", "safety_status_bits"),
                    ("DOUBLE", "VECTOR6D", "INT32", "UINT32", "UINT64", "UINT32"))
# 'U', recipe 2: input_double_register_0 = 1.0, input_int_register_0 = -2
GOLDEN_INPUT = hexbytes("0010 55 02 3ff0000000000000 fffffffe")
GOLDEN_TEXT = hexbytes("000a 4d 02 6869 02 7572 02")  # "hi" from "ur", warning


def test_handshake_messages_match_the_guide() -> None:
    assert frame(MessageType.REQUEST_PROTOCOL_VERSION, encode_version_request(2)) == (
        GOLDEN_VERSION_REQUEST)
    assert frame(MessageType.REQUEST_PROTOCOL_VERSION, encode_accepted(True)) == GOLDEN_ACCEPTED
    assert frame(MessageType.GET_URCONTROL_VERSION) == hexbytes("0003 76")
    assert frame(MessageType.GET_URCONTROL_VERSION,
                 ControllerVersion(5, 11, 6, 0).encode()) == GOLDEN_CONTROLLER_VERSION
    assert ControllerVersion.decode(GOLDEN_CONTROLLER_VERSION[3:]) == ControllerVersion(
        5, 11, 6, 0)
    setup = encode_setup_outputs(500.0, ["timestamp", "actual_q"])
    assert frame(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, setup) == GOLDEN_SETUP_OUTPUTS
    assert decode_setup_outputs(GOLDEN_SETUP_OUTPUTS[3:]) == (500.0, ["timestamp", "actual_q"])
    reply = encode_setup_reply(1, ["DOUBLE", "VECTOR6D"])
    assert frame(MessageType.CONTROL_PACKAGE_SETUP_OUTPUTS, reply) == GOLDEN_SETUP_REPLY
    assert frame(MessageType.CONTROL_PACKAGE_START) == hexbytes("0003 53")
    assert frame(MessageType.CONTROL_PACKAGE_PAUSE, encode_accepted(True)) == hexbytes(
        "0004 50 01")


def test_data_packages_golden_both_directions() -> None:
    values = {"timestamp": 1.5, "actual_q": (0.5, -0.5, 1.0, -1.0, 2.0, 0.25),
              "robot_mode": 7, "runtime_state": 2, "actual_digital_input_bits": 3,
              "safety_status_bits": 4}
    assert frame(MessageType.DATA_PACKAGE, OUT_RECIPE.encode(values)) == GOLDEN_DATA
    assert OUT_RECIPE.decode(GOLDEN_DATA[3:]) == values
    inputs = Recipe(2, ("input_double_register_0", "input_int_register_0"), ("DOUBLE", "INT32"))
    assert frame(MessageType.DATA_PACKAGE, inputs.encode(
        {"input_double_register_0": 1.0, "input_int_register_0": -2})) == GOLDEN_INPUT
    assert inputs.decode(GOLDEN_INPUT[3:]) == {"input_double_register_0": 1.0,
                                                "input_int_register_0": -2}
    assert TextMessage.decode(GOLDEN_TEXT[3:]) == TextMessage("hi", "ur", 2)
    assert frame(MessageType.TEXT_MESSAGE, TextMessage("hi", "ur", 2).encode()) == GOLDEN_TEXT


def test_frame_reader_splits_a_stream_anywhere() -> None:
    stream = GOLDEN_ACCEPTED + GOLDEN_DATA + GOLDEN_TEXT
    for cut in range(len(stream)):
        reader, got = FrameReader(), []
        for part in (stream[:cut], stream[cut:]):
            reader.feed(part)
            while (msg := reader.next()) is not None:
                got.append(msg)
        assert [m[0] for m in got] == [86, 85, 77]
        assert got[1][1] == GOLDEN_DATA[3:]


def test_malformed_messages_name_field_value_and_range() -> None:
    with pytest.raises(DataError) as err:
        OUT_RECIPE.decode(GOLDEN_DATA[3:-1])
    assert (err.value.field, err.value.value) == ("length", 76)
    with pytest.raises(DataError) as err:
        OUT_RECIPE.decode(b"\x02" + GOLDEN_DATA[4:])
    assert (err.value.field, err.value.value) == ("recipe_id", 2)
    with pytest.raises(DataError) as err:
        Recipe(1, ("actual_q",), ("NOT_FOUND",))
    assert err.value.field == "actual_q" and err.value.value == "NOT_FOUND"
    reader = FrameReader()
    reader.feed(hexbytes("0002 55"))
    with pytest.raises(DataError) as err:
        reader.next()
    assert err.value.field == "size" and err.value.value == 2


def test_servo_script_fills_and_checks_its_parameters() -> None:
    text = servo_script(ServoScriptParameters(period=0.008, lookahead_time=0.05, gain=500.0,
                                              watchdog_timeout=0.1, register_offset=24))
    assert "{{" not in text.split("def leadthrough_servo")[1]
    assert "PERIOD = 0.008" in text and "GAIN = 500.0" in text and "REG = 24" in text
    assert "servoj(q, 0, 0, PERIOD, LOOKAHEAD_TIME, GAIN)" in text
    with pytest.raises(DataError) as err:
        ServoScriptParameters(gain=50.0)
    assert err.value.field == "servo_script.gain" and "100..2000" in str(err.value.expected)
    with pytest.raises(DataError):
        ServoScriptParameters(watchdog_timeout=0.001)


# ------------------------------------------------------------------- client vs emulator
@pytest.fixture(scope="module")
def ur5() -> Robot:
    return load_robot("ur5")


def _emulator(robot: Robot, **kw: object) -> RunningEmulator:
    return start("ur-rtde", robot, seed=5, port=0,
                 options=EmulatorOptions(q0=POSE, **kw))  # type: ignore[arg-type]


def _open(client: RtdeClient, emu: RunningEmulator) -> None:
    """Connect, then load the servo program through the secondary interface."""
    client.open()
    upload_script("127.0.0.1", servo_script(), emu.emulator.script_port)  # type: ignore[attr-defined]


def _run(client: RtdeClient, target: object, duration: float, mode: int = 1,
         send: bool = True) -> list[RtdeState]:
    """Answer every data package for ``duration`` s with ``target(t, first)`` [rad]."""

    def respond(state: RtdeState, got: list[RtdeState]) -> None:
        q = target(state.timestamp - got[0].timestamp, got[0])  # type: ignore[operator]
        client.send(ServoCommand(tuple(q), counter=len(got), mode=mode))

    return exchange(client.receive, duration, respond if send else None,
                    stop=lambda: client.error is not None)


def test_servo_follows_a_trajectory(ur5: Robot) -> None:
    inputs = InputSchedule(enable=(Window(0.0),))
    with _emulator(ur5, inputs=inputs, watchdog=0.2) as emu:
        client = RtdeClient("127.0.0.1", emu.port)
        _open(client, emu)
        assert client.controller_version == ControllerVersion(5, 11, 6, 0)
        assert client.frequency == 500.0
        delta = 0.05 * DIRECTION
        states = _run(client, lambda t, f: min_jerk(np.array(f.q), delta, t, 0.5), 0.8)
        client.close()
        report = emu.stop()
    first, last = states[0], states[-1]
    assert np.abs(np.array(first.q) - POSE).max() < 1e-4
    assert np.abs(np.array(last.q) - (np.array(first.q) + delta)).max() < 2e-4
    assert last.values["runtime_state"] == 2 and last.values["output_int_register_0"] == 1
    assert last.values["safety_mode"] == 1 and last.values["robot_mode"] == 7
    assert last.values["actual_digital_input_bits"] & 1
    assert client.error is None and client.stats.malformed == 0 and len(states) > 300
    assert report.violations == () and report.refused == 0 and report.stop_kind is None


def test_a_servoj_jump_triggers_a_protective_stop(ur5: Robot) -> None:
    with _emulator(ur5, watchdog=0.2) as emu:
        client = RtdeClient("127.0.0.1", emu.port)
        _open(client, emu)
        states = _run(client, lambda t, f: np.array(f.q) + (0.1 if t > 0.1 else 0.0), 0.4)
        client.close()
        report = emu.stop()
    assert not states[0].protective_stop and states[-1].protective_stop
    assert states[-1].values["safety_mode"] == 3 and states[-1].values["runtime_state"] == 1
    assert states[-1].values["output_int_register_0"] == 1  # halted by the controller
    assert report.stop_kind == "protective" and "velocity" in report.stop_reason
    assert report.violations == ()
    assert np.abs(np.array(states[-1].q) - states[0].q).max() < 0.01  # never jumped


def test_watchdog_stops_the_program_when_commands_stop(ur5: Robot) -> None:
    with _emulator(ur5) as emu:  # the script's watchdog: 0.05 s
        client = RtdeClient("127.0.0.1", emu.port)
        _open(client, emu)
        _run(client, lambda t, f: f.q, 0.2)
        after = _run(client, lambda t, f: f.q, 0.2, send=False)
        client.close()
        report = emu.stop()
    assert after[-1].values["output_int_register_0"] == 3  # stopped by the watchdog
    assert after[-1].values["runtime_state"] == 1 and after[-1].values["safety_mode"] == 1
    assert report.stop_kind == "watchdog"


def test_estop_loss_and_closed_socket_are_seen_for_what_they_are(ur5: Robot) -> None:
    faults = FaultPlan(estop_at=0.3, loss_bursts=(Window(0.1, 0.12),), close_at=0.6)
    with _emulator(ur5, faults=faults, watchdog=0.5) as emu:
        client = RtdeClient("127.0.0.1", emu.port)
        _open(client, emu)
        states = _run(client, lambda t, f: f.q, 1.0)
        report = emu.stop()
    assert client.stats.gaps == 1 and client.stats.missed == 10 == report.dropped
    assert states[-1].values["safety_mode"] == 7 and states[-1].values["robot_mode"] == 3
    assert states[-1].values["safety_status_bits"] & (1 << 7)
    assert client.error is not None and client.error.kind is LinkErrorKind.CLOSED
    assert client.receive(0.01) is None


def test_a_reset_by_the_controller_is_a_closed_link() -> None:
    """A controller that closes while our commands are still unread in its socket answers them
    with a reset (RST), and recv raises ConnectionResetError: that is the controller closing
    the connection (LinkErrorKind.CLOSED, as a send into a closed connection is), not a
    socket fault. Before, which of the two a closed controller gave depended on the race
    (tests/test_wire_drivers.py::test_nan_and_a_closed_socket failed under load)."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        client = RtdeClient("127.0.0.1", server.getsockname()[1])
        sock = socket.create_connection(server.getsockname())
        conn, _ = server.accept()
        sock.sendall(b"\x00" * 64)                     # never read by the controller
        time.sleep(0.05)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        conn.close()                                    # linger 0: a reset, not a FIN
        client._sock = sock      # the connection as open() leaves it, without a handshake
        try:
            assert client._fill(1.0) is False
        finally:
            sock.close()
    assert client.error is not None and client.error.kind is LinkErrorKind.CLOSED
    assert "reset" in str(client.error).lower()


def test_refused_setups_name_the_variable(ur5: Robot) -> None:
    with _emulator(ur5) as emu:
        bad = RtdeClient("127.0.0.1", emu.port, outputs=("timestamp", "actual_q",
                                                         "actual_current", "actual_TCP_pose"))
        with pytest.raises(DriverError) as err:
            bad.open()
        assert err.value.field == "actual_TCP_pose" and err.value.value == "NOT_FOUND"
        first = RtdeClient("127.0.0.1", emu.port)
        first.open()
        second = RtdeClient("127.0.0.1", emu.port)
        with pytest.raises(DriverError) as err:
            second.open()
        assert err.value.field == "input_double_register_0" and err.value.value == "IN_USE"
        first.close()
        emu.stop()
    assert math.isfinite(emu.emulator.t)


# the RTDE guide's codes: safety_mode 1 NORMAL, 3 PROTECTIVE_STOP, 5 SAFEGUARD_STOP, 6 SYSTEM_
# EMERGENCY_STOP, 7 ROBOT_EMERGENCY_STOP, 9 FAULT, 13 THREE_POSITION_ENABLING_STOP; robot_mode
# 7 RUNNING, 3 POWER_OFF; runtime_state 2 PLAYING, 1 STOPPED
@pytest.mark.parametrize(("safety", "robot", "runtime", "program", "expected"), [
    (1, 7, 2, 1, ControllerState.NORMAL),
    (3, 7, 2, 1, ControllerState.PROTECTIVE_STOP),
    (5, 7, 2, 1, ControllerState.PROTECTIVE_STOP),
    (13, 7, 2, 1, ControllerState.PROTECTIVE_STOP),
    (6, 7, 2, 1, ControllerState.ESTOP),
    (7, 3, 1, 1, ControllerState.ESTOP | ControllerState.NOT_READY),
    (9, 7, 2, 1, ControllerState.NOT_READY),
    (1, 3, 2, 1, ControllerState.NOT_READY),
    (1, 7, 1, 1, ControllerState.NOT_READY),
    (1, 7, 2, 3, ControllerState.NOT_READY),  # the program stopped by its watchdog
])
def test_controller_state_from_the_rtde_codes(safety: int, robot: int, runtime: int,
                                              program: int, expected: ControllerState) -> None:
    values = {"safety_mode": safety, "robot_mode": robot, "runtime_state": runtime,
              "output_int_register_24": program}
    assert controller_state(values, "output_int_register_24") == expected


def test_a_command_is_within_a_cycle_of_every_target_the_arm_may_hold() -> None:
    """The echo says servoj holds target 7; 8 (declared late) may still be taken before the
    next command: that one stays within one cycle at the limiter's speed of both."""
    from leadthrough.drivers.ur_rtde.driver import UrRtdeDriver

    robot = load_robot("ur5")
    driver = UrRtdeDriver(robot, "127.0.0.1")
    step = robot.velocity_limit * driver.margin * driver.dt
    held, late = np.asarray(POSE), np.asarray(POSE) + 0.9 * step * DIRECTION
    for counter, target in ((7, held), (8, late)):   # the ring of targets sent
        row = counter % driver._sent.shape[0]
        driver._sent[row], driver._sent_counter[row] = target, counter
    driver._counter, driver._echoed = 8, 7
    wanted = held + 1.5 * step * DIRECTION  # what the limiter allows from `late`
    sent = driver._within_reach(wanted)
    np.testing.assert_allclose(sent, held + step * DIRECTION)
    assert np.all(np.abs(sent - late) <= step + 1e-12)
    # nothing in flight: the limiter's output passes unchanged
    driver._echoed = 8
    np.testing.assert_array_equal(driver._within_reach(late + 0.5 * step), late + 0.5 * step)
    # no echo seen yet (a program that does not echo): unchanged
    driver._echoed = None
    np.testing.assert_array_equal(driver._within_reach(wanted), wanted)
