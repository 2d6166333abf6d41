"""What every emulated controller shares: the 1 ms real-time loop around an
:class:`~leadthrough.sim.emulators.arm.EmulatedArm`, the controller cycle, injected faults
(lost, late and NaN packets, a closed socket, E-stop and protective stop) and the report.

A protocol module subclasses :class:`EmulatedController` and implements :meth:`open` (bind its
sockets), :meth:`poll` (handle what arrived, every millisecond), :meth:`on_cycle` (the
controller's cycle: take the command, send the status) and :meth:`close_sockets`.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from leadthrough.robot.description import Robot
from leadthrough.sim.emulators.answer_timing import (
    AnswerTiming,
    TimingCounts,
    enable_rx_stamps,
    recv_stamped,
)
from leadthrough.sim.emulators.arm import ArmPhase, EmulatedArm, MotionLimits, StopKind
from leadthrough.sim.emulators.operator import EmulatedOperator
from leadthrough.sim.emulators.scenario import EmulatorOptions

__all__ = ["MAX_STALLS", "STALL_S", "EmulatedController", "EmulatorReport", "UdpController"]

#: A lag of the emulator's loop that the report lists with its time [s] (a real controller's
#: packets never stop for this long; the loop's stale limits are a few cycles, 24-48 ms).
STALL_S = 0.02
#: Stalls the report lists at most, the latest (a loaded machine may stall the emulator every
#: second, and most of all while the client starts: the stalls of a session's end are kept).
MAX_STALLS = 1000


@dataclass(frozen=True)
class EmulatorReport:
    """What happened in an emulator session.

    Attributes:
        kind: Emulator name.
        sim_time: Simulated time [s].
        commands: Commands received; accepted / refused split.
        violations: Executed targets that broke a limit or were not finite (always empty
            unless the emulator is wrong).
        stop_kind: Why the arm stopped (None: it did not).
        stop_reason: Detail of the stop.
        sent, dropped, delayed: Outgoing packets sent, dropped and delayed by faults.
        max_lag: Largest lag of the loop behind the wall clock [s].
        resyncs: Times the loop dropped a lag of more than one controller cycle instead of
            catching it up (a real controller never sends a burst of cycles).
        stalls: The loop's lags of :data:`STALL_S` or more, as (simulated time [s], lag [s]),
            the latest :data:`MAX_STALLS` of them: when the emulator itself went silent (its
            clock stops meanwhile, so the time is when it stopped and resumed), so that a
            client's stale-feedback fault can be told apart from the emulator's own stall at
            that time.
        missed_cycles: Controller cycles, while the client streamed, that had no fresh command
            at the cycle's time (J519: no command answering the last status; RTDE: the
            program's counter unchanged; RSI: no answer with the IPOC, RSI's ``Delay``), without
            the run of them that ended the stream (the client's stop request, or the
            watchdog's stop: reported as the stop).
        operator_start: Simulated time the operator's script started [s] (None: no operator,
            or not yet).
        operator_end: Simulated time the script ends [s] (None: as above).
        timing: The answers timed against the actual sends, the client's lateness apart from
            the emulator's own lag (:mod:`~leadthrough.sim.emulators.answer_timing`).
    """

    kind: str
    sim_time: float
    commands: int
    accepted: int
    refused: int
    violations: tuple[str, ...]
    stop_kind: str | None
    stop_reason: str
    sent: int
    dropped: int
    delayed: int
    max_lag: float
    resyncs: int
    stalls: tuple[tuple[float, float], ...] = ()
    missed_cycles: int = 0
    operator_start: float | None = None
    operator_end: float | None = None
    timing: TimingCounts = field(default_factory=TimingCounts)


class EmulatedController(ABC):
    """Base of the emulated controllers (see the module doc).

    Args:
        robot: Robot description (6 joints).
        seed: Seeds the simulated robot and the fault draws.
        options: Shared settings.
        port: Port to listen on (J519, RTDE; 0: any free port) or to send to (RSI).
    """

    kind: ClassVar[str] = ""
    default_cycle_ms: ClassVar[int] = 8
    #: The simulator step [1 ms] within each cycle period at which the cycle runs: 1 (the
    #: first step's end, at 1, 9, 17, ... ms for 8 ms) or 0 (the period's end, on the
    #: controller clock's ticks: 8, 16, 24, ... ms).
    cycle_phase: ClassVar[int] = 1

    def __init__(self, robot: Robot, seed: int, options: EmulatorOptions, port: int) -> None:
        self.robot, self.options, self.requested_port = robot, options, port
        cycle_ms = options.cycle_ms if options.cycle_ms is not None else self.default_cycle_ms
        q0 = np.array(options.q0) if options.q0 is not None else None
        self.operator = (EmulatedOperator(options.operator) if options.operator is not None
                         else None)
        self.arm = EmulatedArm(robot, seed, cycle_ms * 1e-3, self.motion_limits(robot), q0,
                               operator=self.operator)
        self.rng = np.random.default_rng([seed, 7])
        self._outbox: list[tuple[float, socket.socket, bytes, tuple[str, int] | None,
                                 int | None]] = []
        self.sent = self.dropped = self.delayed = 0
        self.max_lag, self.resyncs = 0.0, 0
        self.stalls: deque[tuple[float, float]] = deque(maxlen=MAX_STALLS)
        self.missed_cycles = 0  # see EmulatorReport; counted by the protocol (cycle_answered)
        self._missed_run = 0     # missed cycles since the last fresh command
        self._sent_at = -math.inf  # wall-clock time of the last cycle's packet [s]
        self.timing = AnswerTiming(self.arm.cycle, tolerance=self.arm.dt)
        self._due = time.monotonic()  # when the current 1 ms step was due (monotonic) [s]
        self.closed = False
        self._ticks = 0
        self._estopped = self._protective = False

    # -------------------------------------------------------------------- protocol hooks
    @abstractmethod
    def motion_limits(self, robot: Robot) -> MotionLimits:
        """The limits this controller checks on consecutive cycle targets."""

    @abstractmethod
    def open(self) -> None:
        """Create and bind the sockets."""

    @abstractmethod
    def close_sockets(self) -> None:
        """Close every socket."""

    @abstractmethod
    def poll(self, t: float) -> None:
        """Handle what arrived (called every millisecond)."""

    @abstractmethod
    def on_cycle(self, t: float) -> None:
        """One controller cycle: take the command, send the status."""

    @property
    @abstractmethod
    def port(self) -> int:
        """The port in use (listening, or sent to)."""

    # --------------------------------------------------------------------------- helpers
    @property
    def t(self) -> float:
        """Simulation time [s]."""
        return self.arm.sim.time

    def inputs(self) -> dict[str, bool]:
        """Digital inputs now ({name: on}): the scripted windows, or the operator's hands."""
        state = self.options.inputs.state(self.t)
        if self.operator is not None:
            hands = self.operator.inputs(self.t)
            state = {name: state[name] or hands.get(name, False) for name in state}
        return state

    def datagrams(self, sock: socket.socket | None
                  ) -> Iterator[tuple[bytes, tuple[str, int], float, bool]]:
        """Every datagram queued on a non-blocking UDP socket (none if it is closed): data,
        sender, the kernel's receive time [s, ``CLOCK_REALTIME``] and whether it is the
        kernel's (:func:`~leadthrough.sim.emulators.answer_timing.recv_stamped`)."""
        while sock is not None:
            try:
                data, addr, rx, exact = recv_stamped(sock, 4096)
            except (BlockingIOError, ConnectionRefusedError):
                return
            assert addr is not None
            yield data, addr, rx, exact

    def transmit(self, sock: socket.socket, data: bytes, addr: tuple[str, int] | None,
                 key: int | None = None) -> None:
        """Send a packet through the fault plan (dropped, delayed, or sent now; on a stream
        socket never before a packet delayed before it: TCP delivers in order).

        Args:
            sock: Socket to send on.
            data: The packet.
            addr: Destination (UDP), or None for a connected stream socket.
            key: A status whose answer is timed (:attr:`timing`): its sequence number, IPOC
                or cycle index; None: not timed. A dropped status is not timed.
        """
        faults, t = self.options.faults, self.t
        self._sent_at = time.monotonic()  # the cycle's time, whatever the faults do to it
        if faults.drop(t, self.rng):
            self.dropped += 1
            return
        delay = faults.delay(t)
        # a stream (TCP) delivers in order: a packet leaves after those delayed before it
        queued = [item[0] for item in self._outbox if addr is None and item[1] is sock]
        if delay > 0 or queued:
            self.delayed += 1
            self._outbox.append((max([time.monotonic() + delay, *queued]), sock, data, addr,
                                 key))
            return
        self._send_now(sock, data, addr, key)

    def _send_now(self, sock: socket.socket, data: bytes, addr: tuple[str, int] | None,
                  key: int | None = None) -> None:
        at, late = time.time(), time.monotonic() - self._due  # just before the system call
        try:
            if addr is None:
                sock.sendall(data)
            else:
                sock.sendto(data, addr)
            self.sent += 1
        except OSError:
            self.on_send_error(sock)
            return
        if key is not None:
            self.timing.sent(key, at, late, label=self.t, done=time.time())

    def wait_for_reply(self) -> None:
        """No reply to the last cycle's packet yet: when this cycle runs early by the wall
        clock (the 1 ms loop catching up after a lag of its own), wait until the cycle's real
        time, a cycle after that packet went out, and read what has come in. A real
        controller's cycles are evenly spaced: a reply counts as missing only when it is
        missing at that time. When the cycle runs late, read once more all the same: a reply
        that came in while this step simulated the arm (after the step's first read) is no
        missing reply (whether it came by the deadline is the answer timing's to say, from
        its kernel stamp). The protocols call it before counting a missed cycle."""
        if not self.options.realtime:
            return
        remaining = self._sent_at + self.arm.cycle - time.monotonic()
        if remaining > 0:
            time.sleep(remaining)
        self.poll(self.t)

    def cycle_answered(self, fresh: bool) -> None:
        """Count a streaming cycle: with a fresh command, or missed."""
        if fresh:
            self._missed_run = 0
        else:
            self.missed_cycles += 1
            self._missed_run += 1

    def stream_ended(self) -> None:
        """The stream ended (a stop request, or the watchdog): the cycles it missed just
        before are the stop's, not missed cycles the stream recovered from."""
        self.missed_cycles -= self._missed_run
        self._missed_run = 0
        self.timing.ended()

    def on_send_error(self, sock: socket.socket) -> None:  # noqa: B027 (optional hook)
        """A send failed (the peer went away); protocols may drop the connection."""

    def _flush(self) -> None:
        if not self._outbox:
            return
        now, keep = time.monotonic(), []
        for item in self._outbox:
            if item[0] <= now:
                self._send_now(*item[1:])
            else:
                keep.append(item)
        self._outbox = keep

    # ------------------------------------------------------------------------------ loop
    def tick(self) -> None:
        """One millisecond: scheduled events, input handling, the cycle, the simulator."""
        t, faults = self.t, self.options.faults
        if faults.close_at is not None and t >= faults.close_at and not self.closed:
            self.close_sockets()
            self.closed = True
            return
        if faults.estop_at is not None and t >= faults.estop_at and not self._estopped:
            self._estopped = True
            self.arm.stop(StopKind.ESTOP, "emergency stop pressed")
        if (faults.protective_stop_at is not None and t >= faults.protective_stop_at
                and not self._protective):
            self._protective = True
            self.arm.stop(StopKind.PROTECTIVE, "protective stop (safeguard)")
        self.poll(t)
        self.arm.step()
        self._ticks += 1
        if self._ticks % self.arm.steps == self.cycle_phase % self.arm.steps:
            self.on_cycle(self.t)
        self._flush()

    def run(self, stop: threading.Event) -> EmulatorReport:
        """Serve until ``stop`` is set or the sockets are closed by a fault.

        Args:
            stop: Set it to end the session.

        Returns:
            The session report.
        """
        dt = self.arm.dt
        t0, k = time.monotonic(), 0
        try:
            while not stop.is_set() and not self.closed:
                self._due = t0 + k * dt if self.options.realtime else time.monotonic()
                self.tick()
                k += 1
                if not self.options.realtime:
                    continue
                lag = time.monotonic() - (t0 + k * dt)
                if lag < 0:
                    time.sleep(-lag)
                    continue
                self.max_lag = max(self.max_lag, lag)
                if lag >= STALL_S:
                    self.stalls.append((round(self.t, 4), round(lag, 4)))
                self._note_lag(lag)
                if lag > self.arm.cycle:  # late by a cycle: carry on from now, no burst
                    self.resyncs += 1
                    t0 += lag
        finally:
            if not self.closed:
                self.close_sockets()
        return self.report()

    def _note_lag(self, lag: float) -> None:
        """The loop is ``lag`` [s] behind its schedule: tell the answer timing."""
        if lag <= self.timing.tolerance:
            return
        now = time.time()
        if lag > self.arm.cycle:
            self.timing.resynced(now - lag, lag)
        else:
            self.timing.lagged(now - lag, now)

    def report(self) -> EmulatorReport:
        """The session so far."""
        arm = self.arm
        kind = arm.stop_kind
        return EmulatorReport(
            kind=self.kind, sim_time=self.t, commands=arm.commands, accepted=arm.accepted,
            refused=arm.commands - arm.accepted, violations=tuple(arm.violations()),
            stop_kind=None if kind is None else kind.value, stop_reason=self.arm.stop_reason,
            sent=self.sent, dropped=self.dropped, delayed=self.delayed,
            max_lag=self.max_lag, resyncs=self.resyncs, stalls=tuple(self.stalls),
            missed_cycles=self.missed_cycles,
            operator_start=None if self.operator is None else self.operator.t0,
            operator_end=None if self.operator is None else self.operator.finished_at,
            timing=self.timing.counts())

    @property
    def faulted(self) -> bool:
        """The arm stopped on a fault (or is stopping)."""
        return self.arm.phase in (ArmPhase.STOPPING, ArmPhase.FAULT) and (
            self.arm.stop_kind is not StopKind.REQUEST)


class UdpController(EmulatedController):
    """An emulated controller with one non-blocking UDP socket bound to :attr:`bind_port`."""

    _sock: socket.socket | None = None

    @property
    def bind_port(self) -> int:
        """Local port to bind (0: an ephemeral port)."""
        return self.requested_port

    def open(self) -> None:
        """Bind the UDP socket on ``options.host``."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((self.options.host, self.bind_port))
        sock.setblocking(False)
        enable_rx_stamps(sock)
        self._sock = sock

    def close_sockets(self) -> None:
        """Close the socket."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None
