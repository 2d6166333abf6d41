"""The independent ``ur_rtde`` client (SDU Robotics, PyPI ``ur-rtde``) reads our emulated
controller's ``actual_q`` and ``actual_current``.

What ur_rtde needs to connect (found by running it against the emulator):

* port 30004: ``RTDEReceiveInterface`` has no port argument, so the emulator listens on
  30004 of a free 127.x.y.z address (no clash with other sessions on the machine);
* a separate process (``leadthrough emulate``): its constructor holds the GIL while it waits
  for the handshake answers, so an emulator thread of the same interpreter could not answer;
* protocol version 2, GET_URCONTROL_VERSION (major 5: it asks for 500 Hz), an output
  recipe whose names end with a trailing comma (the emulator accepts it), START;
* an explicit variable list: without one it asks for ~60 outputs (TCP pose, forces,
  voltages, payload, ...) that the emulator does not produce; ur_rtde then fails naming
  them, as it would on an old controller.

The package is a test dependency (``test`` extra): if it is missing this test fails.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
import rtde_receive

from leadthrough.drivers.ur_rtde.client import RtdeClient
from wire_helpers import emulated_ur5


@pytest.fixture
def emulator_host() -> Iterator[str]:
    with emulated_ur5() as host:
        yield host


def test_ur_rtde_reads_actual_q_and_current(emulator_host: str) -> None:
    ours = RtdeClient(emulator_host)
    ours.open()
    mine = ours.receive(1.0)
    ours.close()
    assert mine is not None
    recv = rtde_receive.RTDEReceiveInterface(
        emulator_host, -1.0, ["timestamp", "actual_q", "actual_current"])
    try:
        time.sleep(0.1)
        assert recv.isConnected()
        q, current, t1 = recv.getActualQ(), recv.getActualCurrent(), recv.getTimestamp()
        time.sleep(0.1)
        t2 = recv.getTimestamp()
    finally:
        recv.disconnect()
    assert len(q) == 6 and len(current) == 6
    # the robot holds its pose: both clients read the same joints, up to encoder steps
    assert np.abs(np.array(q) - mine.q).max() < 1e-4
    assert np.abs(np.array(current)).max() > 0.1  # gravity load on the shoulder
    assert np.abs(np.array(current) - mine.current).max() < 0.5
    assert 0.05 < t2 - t1 < 0.5 and t1 > mine.timestamp
