"""A :class:`~leadthrough.drivers.protocol.Driver` for KUKA robots over RSI (Ethernet), with the
shipped controller configuration (:mod:`leadthrough.drivers.kuka_rsi.config`).

Here the robot sends first: :meth:`KukaRsiDriver.open` binds the UDP port of the Ethernet
configuration (49152) and waits up to ``connect_timeout`` for the first ``<Rob>`` document
(start ``leadthrough_rsi.src`` on the robot once the driver listens; ``listen`` binds the
port beforehand), answers it at once with
zero motion and takes its ``ASPos`` (the axis setpoints at ``RSI_ON``) as the reference of the
absolute corrections (``RSI_ON(#ABSOLUTE)``: target = reference + AK).

Who the robot is: documents are taken from one sender only, the robot's address and port:
given as ``robot_address`` (``--robot-address HOST[:PORT]``), or else **fixed by the first valid
document** (:attr:`KukaRsiDriver.peer`). Without ``robot_address`` a process that sends a valid
document before the robot does is taken for the robot for the whole session, and the robot's
own documents are then dropped as foreign (unanswered, it stops RSI after its ``Timeout``); so
give ``robot_address`` on any network or computer that others share. Documents from any other
sender are dropped unparsed and counted (``stats.bad[BadPacket.FOREIGN]``), never answered; an
IPOC that does not advance by whole cycles is a counted bad packet, a run of them a broken link
after which :meth:`~KukaRsiDriver.close` still answers the robot with ``Stop``
(:mod:`~leadthrough.drivers.kuka_rsi.client`); every document is parsed with DTDs and entities
refused and a strict grammar (:mod:`~leadthrough.drivers.kuka_rsi.messages`).

Every document (4 ms) is a feedback sample:

* ``AIPos`` [deg] → ``q`` [rad], ``IPOC`` [ms] → ``t`` [s] and ``sequence`` ((IPOC - first
  IPOC) / cycle, so a lost document is a jump);
* ``GearTorque`` [N·m] (the GEARTORQUE object: joint torque, not current) → ``torque`` (when
  the feedback has a torque array, as :meth:`~KukaRsiDriver.make_feedback` gives) and
  ``current`` = torque / (R·Kt) of the robot file: the motor current that torque stands for,
  so that what takes currents (the estimator, identification) works unchanged;
* ``DiL`` → ``inputs`` (bit k = ``$IN[k+1]``);
* ``Delay`` grown by more than the documents we never received (the robot counted an answer
  of ours as late): counted (``late_answers``, ``tolerance``); only late answers in a run
  (:class:`~leadthrough.drivers.late_answers.LateAnswerTolerance`: 5 in a row, or 20 within
  250 cycles; RSI itself stops after ``Timeout`` = 100 in a row) → ``COMMAND_REJECTED``.
  An isolated late answer is one cycle in which the robot held its last correction, which RSI
  carries on from; latching a fault on each would end sessions on any PC that is not
  real-time. RSI reports no E-stop or protective stop: the
  robot stops sending (after an E-stop, a stop of the KRL program, or ``Timeout`` late
  answers in a row), which the driver sees as silence: ``read`` returns False, and the caller
  stops on stale feedback.

Answers carry the document's IPOC and AK = target - reference [deg]; targets pass a
:class:`~leadthrough.drivers.cycle_limits.CycleLimiter` with the robot file's joint speed
limits (the robot's speed monitoring stops a faster setpoint; its acceleration is left to the
loop's interpolator: a limit on it here would turn every cycle the robot held for a late
answer into a lag of millimetres that takes a fifth of a second to make up), then the
corrections are clipped to the context's AXISCORR range and within ``margin`` of
AXISCORRMON's maximum (a larger correction stops RSI).

:meth:`~KukaRsiDriver.close` ends the session the way KUKA's own client SDK does: the document
waiting for an answer (or the next) is answered with the last target held and
``<Stop>1</Stop>``, which the shipped context wires to its STOP object: ``RSI_MOVECORR()``
returns and the KRL program goes on to ``RSI_OFF`` (without it the robot counts ``Timeout``
late answers before RSI stops).

Message format and sources: :mod:`leadthrough.drivers.kuka_rsi.messages`.
"""

from __future__ import annotations

import numpy as np

from leadthrough.drivers.cycle_limits import CycleLimits
from leadthrough.drivers.kuka_rsi.client import DEFAULT_PORT, RsiClient
from leadthrough.drivers.kuka_rsi.config import EthernetConfig, RsiContext
from leadthrough.drivers.kuka_rsi.messages import RobotMessage
from leadthrough.drivers.late_answers import LateAnswerTolerance
from leadthrough.drivers.protocol import ControllerState, DriverFeedback
from leadthrough.drivers.streaming import Array, StreamingDriver
from leadthrough.drivers.wire import BadPacket
from leadthrough.errors import DriverError
from leadthrough.robot.description import Robot

__all__ = ["KukaRsiDriver"]


class KukaRsiDriver(StreamingDriver[RobotMessage]):
    """KUKA RSI driver (see the module doc).

    Args:
        robot: Robot file of the arm (6 axes A1-A6).
        host: Local address to listen on.
        port: Local UDP port (the Ethernet configuration's ``PORT``).
        cycle: RSI cycle [s] (0.004; 0.012 on KR C2).
        context: RSI context whose correction limits apply (default: the shipped one).
        config: Ethernet configuration (default: the shipped one; its ``SENTYPE`` is used).
        timeout: Longest wait for a document [s]; None: 3 cycles.
        connect_timeout: Longest wait for the robot's first document [s].
        margin: Fraction of the limits kept.
        tolerance: When late answers are ``COMMAND_REJECTED`` (default: 5 in a row or 20
            within 250 cycles; ``LateAnswerTolerance(1, 1, 1)``: every one).
        robot_address: The robot's (host, port or None): documents from anyone else are
            dropped and counted. None: the first valid document fixes the sender for the
            session, so a process that sends one before the robot does is taken for it
            (:mod:`~leadthrough.drivers.kuka_rsi.client`); :attr:`peer` says who was taken.
    """

    controller = "KUKA RSI"
    stop_method = ("an answer with Stop = 1: the context's STOP object ends RSI_MOVECORR (the "
                   "KRL program goes on to RSI_OFF)")
    client: RsiClient
    reports_torque = True
    answer_late_packets = True  # RSI counts a missing answer as late as a late one

    def __init__(self, robot: Robot, host: str = "0.0.0.0", port: int = DEFAULT_PORT, *,
                 cycle: float = 0.004, context: RsiContext | None = None,
                 config: EthernetConfig | None = None, timeout: float | None = None,
                 connect_timeout: float = 30.0, margin: float = 0.95,
                 tolerance: LateAnswerTolerance | None = None,
                 robot_address: tuple[str, int | None] | None = None) -> None:
        if robot.n != 6:
            raise DriverError("the RSI configuration streams 6 axes (A1-A6)",
                              source=robot.name, field="robot.n", value=robot.n, expected="6")
        super().__init__(robot, cycle, timeout, connect_timeout, margin)
        self.context = context if context is not None else RsiContext.shipped()
        self.config = config if config is not None else EthernetConfig.shipped()
        self.client = RsiClient(host, port, sentype=self.config.sentype,
                                precision=self.context.precision,
                                cycle_ms=round(cycle * 1000), robot_address=robot_address,
                                max_gap=self.context.timeout)
        ctx = self.context
        bound = np.array(ctx.max_correction) * margin
        self._ak_lo = np.maximum(np.array(ctx.lower), -bound)
        self._ak_hi = np.minimum(np.array(ctx.upper), bound)
        self._ipoc0 = 0
        self._delay: int | None = None
        self._seen = 0  # sequence of the newest document received
        self._late_count = 0  # late answers the newest document reports
        self.corrections_clipped = 0
        #: Late answers counted, and when they are a fault.
        self.tolerance = tolerance if tolerance is not None else LateAnswerTolerance()

    @property
    def address(self) -> tuple[str, int]:
        """The bound (address, port), the real port when 0 was asked."""
        return self.client.address

    @property
    def out_of_order(self) -> int:
        """Documents not newer than one already taken (delivered late behind a newer one, or
        repeated): the client drops them as ``BadPacket.STALE``; counted since ``open``."""
        return self._out_of_order + self.client.stats.bad[BadPacket.STALE]

    @out_of_order.setter
    def out_of_order(self, value: int) -> None:
        self._out_of_order = value

    @property
    def peer(self) -> tuple[str, int] | None:
        """The robot's (address, port) the documents are taken from (None: none yet)."""
        return self.client.peer

    @property
    def last_message(self) -> RobotMessage | None:
        """The newest ``<Rob>`` document."""
        return self.client.last_message

    def reach(self) -> tuple[Array, Array]:
        """The joint positions the corrections can reach [rad], (lower, upper), shapes (6,):
        the reference (``ASPos`` at ``RSI_ON``) plus the context's correction range as the
        driver clips it (AXISCORR, within ``margin`` of AXISCORRMON). A target beyond it is
        clipped: the robot stops short of it and the run ends on a following error.

        Raises:
            DriverError: Not open yet (no reference).
        """
        ref = self.client.reference
        if ref is None:
            raise DriverError("no reference yet", field="ASPos", value=None,
                              expected="open() first (the robot's first document)")
        return np.radians(np.array(ref) + self._ak_lo), np.radians(np.array(ref) + self._ak_hi)

    def listen(self) -> tuple[str, int]:
        """Bind the UDP port now (``open`` then waits on it); returns the bound address, the
        real port when 0 was asked (for a robot or emulator to be pointed at)."""
        if not self.client.bound:
            self.client.open()
        return self.client.address

    def _connect(self) -> None:
        self.listen()
        self._delay = None

    def _disconnect(self) -> None:
        if self.opened and self.limiter is not None:
            if self.client.error is None:
                self._answer_stop()
            else:  # a broken IPOC stream: still the Stop answer (a socket error: none)
                self.client.answer_stop(self._correction(self.limiter.position))
        self.client.close()

    def _answer_stop(self) -> None:
        """The session's last answer: the document waiting for one (else the next, within the
        timeout) answered with the last target held and ``<Stop>1</Stop>``. Without it (or on
        a robot whose configuration lacks ``Stop``) the robot counts ``Timeout`` late answers,
        then RSI stops."""
        if not self._answer_due and self.client.receive(self.timeout) is None:
            return
        assert self.limiter is not None
        self.client.send(self._correction(self.limiter.position), stop=True)
        self._answer_due = False

    def _receive(self, timeout: float) -> RobotMessage | None:
        return self.client.receive(timeout)

    def _positions(self, sample: RobotMessage) -> Array:
        return np.radians(sample.axis_actual)

    def _start_target(self, first: RobotMessage) -> Array:
        return np.radians(self.client.reference or first.axis_actual)

    def _started(self, first: RobotMessage) -> None:
        self._ipoc0 = first.ipoc
        self._delay, self._seen = first.delay, 0
        self.tolerance.reset()
        if self.limiter is not None:  # answered at once: zero motion
            self._send(self.limiter.limit(self._start_target(first)))
            self._answered = 0

    def _limits(self) -> CycleLimits:
        # the robot's monitoring checks the joint speed of the corrected setpoints
        return CycleLimits(self.robot.velocity_limit.copy())

    def _sequence(self, sample: RobotMessage) -> int:
        return (sample.ipoc - self._ipoc0) // self.client.cycle_ms

    def _answer_late(self, sample: RobotMessage) -> bool:
        """The robot counted more late answers than documents we never saw (none before our
        first answer: the documents of the set-up were not answered, and no command of ours
        was refused)."""
        counted = (sample.delay - self._delay if sample.delay is not None
                   and self._delay is not None else 0)
        self._delay = sample.delay if sample.delay is not None else self._delay
        unseen = self._sequence(sample) - self._seen - 1
        self._seen = self._sequence(sample)
        self._late_count = (counted - max(unseen, 0) if self._answered is not None else 0)
        return self._late_count > 0

    def _rejected(self, sample: RobotMessage, late: bool) -> bool:
        return self.tolerance.update(self._sequence(sample), self._late_count if late else 0)

    def _fill(self, fb: DriverFeedback, sample: RobotMessage) -> None:
        fb.t = sample.ipoc * 1e-3
        fb.sequence = self._sequence(sample)
        fb.q[:] = np.radians(sample.axis_actual)
        if sample.gear_torque is not None:
            torque = np.array(sample.gear_torque)
            fb.current[:] = torque / self.robot.torque_per_amp
            if fb.torque is not None:
                fb.torque[:] = torque
        else:
            fb.current[:] = np.nan
            if fb.torque is not None:
                fb.torque[:] = np.nan
        fb.state = int(ControllerState.NORMAL)
        fb.inputs_read = sample.digital_inputs is not None
        fb.inputs = sample.digital_inputs or 0

    def _send(self, q: Array) -> None:
        self.client.send(self._correction(q))

    def _correction(self, q: Array) -> list[float]:
        """AK [deg] for target ``q`` [rad], clipped to the context's range (counted)."""
        ak = np.array(self.client.correction_for(np.degrees(q).tolist()))
        clipped = np.clip(ak, self._ak_lo, self._ak_hi)
        if np.any(clipped != ak):
            self.corrections_clipped += 1
        return list(clipped.tolist())

    def _no_data_hint(self) -> str:
        return ("a <Rob> document: is leadthrough_rsi.src running, and does the Ethernet "
                "configuration's IP_NUMBER / PORT point at this computer?")
