"""A :class:`~leadthrough.drivers.protocol.Driver` for FANUC Stream Motion (option J519).

:class:`FanucJ519Driver` runs on :class:`~leadthrough.drivers.fanuc_j519.client.
StreamMotionClient`: :meth:`~FanucJ519Driver.open` sends the start packet, asks the controller
for its velocity, acceleration and jerk limit tables of axes 1..n (and of axis n+1: a robot
with more axes than the robot file is refused) and waits for the first status packet. Every
status packet (8 ms, or 4 ms where the controller runs that cycle) is a feedback sample:

* joint angles [deg] → ``q`` [rad], motor currents [A] → ``current``, ``sequence_no`` →
  ``sequence``, ``time_stamp`` [ms] → ``t`` [s];
* status bits 0 (ready for commands) and 2 (SYSRDY) not both set → ``NOT_READY`` (J519 does
  not tell an E-stop from an alarm or servo power off: each clears SYSRDY); bit 1 (command
  received) clear after we answered the previous status → ``COMMAND_REJECTED`` (our answer
  came too late: the controller ran that cycle without it);
* ``read_io_value`` → ``inputs`` (bit k = DI[``input_index`` + k]) once the controller echoes
  the digital-input read that every command requests.

Each command answers the newest status with its sequence number, and only a status that
reports the controller ready (bits 0 and 2, as FANUC's sample client requires) is answered
(``withheld`` counts the others); the targets pass a
:class:`~leadthrough.drivers.cycle_limits.CycleLimiter` set to the most restrictive entry of
each limit table (no payload and full payload, every TCP-speed step) and the robot file's own
velocity and acceleration limits, scaled by ``margin``: the controller rejects a command beyond
its limits with an alarm. :meth:`~FanucJ519Driver.close` sends the stop packet.

Wire format and sources: :mod:`leadthrough.drivers.fanuc_j519.packets`.
"""

from __future__ import annotations

import numpy as np

from leadthrough.drivers.cycle_limits import CycleLimits
from leadthrough.drivers.fanuc_j519.client import StreamMotionClient
from leadthrough.drivers.fanuc_j519.limits import LimitAnswer, LimitKind
from leadthrough.drivers.fanuc_j519.packets import (
    DEFAULT_PORT,
    MAX_AXES,
    IoType,
    StatusBits,
    StatusPacket,
)
from leadthrough.drivers.protocol import ControllerState, DriverFeedback
from leadthrough.drivers.streaming import Array, StreamingDriver
from leadthrough.errors import DriverError
from leadthrough.robot.description import Robot

__all__ = ["FanucJ519Driver"]


def _table_min(answer: LimitAnswer) -> float:
    """The most restrictive positive entry of a limit answer [deg/s^k] (0: none)."""
    values = [v for v in (*answer.no_payload, *answer.full_payload) if v > 0]
    return min(values) if values else 0.0


class FanucJ519Driver(StreamingDriver[StatusPacket]):
    """FANUC J519 driver (see the module doc).

    Args:
        robot: Robot file of the arm (1..9 axes, in J519's axis order).
        host: Controller address.
        port: Stream Motion port (60015).
        cycle: The controller's interpolation cycle [s] (0.008; 0.004 where configured).
        input_index: First digital input read every cycle (DI[input_index..+15]).
        timeout: Longest wait for a status packet [s]; None: 3 cycles.
        connect_timeout: Longest wait for the limit answers and the first status [s].
        margin: Fraction of the limits kept by the limiter.
    """

    controller = "FANUC J519"
    stop_method = "J519's stop packet: the controller ends Stream Motion"
    client: StreamMotionClient
    extrapolates = True  # missed cycles go on at the last velocity (the emulator's assumption)

    def __init__(self, robot: Robot, host: str, port: int = DEFAULT_PORT, *,
                 cycle: float = 0.008, input_index: int = 1, timeout: float | None = None,
                 connect_timeout: float = 2.0, margin: float = 0.95) -> None:
        if not 1 <= robot.n <= MAX_AXES:
            raise DriverError("J519 streams 1 to 9 axes", source=robot.name, field="robot.n",
                              value=robot.n, expected=f"1..{MAX_AXES}")
        super().__init__(robot, cycle, timeout, connect_timeout, margin)
        self.client = StreamMotionClient(host, port, read_io=(IoType.DI, input_index, 0xFFFF))
        self.controller_limits: dict[LimitKind, Array] = {}
        self.withheld = 0  # commands not sent because the controller was not ready

    @property
    def last_status(self) -> StatusPacket | None:
        """The newest status packet (its raw bits, I/O and TCP pose)."""
        return self.client.last_status

    def _connect(self) -> None:
        self.client.open()
        try:
            self._query_limits()
        except BaseException:
            self.client.close()
            raise

    def _query_limits(self) -> None:
        n, c = self._n, self.client
        answers = c.query_limits(range(1, n + 1), timeout=self.connect_timeout)
        self.controller_limits = {
            kind: np.radians([_table_min(answers[(a, kind)]) for a in range(1, n + 1)])
            for kind in LimitKind}
        if n < MAX_AXES:
            try:
                extra = c.query_limits([n + 1], timeout=min(0.3, self.connect_timeout))
            except DriverError:
                extra = {}  # no answer: no such axis
            answer = extra.get((n + 1, LimitKind.VELOCITY))
            if answer is not None and _table_min(answer) > 0:
                raise DriverError("the controller streams more axes than the robot file has",
                                  source=self.robot.name, field="robot.n", value=n,
                                  expected=f"at least {n + 1} axes (axis {n + 1} has limits)")
        for kind, values in self.controller_limits.items():
            if np.any(values <= 0):
                j = int(np.argmax(values <= 0))
                raise DriverError("the controller has no limit for this axis",
                                  field=f"{kind.name.lower()} limit of axis {j + 1}",
                                  value=0.0, expected="> 0 (is the axis configured?)")

    def _limits(self) -> CycleLimits:
        lim, r = self.controller_limits, self.robot
        return CycleLimits(np.minimum(lim[LimitKind.VELOCITY], r.velocity_limit),
                           np.minimum(lim[LimitKind.ACCELERATION], r.acceleration_limit),
                           lim[LimitKind.JERK])

    def _disconnect(self) -> None:
        self.client.close()

    def _receive(self, timeout: float) -> StatusPacket | None:
        return self.client.receive(timeout)

    def _positions(self, sample: StatusPacket) -> Array:
        return np.radians(sample.joints[:self._n])

    def _sequence(self, sample: StatusPacket) -> int:
        return sample.sequence

    def _answer_late(self, sample: StatusPacket) -> bool:
        # the emulator's documented reading of bit 1: set when the command answering the
        # previous status arrived within the cycle (a controller that keeps it set once a
        # command came, as some clients read it, never reports a late answer this way)
        return (self._answered_previous(sample) and sample.ready
                and not sample.status & StatusBits.COMMAND_RECEIVED)

    def _fill(self, fb: DriverFeedback, sample: StatusPacket) -> None:
        n = self._n
        fb.t = sample.timestamp * 1e-3
        fb.sequence = sample.sequence
        fb.q[:] = np.radians(sample.joints[:n])
        fb.current[:] = sample.current[:n]
        fb.state = int(ControllerState.NORMAL if sample.ready else ControllerState.NOT_READY)
        fb.inputs_read = sample.read_io_type == IoType.DI
        fb.inputs = sample.read_io_value if fb.inputs_read else 0

    def _send(self, q: Array) -> None:
        last = self.client.last_status
        if last is not None and not last.ready:  # FANUC's sample client: status & 5 == 5
            self.withheld += 1
            return
        self.client.send(self.client.make_command(np.degrees(q).tolist()))

    def _no_data_hint(self) -> str:
        return "status packets: is the TP program with IBGN start running?"
