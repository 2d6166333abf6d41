"""FANUC Stream Motion (J519): golden packets from the v1 layout tables, the codec's errors,
and our client against the emulated controller over loopback (trajectory, I/O, faults)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.drivers.fanuc_j519.client import StreamMotionClient
from leadthrough.drivers.fanuc_j519.limits import LimitKind
from leadthrough.drivers.fanuc_j519.packets import (
    CommandPacket,
    LimitAnswer,
    LimitQuery,
    StartPacket,
    StatusPacket,
    StopPacket,
    decode_client_packet,
    decode_robot_packet,
)
from leadthrough.drivers.link import LinkErrorKind
from leadthrough.errors import DataError
from leadthrough.robot import Robot
from leadthrough.sim.emulators import (
    EmulatorOptions,
    FaultPlan,
    InputSchedule,
    RunningEmulator,
    Window,
    start,
)
from wire_helpers import DIRECTION, POSE, exchange, hexbytes, min_jerk

# ------------------------------------------------------------------ golden packets (by hand)
# status: type 0, version 1, seq 300, status 0x0d (ready, SYSRDY, in motion), read I/O type 1
# index 1 mask 0x0003 value 0x0001, time stamp 1000, position 100 -45 10 0.5 0.25 1.5 0 0 0,
# joints 90 -45 10 1.5 0.5 -1 0 0 0, currents 1 2 3 0.25 0.5 -1 0 0 0 (float32 big-endian)
STATUS = hexbytes("""
00000000 00000001 0000012c 0d 01 0001 0003 0001 000003e8
42c80000 c2340000 41200000 3f000000 3e800000 3fc00000 00000000 00000000 00000000
42b40000 c2340000 41200000 3fc00000 3f000000 bf800000 00000000 00000000 00000000
3f800000 40000000 40400000 3e800000 3f000000 bf800000 00000000 00000000 00000000
""")
# command: type 1, version 1, seq 300, last_data 1, read I/O type 1 index 1 mask 3,
# data_style 1 (joint), write I/O type 2 index 5 mask 1 value 1, unused 0,
# positions 90 -45 10 1.5 0.5 -1 0 0 0
COMMAND = hexbytes("""
00000001 00000001 0000012c 01 01 0001 0003 01 02 0005 0001 0001 0000
42b40000 c2340000 41200000 3fc00000 3f000000 bf800000 00000000 00000000 00000000
""")
QUERY = hexbytes("00000003 00000001 00000002 00000001")  # axis 2, acceleration
# answer: axis 2, velocity, max TCP speed 2000, interval 100, 20 x 170.0, 20 x 90.0
ANSWER = hexbytes("00000003 00000001 00000002 00000000 000007d0 00000064"
                  + " 432a0000" * 20 + " 42b40000" * 20)


def test_start_and_stop_packets_match_the_table() -> None:
    assert StartPacket().encode() == hexbytes("00000000 00000001")
    assert StopPacket().encode() == hexbytes("00000002 00000001")
    assert decode_client_packet(hexbytes("00000000 00000001")) == StartPacket()
    assert decode_client_packet(hexbytes("00000002 00000001")) == StopPacket()


def test_status_packet_golden_both_directions() -> None:
    assert len(STATUS) == 132
    p = StatusPacket.decode(STATUS)
    assert (p.sequence, p.status, p.timestamp) == (300, 0x0D, 1000)
    assert (p.read_io_type, p.read_io_index, p.read_io_mask, p.read_io_value) == (1, 1, 3, 1)
    assert p.joints[:6] == (90.0, -45.0, 10.0, 1.5, 0.5, -1.0) and p.joints[6:] == (0.0,) * 3
    assert p.current[:6] == (1.0, 2.0, 3.0, 0.25, 0.5, -1.0)
    assert p.position[:6] == (100.0, -45.0, 10.0, 0.5, 0.25, 1.5)
    assert p.ready and p.in_motion
    assert p.encode() == STATUS
    assert decode_robot_packet(STATUS) == p


def test_command_packet_golden_both_directions() -> None:
    cmd = CommandPacket(sequence=300, positions=(90.0, -45.0, 10.0, 1.5, 0.5, -1.0),
                        last_data=True, read_io_type=1, read_io_index=1, read_io_mask=3,
                        write_io_type=2, write_io_index=5, write_io_mask=1, write_io_value=1)
    assert cmd.encode() == COMMAND
    back = CommandPacket.decode(COMMAND)
    assert back.positions == (90.0, -45.0, 10.0, 1.5, 0.5, -1.0, 0.0, 0.0, 0.0)
    assert (back.sequence, back.last_data, back.data_style, back.write_io_value) == (
        300, True, 1, 1)
    assert decode_client_packet(COMMAND) == back


def test_limit_query_and_answer_golden() -> None:
    assert LimitQuery(2, LimitKind.ACCELERATION).encode() == QUERY
    assert decode_client_packet(QUERY) == LimitQuery(2, LimitKind.ACCELERATION)
    ans = LimitAnswer.decode(ANSWER)
    assert (ans.axis, ans.kind, ans.max_cartesian_speed, ans.interval) == (
        2, LimitKind.VELOCITY, 2000, 100)
    assert ans.no_payload == (170.0,) * 20 and ans.full_payload == (90.0,) * 20
    assert ans.encode() == ANSWER and decode_robot_packet(ANSWER) == ans


@pytest.mark.parametrize(("data", "field", "value"), [
    (STATUS[:-1], "length", 131),
    (hexbytes("00000000 00000002") + STATUS[8:], "version_no", 2),
    (hexbytes("00000001") + STATUS[4:], "packet_type", 1),
])
def test_malformed_status_names_field_value_and_range(data: bytes, field: str,
                                                      value: int) -> None:
    with pytest.raises(DataError) as err:
        StatusPacket.decode(data)
    assert (err.value.field, err.value.value) == (field, value)
    assert err.value.expected and "J519 status packet" in str(err.value)


def test_command_encoding_refuses_bad_fields() -> None:
    with pytest.raises(DataError) as err:
        CommandPacket(sequence=1, positions=(0.0, math.nan, 0.0, 0.0, 0.0, 0.0)).encode()
    assert err.value.field == "command_pos[1]"
    with pytest.raises(DataError) as err:
        CommandPacket(sequence=2**32, positions=(0.0,) * 6).encode()
    assert err.value.field == "sequence_no" and "uint32" in str(err.value.expected)
    with pytest.raises(DataError) as err:
        CommandPacket(sequence=1, positions=(0.0,) * 10).encode()
    assert err.value.field == "command_pos" and err.value.value == 10
    with pytest.raises(DataError) as err:
        decode_client_packet(b"\x00" * 20)
    assert err.value.field == "length" and err.value.value == 20


f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(seq=st.integers(0, 2**32 - 1), q=st.lists(f32, min_size=9, max_size=9),
       last=st.booleans(), mask=st.integers(0, 0xFFFF))
def test_command_round_trip(seq: int, q: list[float], last: bool, mask: int) -> None:
    cmd = CommandPacket(sequence=seq, positions=tuple(q), last_data=last, read_io_mask=mask)
    assert CommandPacket.decode(cmd.encode()) == cmd


# ------------------------------------------------------------------- client vs emulator
CYCLE = 0.008
def _emulator(er20: Robot, **kw: object) -> RunningEmulator:
    return start("fanuc-j519", er20, seed=3, port=0,
                 options=EmulatorOptions(q0=POSE, **kw))  # type: ignore[arg-type]


def _stream(client: StreamMotionClient, target: object, duration: float,
            send: bool = True) -> list[StatusPacket]:
    """Answer every status for ``duration`` s with ``target(t, first_status)`` [deg].

    ``t`` is the controller time of the status (sequence × 8 ms), as a J519 client keeps
    its trajectory on the controller's clock (wall-clock jitter would read as jerk).
    """

    def respond(status: StatusPacket, got: list[StatusPacket]) -> None:
        t = (status.sequence - got[0].sequence) * CYCLE
        goal = target(t, got[0])  # type: ignore[operator]
        client.send(client.make_command(list(goal)))

    return exchange(client.receive, duration, respond if send else None)


def test_stream_follows_a_trajectory_and_reports_inputs(er20: Robot) -> None:
    inputs = InputSchedule(enable=(Window(0.0),), mark=(Window(0.3, 0.5),))
    with _emulator(er20, inputs=inputs, watchdog=0.2) as emu:
        client = StreamMotionClient("127.0.0.1", emu.port)
        client.open()
        limits = client.query_limits([1, 6])
        assert limits[(1, LimitKind.VELOCITY)].no_payload[0] == pytest.approx(
            math.degrees(er20.velocity_limit[0]), rel=1e-6)
        assert limits[(6, LimitKind.JERK)].full_payload[19] == pytest.approx(
            math.degrees(er20.acceleration_limit[5] * 50.0), rel=1e-6)
        delta = np.degrees(0.05 * DIRECTION)

        def goal(t: float, first: StatusPacket) -> np.ndarray:
            return min_jerk(np.array(first.joints[:6]), delta, t, 0.5)

        statuses = _stream(client, goal, 0.9)
        client.close()
        report = emu.stop()
    assert len(statuses) > 90 and client.error is None and client.stats.malformed == 0
    assert all(s.ready for s in statuses[1:])
    end = np.array(statuses[-1].joints[:6])
    start_q = np.array(statuses[0].joints[:6])
    assert np.abs(end - (start_q + delta)).max() < 0.02  # deg, settled after 0.4 s
    assert np.abs(start_q - np.degrees(POSE)).max() < 0.01
    assert np.abs(statuses[0].current[:6]).max() > 0.1  # holding gravity
    marks = [(s.timestamp / 1000.0, s.read_io_value) for s in statuses[1:]]  # after a request
    assert all(v & 1 for _, v in marks)  # enabling device held throughout
    pressed = [t for t, v in marks if v & 2]
    assert pressed and min(pressed) >= 0.28 and max(pressed) <= 0.52
    # no stop but the client's own: close() sends the stop packet, which the emulator reads or
    # not before the test stops it (a race of the two processes' schedules)
    assert report.violations == () and report.refused == 0
    assert report.stop_kind in (None, "request")
    assert report.accepted == report.commands >= 90


def test_lost_status_packets_show_as_sequence_gaps(er20: Robot) -> None:
    faults = FaultPlan(loss_bursts=(Window(0.3, 0.34),))  # 5 cycles of 8 ms
    with _emulator(er20, faults=faults, watchdog=0.5) as emu:
        client = StreamMotionClient("127.0.0.1", emu.port)
        client.open()
        _stream(client, lambda t, first: first.joints[:6], 0.6)
        client.close()
        report = emu.stop()
    assert report.dropped == 5
    assert client.stats.gaps == 1 and client.stats.missed == 5 and client.error is None


def test_a_jump_beyond_the_limits_is_refused_and_stops_the_arm(er20: Robot) -> None:
    with _emulator(er20, watchdog=0.5) as emu:
        client = StreamMotionClient("127.0.0.1", emu.port)
        client.open()

        def goal(t: float, first: StatusPacket) -> np.ndarray:
            q = np.array(first.joints[:6])
            return q + (2.0 if t > 0.1 else 0.0)  # 2 deg in one 8 ms cycle: 250 deg/s

        statuses = _stream(client, goal, 0.4)
        client.close()
        report = emu.stop()
    assert report.stop_kind == "limit" and "velocity" in report.stop_reason
    assert report.refused >= 1 and report.violations == ()
    assert statuses[0].ready and not statuses[-1].ready and statuses[-1].status & 4 == 0
    assert np.abs(np.array(statuses[-1].joints[:6]) - statuses[0].joints[:6]).max() < 0.05


def test_watchdog_makes_a_controlled_stop_when_commands_stop(er20: Robot) -> None:
    with _emulator(er20) as emu:  # default watchdog: 4 cycles
        client = StreamMotionClient("127.0.0.1", emu.port)
        client.open()
        speed = np.degrees(0.2 * DIRECTION)  # deg/s

        def goal(t: float, first: StatusPacket) -> np.ndarray:
            # reach 0.2 rad/s in 0.2 s at 1 rad/s^2, within every limit
            travel = t * t / 0.4 if t < 0.2 else t - 0.1
            return np.array(first.joints[:6]) + speed * travel

        moving = _stream(client, goal, 0.3)
        after = _stream(client, goal, 0.3, send=False)
        client.close()
        report = emu.stop()
    assert moving[-1].in_motion and moving[-1].ready
    assert report.stop_kind == "watchdog" and report.violations == ()
    assert not after[-1].ready and not after[-1].in_motion
    # stopped: the joints' speed over the last 5 cycles (the servo still settling) is below
    # 5 % of the 0.2 rad/s of the motion
    speed = np.abs(np.array(after[-1].joints[:6]) - after[-6].joints[:6]).max() / (5 * CYCLE)
    assert math.radians(speed) < 0.01


def test_estop_closed_port_and_nan_are_seen_for_what_they_are(er20: Robot) -> None:
    faults = FaultPlan(estop_at=0.2, nan_q=(Window(0.1, 0.15),), close_at=0.5)
    with _emulator(er20, faults=faults, watchdog=0.5) as emu:
        client = StreamMotionClient("127.0.0.1", emu.port)
        client.open()
        statuses = _stream(client, lambda t, first: first.joints[:6], 0.8)
        report = emu.stop()
        # UDP learns of a closed port from the ICMP answer to a packet: a driver that keeps
        # answering (here: one more command) then reads the error
        client.send(client.make_command(list(statuses[-1].joints[:6])))
        assert client.receive(0.2) is None
        client.close()
    assert any(all(math.isnan(x) for x in s.joints[:6]) for s in statuses)
    assert report.stop_kind == "estop" and not statuses[-1].ready
    assert client.error is not None and client.error.kind is LinkErrorKind.CLOSED
