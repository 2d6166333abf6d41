"""The emulated controllers' answer timing (issue 25, must show 5): a late command is the
client's when its answer reached the socket after the status's actual send + one cycle; the
emulator's own late sends, skipped cycles and lag are counted apart. The counter is fed
timestamps; the kernel's receive stamps are checked on real loopback sockets, and a stalled
emulator's report on a real one."""

from __future__ import annotations

import ast
import os
import select
import signal
import socket
import sys
import time
from typing import Any

import pytest

from leadthrough.drivers.ur_rtde.protocol import (
    ControllerVersion,
    FrameReader,
    MessageType,
    Recipe,
    encode_setup_inputs,
    frame,
)
from leadthrough.sim.emulators.answer_timing import (
    HORIZON_S,
    AnswerTiming,
    enable_rx_stamps,
    recv_stamped,
)
from leadthrough.sim.emulators.controller import STALL_S
from leadthrough.sim.emulators.process import (
    emulator_report,
    free_loopback_address,
    spawn_emulator,
    stop_emulator,
)
from leadthrough.sim.emulators.rtde_session import RtdeSession

CYCLE = 4e-3
T0 = 1_700_000_000.0  # a wall-clock time [s]

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="SO_TIMESTAMPNS is Linux's")


def _flat(windows: tuple[tuple[float, float], ...]) -> list[float]:
    return [x for window in windows for x in window]


def _timing() -> AnswerTiming:
    return AnswerTiming(CYCLE, tolerance=1e-3)


def test_an_answer_is_late_only_after_the_actual_send_plus_one_cycle() -> None:
    """Deadlines run from the actual send, whatever the schedule said: a status sent 0.5 ms
    behind schedule (within the tolerance) answered 3.9 ms after it is in time; one answered
    4.1 ms after its send is the client's late answer."""
    t = _timing()
    t.sent(1, T0, lag=0.5e-3, label=1.0)
    t.answer(T0 + 3.9e-3, key=1)
    t.sent(2, T0 + CYCLE, lag=0.0, label=1.004)
    t.answer(T0 + CYCLE + 4.1e-3, key=2)
    c = t.counts()
    assert (c.statuses, c.in_time, c.late, c.late_with_lag, c.never) == (2, 1, 1, 0, 0)
    assert (c.sends_late, c.cycles_skipped) == (0, 0)
    assert c.worst_answer_ms == pytest.approx(4.1)
    assert c.events == ("t=1.004 #2 +4.1 ms",)
    assert _flat(c.client_windows) == pytest.approx([T0 + CYCLE, T0 + CYCLE + 4.1e-3], abs=1e-6)


def test_late_answers_that_coincide_with_the_emulators_lag_are_told_apart() -> None:
    """A late answer to a status the emulator sent 2 ms behind schedule, and one whose
    send-to-answer window overlaps a stretch where the emulator's loop was behind, coincide
    with the emulator's lag; a late answer outside both does not."""
    t = _timing()
    t.sent(1, T0, lag=2e-3)                                  # sent late by the emulator
    t.answer(T0 + 5e-3, key=1)
    t.sent(2, T0 + 0.010, lag=0.0)
    t.lagged(T0 + 0.011, T0 + 0.013)                          # the loop was 2 ms behind
    t.answer(T0 + 0.015, key=2)
    t.sent(3, T0 + 0.020, lag=0.0)
    t.answer(T0 + 0.026, key=3)                               # the client's own
    c = t.counts()
    assert (c.late, c.late_with_lag, c.sends_late) == (3, 2, 1)
    assert [e.endswith(" lag") for e in c.events] == [True, True, False]
    # only the client's own keeps its window (send to arrival), for a machine's stalls
    assert _flat(c.client_windows) == pytest.approx([T0 + 0.020, T0 + 0.026], abs=1e-6)


def test_a_send_call_that_held_the_emulator_up_is_the_emulators() -> None:
    """A status whose send call took 1.5 ms (the emulator held up inside it, though on time
    by its schedule), answered 4.5 ms after the call began but 3 ms after it returned: late,
    with the emulator's lag. Answered 4.5 ms after a call that took 0.1 ms: the client's."""
    t = _timing()
    t.sent(1, T0, lag=0.0, done=T0 + 1.5e-3)
    t.answer(T0 + 4.5e-3, key=1)
    t.sent(2, T0 + 0.010, lag=0.0, done=T0 + 0.0101)
    t.answer(T0 + 0.0145, key=2)
    c = t.counts()
    assert (c.late, c.late_with_lag) == (2, 1)
    assert c.events == ("t=0.000 #1 +4.5 ms lag", "t=0.000 #2 +4.5 ms")


def test_never_answered_statuses_expire_and_a_resync_skips_cycles() -> None:
    """A status with no answer within the horizon is never answered; one whose deadline fell in
    a resynchronisation (a 10 ms lag dropped: 2 cycle slots of 4 ms skipped) coincides with the
    emulator's lag. An answer after the horizon is stale, not in time."""
    t = _timing()
    t.sent(1, T0, lag=0.0)
    t.resynced(T0 + 0.030, 0.010)
    t.sent(2, T0 + 0.031, lag=0.0)
    t.sent(3, T0 + 0.050, lag=0.0)
    t.answer(T0 + 0.052, key=3)
    assert t.counts().never == 0                              # not yet past the horizon
    t.sent(4, T0 + 0.031 + HORIZON_S, lag=0.0)                # both 1 and 2 expire now
    t.answer(T0 + 0.040 + HORIZON_S, key=2)                   # too late: stale
    c = t.counts()
    assert (c.in_time, c.never, c.never_with_lag, c.cycles_skipped, c.stale) == (1, 2, 1, 2, 1)
    # status 1, never answered and not in the resync: its window ends at its deadline
    assert _flat(c.client_windows) == pytest.approx([T0, T0 + CYCLE], abs=1e-6)


def test_the_run_that_ends_the_stream_is_the_stops_not_missing_answers() -> None:
    """When the stream ends, the statuses after the last answered one are the stop's (the
    client stopped answering on purpose); an unanswered one before it was never answered."""
    t = _timing()
    for k in range(6):
        t.sent(k, T0 + k * CYCLE, lag=0.0)
    for k in (0, 2):
        t.answer(T0 + k * CYCLE + 1e-3, key=k)
    t.ended()
    c = t.counts()
    assert (c.in_time, c.never, c.late) == (2, 1, 0)
    assert c.events == ("t=0.000 #1 never",)


def test_an_rtde_answer_answers_the_latest_package_sent_before_it() -> None:
    """RTDE answers carry no key: a counter change answers the newest package the client could
    have read. An answer 1 ms after package 2 (5 ms after package 1) is package 2's, in time;
    package 1 was never answered. An answer before any pending package is stale."""
    t = _timing()
    t.answer(T0 - 1e-3)
    t.sent(1, T0, lag=0.0)
    t.sent(2, T0 + CYCLE, lag=0.0)
    t.answer(T0 + CYCLE + 1e-3)
    t.ended()
    c = t.counts()
    assert (c.stale, c.in_time, c.late, c.never) == (1, 1, 0, 1)


def test_an_answer_time_that_is_only_an_upper_bound_is_not_blamed_on_the_client() -> None:
    """A late answer whose receive time is only a bound (it waited in a TCP buffer the
    emulator read late) counts as late with the emulator's lag."""
    t = _timing()
    t.sent(1, T0, lag=0.0)
    t.answer(T0 + 6e-3, key=1, exact=False)
    t.sent(2, T0 + 0.010, lag=0.0)
    t.answer(T0 + 0.012, key=2, exact=False)                 # a bound within the deadline
    c = t.counts()
    assert (c.in_time, c.late, c.late_with_lag) == (1, 1, 1)


def _wait_for_arrival_stamps(rx_sock: socket.socket, tx_sock: socket.socket) -> None:
    """Until the kernel stamps datagrams as they arrive. Enabling ``SO_TIMESTAMPNS`` switches
    the system's receive stamping on through deferred work (``net_enable_timestamp``,
    net/core/dev.c); a datagram that arrives before it has run is stamped when it is read
    (``__sock_recv_timestamp``, net/socket.c: "Race occurred between timestamp enabling and
    packet receiving"), which on a loaded machine took 30 ms here. A probe read 5 ms after it
    became readable tells which: stamped on arrival, or on the read."""
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        tx_sock.sendto(b"probe", rx_sock.getsockname())
        select.select([rx_sock], [], [], 1.0)
        readable = time.time()
        time.sleep(0.005)
        _, _, rx, _ = recv_stamped(rx_sock)
        if rx <= readable + 1e-4:
            return
    raise AssertionError("the kernel did not stamp datagrams on arrival within 2 s")


@linux_only
def test_the_udp_receive_time_is_the_kernels_not_when_the_emulator_read_it() -> None:
    """A datagram read 30 ms after it arrived carries its arrival time. Arrival is when the
    kernel queues it on the socket: on loopback usually within the send call, but a loaded
    machine may defer the receive path (softirq) by milliseconds (CI saw 30 ms); the socket
    turning readable bounds it."""
    rx_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with rx_sock, tx_sock:
        rx_sock.bind(("127.0.0.1", 0))
        assert enable_rx_stamps(rx_sock)
        _wait_for_arrival_stamps(rx_sock, tx_sock)
        before = time.time()
        tx_sock.sendto(b"answer", rx_sock.getsockname())
        readable, _, _ = select.select([rx_sock], [], [], 1.0)
        arrived = time.time()           # queued on the socket by now: stamped by now
        time.sleep(0.03)
        data, _, rx, exact = recv_stamped(rx_sock)
        read = time.time()
    assert readable and (data, exact) == (b"answer", True)
    assert before - 1e-4 <= rx <= arrived + 1e-4
    assert read - rx >= 0.025


@linux_only
def test_rtde_frames_merged_in_one_tcp_read_are_stamped_as_bounds_but_the_last() -> None:
    """Two input packages that wait unread in the TCP buffer come out of one read: the last
    one has its own arrival time, the first only a bound; a package read alone has its own."""
    listener = socket.create_server(("127.0.0.1", 0))
    client = socket.create_connection(listener.getsockname())
    client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as the driver's
    conn, _ = listener.accept()
    conn.setblocking(False)
    assert enable_rx_stamps(conn)
    writes: list[tuple[Any, float, bool]] = []
    session = RtdeSession(conn, ControllerVersion(5, 11, 6, 0), 500.0, {}, {},
                          lambda values, rx, exact: writes.append(
                              (values["input_int_register_24"], rx, exact)))
    session.started = True
    with listener, client:
        client.sendall(frame(MessageType.CONTROL_PACKAGE_SETUP_INPUTS,
                             encode_setup_inputs(["input_int_register_24"])))
        time.sleep(0.01)
        session.receive()
        reader = FrameReader()
        reader.feed(client.recv(4096))
        reply = reader.next()
        assert reply is not None and reply[1][0] == 1  # the connection's first input recipe
        recipe = Recipe(1, ("input_int_register_24",), ("INT32",))

        def package(counter: int) -> bytes:
            return frame(MessageType.DATA_PACKAGE, recipe.encode(
                {"input_int_register_24": counter}))

        client.sendall(package(1))
        time.sleep(0.01)
        before = time.time()
        client.sendall(package(2))
        after = time.time()
        time.sleep(0.03)
        session.receive()
        client.sendall(package(3))
        time.sleep(0.03)
        session.receive()
        read = time.time()
    session.close()
    assert [(c, exact) for c, _, exact in writes] == [(1, False), (2, True), (3, True)]
    assert before - 1e-4 <= writes[1][1] <= after + 1e-4         # the second's own arrival
    assert read - writes[2][1] >= 0.025                         # not when it was read


@linux_only
def test_a_stalled_emulator_lists_the_stall_at_its_simulated_time() -> None:
    """``leadthrough emulate`` stopped (SIGSTOP) for 0.15 s: its report lists that stall, at
    least 0.14 s long, at a simulated time between its start and the stop; its clock stopped
    meanwhile, so the session's simulated time falls short of the wall time until it stopped
    (by 0.1 s at least: the clock starts a moment before the ready line is read).
    Only lags of ``STALL_S`` or more are listed (a loaded machine may add some of its own)."""
    emu = spawn_emulator("fanuc-j519", "er20", free_loopback_address(60015), 0)
    started = time.monotonic()
    try:
        time.sleep(0.5)
        stopped_at = time.monotonic() - started
        os.kill(emu.pid, signal.SIGSTOP)
        time.sleep(0.15)
        os.kill(emu.pid, signal.SIGCONT)
        time.sleep(0.3)
    finally:
        report = emulator_report(stop_emulator(emu))
    wall = time.monotonic() - started
    stalls = ast.literal_eval(report["stalls"])
    assert all(lag >= STALL_S for _, lag in stalls), stalls
    ours = [(t, lag) for t, lag in stalls if lag >= 0.14]
    assert any(0.0 < t <= stopped_at + 0.05 for t, _ in ours), (stalls, stopped_at)
    assert float(report["sim_time"]) <= wall - 0.1, (report["sim_time"], wall)
