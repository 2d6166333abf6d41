"""The emulated FANUC controller stamps its J519 status packets in milliseconds at a 2 ms
resolution: every stamp even, successive statuses a cycle apart (on real loopback UDP, the
packets decoded with the driver's codec)."""

from __future__ import annotations

import itertools
import socket

import pytest
from hypothesis import given
from hypothesis import strategies as st

from leadthrough.drivers.fanuc_j519.packets import (
    StartPacket,
    StatusPacket,
    StopPacket,
    decode_robot_packet,
)
from leadthrough.robot.description import load_robot
from leadthrough.sim.emulators import EmulatorOptions, start
from leadthrough.sim.emulators.fanuc_j519 import TIMESTAMP_RESOLUTION_MS, status_timestamp

POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)


@given(st.integers(min_value=0, max_value=2**40))
def test_a_stamp_is_the_last_2_ms_tick(ms: int) -> None:
    for t in (ms / 1000.0, (ms + 0.4) / 1000.0):
        stamp = status_timestamp(t)
        assert stamp % 2 == 0
        assert stamp == (ms - ms % 2) & 0xFFFFFFFF    # the tick at or before t, modulo 2**32


@pytest.mark.parametrize("cycle_ms", [8, 4])
def test_status_stamps_advance_in_2_ms_steps_by_the_cycle(cycle_ms: int) -> None:
    assert TIMESTAMP_RESOLUTION_MS == 2
    options = EmulatorOptions(q0=POSE, cycle_ms=cycle_ms)
    with start("fanuc-j519", load_robot("ur5"), seed=2, port=0, options=options) as emu, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(2.0)
        sock.sendto(StartPacket().encode(), ("127.0.0.1", emu.port))
        statuses: list[StatusPacket] = []
        while len(statuses) < 40:
            packet = decode_robot_packet(sock.recv(2048))
            if isinstance(packet, StatusPacket):
                statuses.append(packet)
        sock.sendto(StopPacket().encode(), ("127.0.0.1", emu.port))
    stamps = [s.timestamp for s in statuses]
    assert all(stamp % 2 == 0 for stamp in stamps)
    # a cycle per sequence number (a status lost on the way skips both alike)
    assert all(b.timestamp - a.timestamp == cycle_ms * (b.sequence - a.sequence)
               for a, b in itertools.pairwise(statuses))
    assert len(set(stamps)) == len(stamps)
