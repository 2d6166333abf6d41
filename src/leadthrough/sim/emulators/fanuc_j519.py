"""An emulated FANUC controller running Stream Motion (J519) on UDP port 60015.

The emulator is the server, as the real controller is. After a start packet it sends one
status packet per cycle (8 ms, or 4 ms with ``cycle_ms=4``) to the sender of the start packet
and takes, from each command packet carrying the sequence number of the latest status, the
joint targets of the next cycle. Its behaviour:

* limits: each target is checked against the drive file's joint velocity and acceleration
  limits and a jerk limit of 50 × the acceleration limit per second (finite differences over
  the cycle, as the controller rejects commands beyond its velocity, acceleration and jerk
  limits); a refused target starts a controlled stop and latches a fault (status bits 0 and
  2 cleared), as the controller's alarm does;
* missing commands: a cycle without a command (none came, or it answered an older status)
  continues at the last velocity (assumption: the manual is not public); when no command has
  come for the watchdog time (default 4 cycles) the arm makes a controlled stop at its
  deceleration limit, then faults. Status bit 1 (command received) tells whether the command
  answering the previous status arrived in time (assumption, as above);
* ``last_data``: the motion ends at that target (no watchdog afterwards); a stop packet ends
  the stream;
* limit queries (any time) are answered with 20-entry tables holding the same limits (deg/s,
  deg/s², deg/s³) for no payload and full payload, ``max_cartesian_speed`` 2000 mm/s;
* read I/O: with ``read_io_type`` 1 (DI) the status reports DI[index..index+15] masked;
  DI[1] is the enabling device and DI[2] the mark button;
* time stamp: the status packet's ``time_stamp`` is the controller clock in milliseconds
  (the unit the driver reads, :mod:`leadthrough.drivers.fanuc_j519.packets`) at a 2 ms
  resolution: the cycles run on the clock's ticks (every 8 or 4 ms of simulated time, from
  the period's end), so every stamp is even, is the instant of the status's data, and
  successive statuses differ by the cycle. Assumption, as the unit: the 2 ms step is the
  resolution stated for the field, which FANUC's manual (B-84904EN, not public) could not be
  checked for here;
* faults of :class:`~leadthrough.sim.emulators.scenario.FaultPlan`: dropped or late status
  packets, NaN joint angles, E-stop / protective stop (controlled stop, then status bits 0
  and 2 cleared), a closed port (the client's next send / receive gets ICMP port
  unreachable).

The wire format is :mod:`leadthrough.drivers.fanuc_j519.packets` (sources cited there).
"""

from __future__ import annotations

import math

import numpy as np

from leadthrough.drivers.fanuc_j519.limits import LimitKind
from leadthrough.drivers.fanuc_j519.packets import (
    DEFAULT_PORT,
    CommandPacket,
    IoType,
    LimitAnswer,
    LimitQuery,
    StartPacket,
    StatusBits,
    StatusPacket,
    StopPacket,
    decode_client_packet,
)
from leadthrough.errors import DataError
from leadthrough.robot.description import Robot
from leadthrough.sim.emulators.arm import ArmPhase, MotionLimits, StopKind
from leadthrough.sim.emulators.controller import UdpController
from leadthrough.sim.emulators.scenario import EmulatorOptions

__all__ = ["TIMESTAMP_RESOLUTION_MS", "FanucJ519Emulator", "status_timestamp"]

JERK_PER_ACCEL = 50.0  # jerk limit = 50/s × acceleration limit
TIMESTAMP_RESOLUTION_MS = 2  # the status time stamp's step [ms] (module doc)
WATCHDOG_CYCLES = 4
DI_INPUTS = {1: "enable", 2: "mark", 3: "reset"}  # DI number -> input name


def status_timestamp(t: float) -> int:
    """The status packet's ``time_stamp`` at simulation time ``t`` [s]: milliseconds on the
    controller's 2 ms clock (the last tick at or before ``t``), modulo 2**32."""
    ms = round(t * 1000)
    return (ms - ms % TIMESTAMP_RESOLUTION_MS) & 0xFFFFFFFF


class FanucJ519Emulator(UdpController):
    """FANUC J519 controller (see the module doc)."""

    kind = "fanuc-j519"
    default_cycle_ms = 8
    cycle_phase = 0  # cycles on the 2 ms clock's ticks (the time stamp, module doc)

    def __init__(self, robot: Robot, seed: int, options: EmulatorOptions,
                 port: int = DEFAULT_PORT) -> None:
        super().__init__(robot, seed, options, port)
        self.watchdog = (options.watchdog if options.watchdog is not None
                         else WATCHDOG_CYCLES * self.arm.cycle)
        self.client: tuple[str, int] | None = None
        self.streaming = False
        self.sequence = 0
        self._pending: CommandPacket | None = None
        self._io = (0, 0, 0)
        self._motion = False      # a motion has started and not ended (last_data)
        self._silent = 0.0        # time without a command during a motion [s]
        self.late_commands = self.malformed = 0

    def motion_limits(self, robot: Robot) -> MotionLimits:
        """Velocity, acceleration and jerk (J519 checks all three)."""
        return MotionLimits.of(robot, acceleration=True, jerk_per_accel=JERK_PER_ACCEL)

    @property
    def port(self) -> int:
        """The bound UDP port."""
        return int(self._sock.getsockname()[1]) if self._sock is not None else self.requested_port

    # ---------------------------------------------------------------------------- input
    def poll(self, t: float) -> None:
        """Handle start, stop, command and limit-query packets."""
        for data, addr, rx, exact in self.datagrams(self._sock):
            try:
                packet = decode_client_packet(data)
            except DataError:
                self.malformed += 1
                continue
            if isinstance(packet, CommandPacket) and self.streaming and addr == self.client:
                self.timing.answer(rx, key=packet.sequence, exact=exact)
            self._handle(packet, addr, t)

    def _handle(self, packet: StartPacket | StopPacket | CommandPacket | LimitQuery,
                addr: tuple[str, int], t: float) -> None:
        if isinstance(packet, StartPacket):
            self.client, self.streaming, self._pending = addr, True, None
        elif isinstance(packet, StopPacket):
            self.streaming, self._motion = False, False
            self.stream_ended()
            if self.arm.phase is ArmPhase.RUNNING:
                self.arm.stop(StopKind.REQUEST, "stop packet")
        elif isinstance(packet, LimitQuery):
            self._answer_limits(packet, addr)
        elif self.streaming and addr == self.client:
            if packet.sequence == self.sequence:
                self._pending = packet
            else:
                self.late_commands += 1

    def _answer_limits(self, query: LimitQuery, addr: tuple[str, int]) -> None:
        lim = self.arm.limits
        table = {LimitKind.VELOCITY: lim.velocity, LimitKind.ACCELERATION: lim.acceleration,
                 LimitKind.JERK: lim.jerk}[query.kind]
        j = query.axis - 1
        value = float(np.degrees(table[j])) if table is not None and j < self.robot.n else 0.0
        answer = LimitAnswer(query.axis, query.kind, max_cartesian_speed=2000, interval=100,
                             no_payload=(value,) * 20, full_payload=(value,) * 20)
        if self._sock is not None:
            self._send_now(self._sock, answer.encode(), addr)

    # ---------------------------------------------------------------------------- cycle
    def on_cycle(self, t: float) -> None:
        """Take the command answering the last status, then send the next status."""
        if not self.streaming or self.client is None or self._sock is None:
            return
        if self._pending is None and self._motion:
            self.wait_for_reply()
        received = self._pending is not None
        if self._pending is not None:
            self.cycle_answered(True)
            self._take(self._pending, t)
            self._pending = None
        elif self._motion and self.arm.phase is ArmPhase.RUNNING:
            self.cycle_answered(False)
            self._silent += self.arm.cycle
            if self._silent >= self.watchdog - 1e-9:
                self.arm.stop(StopKind.WATCHDOG, f"no command for {self._silent:.3f} s")
                self.stream_ended()
            else:
                self.arm.hold(extrapolate=True)
        self.sequence = (self.sequence + 1) & 0xFFFFFFFF
        self.transmit(self._sock, self._status(t, received).encode(), self.client,
                      key=self.sequence)

    def _take(self, cmd: CommandPacket, t: float) -> None:
        self._io = (cmd.read_io_type, cmd.read_io_index, cmd.read_io_mask)
        n = self.robot.n
        if cmd.data_style != 1:
            self.arm.refuse(cmd.positions[:n], t, "Cartesian command (data_style 0) not emulated")
            return
        q = np.radians(np.array(cmd.positions[:n], dtype=float))
        if self.arm.command(q, t):
            self._motion, self._silent = not cmd.last_data, 0.0

    def _status(self, t: float, received: bool) -> StatusPacket:
        ok = not self.faulted
        bits = (StatusBits.SYSTEM_READY if ok else 0) | (
            StatusBits.READY if ok and self.arm.phase is not ArmPhase.STOPPING else 0) | (
            StatusBits.COMMAND_RECEIVED if received else 0) | (
            StatusBits.IN_MOTION if self.arm.moving else 0)
        fb = self.arm.sample()
        joints = tuple(np.degrees(fb.q).tolist())
        if self.options.faults.nan(t):
            joints = (math.nan,) * len(joints)
        pose = self.arm.tcp_pose(fb.q)
        io_type, io_index, io_mask = self._io
        return StatusPacket(
            sequence=self.sequence, status=int(bits), joints=joints,
            current=tuple(fb.current.tolist()), position=(*pose, 0.0, 0.0, 0.0),
            timestamp=status_timestamp(t), read_io_type=io_type,
            read_io_index=io_index, read_io_mask=io_mask,
            read_io_value=self._read_io(io_type, io_index, io_mask))

    def _read_io(self, io_type: int, index: int, mask: int) -> int:
        if io_type != IoType.DI:
            return 0
        state = self.inputs()
        value = 0
        for di, name in DI_INPUTS.items():
            bit = di - index
            if 0 <= bit < 16 and state[name]:
                value |= 1 << bit
        return value & mask
