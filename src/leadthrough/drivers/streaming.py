"""What the drivers of real controllers share: a :class:`~leadthrough.drivers.protocol.Driver`
that answers each of the controller's cycles with one joint target.

The controller paces the exchange: it sends a state packet every cycle (FANUC J519 status,
UR RTDE data package, KUKA RSI ``<Rob>`` document) and takes the answer to it as the next
cycle's target. A :class:`StreamingDriver` maps the loop's calls onto that:

* :meth:`~StreamingDriver.step` waits (at most ``timeout``) for the next packet; none in time
  leaves the feedback stale (``read`` returns False, ``stats.timeouts`` counts it), and so
  does a packet whose cycle number is not newer than one already taken (``out_of_order``
  counts it: delivered late, behind a newer one; its cycle has gone by, and fed to the
  estimator it would be a step back in time); a broken
  link (closed connection or port, socket error, the controller refusing the exchange) raises
  :class:`~leadthrough.errors.DriverError`, naming the cause;
* :meth:`~StreamingDriver.read` converts the packet into SI units and fills the feedback,
  controller state and digital inputs included;
* :meth:`~StreamingDriver.write` answers the newest packet, once: the target passes the
  :class:`~leadthrough.drivers.cycle_limits.CycleLimiter` (the controller refuses targets
  beyond its limits), then goes out in the controller's units. Cycles whose packets were
  lost or came too late went by without a target from us; the limiter is told
  (:meth:`~leadthrough.drivers.cycle_limits.CycleLimiter.skip`), so the next target is judged
  against what the controller did meanwhile; so is an answer the controller reports it did
  not take in time (J519's "command received" bit, RSI's late-answer count, the UR program's
  echo of the command it took), which also sets ``COMMAND_REJECTED`` in the feedback (RSI:
  only late answers in a run, :mod:`~leadthrough.drivers.late_answers`; UR: never, its
  program just holds a cycle). A write with no new packet to answer sends nothing
  (``unanswered`` counts it): the controller is waiting for its next cycle, not for a second
  answer.

:meth:`~StreamingDriver.open` connects, runs the protocol's handshake and waits for the first
packet, checking it against the robot file (joint count, and every joint inside its limits,
which catches a wrong robot file, joint order or unit). From then on the controller expects an
answer every cycle: its own watchdog (J519's, the UR program's, RSI's late-packet count) stops
the robot if the answers stop, so the caller must have finished any slow set-up (compilation,
warm-up) before ``open``.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from typing import Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from leadthrough.drivers.cycle_limits import CycleLimiter, CycleLimits
from leadthrough.drivers.link import LinkError, LinkStats, Transport
from leadthrough.drivers.protocol import ControllerState, DriverFeedback, JointCommand
from leadthrough.errors import DriverError
from leadthrough.robot.description import Robot

__all__ = ["POSITION_SLACK", "StreamingDriver"]

Array = NDArray[np.float64]
S = TypeVar("S")

POSITION_SLACK = 0.02
"""How far [rad] a reported joint may lie outside the robot file's limits before ``open``
calls the robot file, joint order or unit wrong."""


class StreamingDriver(ABC, Generic[S]):
    """Base of the real-controller drivers (see the module doc).

    Args:
        robot: The robot file of the arm behind the controller.
        cycle: Controller cycle [s]: the driver's ``dt``.
        timeout: Longest wait of :meth:`step` for a packet [s]; None: 3 cycles.
        connect_timeout: Longest wait of :meth:`open` for the first packet [s].
        margin: Fraction of the controller's limits the limiter keeps.
    """

    controller = ""
    """Name of the controller interface, for messages."""

    stop_method = ""
    """How :meth:`close` ends the stream, in words (the loop logs it)."""

    client: Transport
    """The protocol's transport (set by the subclass)."""

    def __init__(self, robot: Robot, cycle: float, timeout: float | None,
                 connect_timeout: float, margin: float) -> None:
        self.robot = robot
        self._n = robot.n
        self._dt = cycle
        self.timeout = timeout if timeout is not None else 3.0 * cycle
        self.connect_timeout = connect_timeout
        self.margin = margin
        self.limiter: CycleLimiter | None = None
        self.opened = False
        self.unanswered = 0
        self.skipped_cycles = 0  # controller cycles that went by without our target
        self.late_answers = 0    # answers the controller reported as not taken in time
        self.out_of_order = 0    # packets not newer than one already taken (dropped)
        self._sample_late = False
        self._sample: S | None = None   # received, not yet read
        self._newest: S | None = None   # the packet the next write answers
        self._answered: int | None = None  # sequence number of the last packet answered
        self._answer_due = False
        self._aborted = False   # set by abort() from the watchdog's thread

    # --------------------------------------------------------------------------- protocol
    @property
    def n(self) -> int:
        """Number of joints."""
        return self._n

    @property
    def dt(self) -> float:
        """Servo period: the controller's cycle [s]."""
        return self._dt

    @property
    def simulated(self) -> bool:
        """False: :meth:`step` waits for the controller."""
        return False

    extrapolates = False
    """Whether the controller continues at the last velocity for one cycle without a target
    (else it holds the last target); see :meth:`CycleLimiter.skip`."""

    reports_torque = False
    """Whether the controller reports joint torque (``make_feedback`` then has a torque
    array)."""

    answer_late_packets = False
    """Whether a packet that may have waited is best answered anyway: the controller counts a
    packet left unanswered as late just as one answered late (RSI), so an answer can only
    help. Else a late answer is worse than none (J519 refuses it; the UR program holds a
    cycle either way): the loop answers at its start only packets it waited for
    (:func:`~leadthrough.session.servo_loop.fresh_packet`)."""

    def make_feedback(self) -> DriverFeedback:
        """A feedback for this robot, holding no sample yet."""
        return DriverFeedback.empty(self._n, torque=self.reports_torque)

    def make_command(self) -> JointCommand:
        """A zero command for this robot (fill ``q`` before writing it)."""
        return JointCommand.zeros(self._n)

    def step(self) -> None:
        """Wait for the controller's next packet (at most ``timeout``).

        Raises:
            DriverError: Not open, or the link broke (its cause in the message).
        """
        self._require_open()
        self._aborted = False
        sample = self._receive(self.timeout)
        if self._aborted:
            self._aborted = False
            raise DriverError(f"the {self.controller} exchange was aborted by the loop's "
                              "watchdog", field="step", value="aborted",
                              expected="an exchange within the watchdog's abort time")
        if sample is None:
            self._raise_if_broken()
            return
        if self._newest is not None and self._sequence(sample) <= self._sequence(self._newest):
            self.out_of_order += 1   # not newer than one taken: stale, neither read nor
            return                   # answered (its controller cycle has gone by)
        late = self._answer_late(sample)
        if late and self.limiter is not None:
            self._after_late_answer()
            self.late_answers += 1
        self._sample, self._newest = sample, sample
        self._sample_late = self._rejected(sample, late)
        self._answer_due = True

    def read(self, fb: DriverFeedback) -> bool:
        """Fill ``fb`` with the packet the last :meth:`step` got, if any (SI units)."""
        sample = self._sample
        if sample is None:
            return False
        self._sample = None
        self._fill(fb, sample)
        if self._sample_late:
            fb.state |= ControllerState.COMMAND_REJECTED
        return True

    def write(self, cmd: JointCommand) -> None:
        """Answer the newest packet with ``cmd.q`` [rad], limited to the controller's limits.

        Raises:
            DriverError: Not open, or a command of the wrong shape or not finite (nothing is
                sent).
        """
        self._require_open()
        q = cmd.q
        if q.shape != (self._n,) or not np.all(np.isfinite(q)):
            raise DriverError("command not sent: wrong shape or not finite", field="cmd.q",
                              value=np.asarray(q).tolist(),
                              expected=f"{self._n} finite joint positions [rad]")
        if not self._answer_due or self.limiter is None or self._newest is None:
            self.unanswered += 1
            return
        self._answer_due = False
        sequence = self._sequence(self._newest)
        if self._answered is not None and sequence - self._answered > 1:
            self.skipped_cycles += sequence - self._answered - 1
            self.limiter.skip(sequence - self._answered - 1, self.extrapolates)
        self._answered = sequence
        self._send(self.limiter.limit(q))

    def abort(self) -> None:
        """Make the :meth:`step` in progress raise :class:`~leadthrough.errors.DriverError`
        when its receive returns (within ``timeout`` and the parse budget): called by the
        loop's watchdog, from its thread, for an exchange blocked past its abort time. The
        stream is not closed: the loop's end then calls :meth:`close`, which sends the
        protocol's stop (a commanded stop, not the controller's watchdog)."""
        self._aborted = True

    # ------------------------------------------------------------------------ connection
    def open(self) -> None:
        """Connect, run the handshake, check the first packet and start the limiter there.

        Raises:
            DriverError: The controller cannot be reached, refuses the stream, sends nothing
                within ``connect_timeout``, or reports joints that do not fit the robot file.
        """
        if self.opened:
            self.close()
        self._connect()
        try:
            first = self._first_packet()
            q = self._positions(first)
            self._check_positions(q)
            self.limiter = CycleLimiter(self._limits(), self._dt, self.margin)
            self.limiter.reset(self._start_target(first))
            self._answered = None
            self._started(first)
        except BaseException:
            self._disconnect()
            raise
        self.opened, self.unanswered, self.skipped_cycles, self.late_answers = True, 0, 0, 0
        self.out_of_order = 0
        self._sample, self._newest, self._answer_due = None, first, False

    def close(self) -> None:
        """End the stream (the controller's own way) and close the connection."""
        self._disconnect()
        self.opened = False

    def __enter__(self) -> StreamingDriver[S]:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _first_packet(self) -> S:
        deadline = time.monotonic() + self.connect_timeout
        while True:
            sample = self._receive(min(0.1, max(deadline - time.monotonic(), 0.0)))
            if sample is not None:
                return sample
            self._raise_if_broken()
            if time.monotonic() >= deadline:
                raise DriverError(f"no data from the {self.controller} controller",
                                  field="connect_timeout", value=self.connect_timeout,
                                  expected=self._no_data_hint())

    def _check_positions(self, q: Array) -> None:
        r = self.robot
        if q.shape != (self._n,) or not np.all(np.isfinite(q)):
            raise DriverError(f"the {self.controller} controller reports unusable joint "
                              "positions", field="q", value=np.asarray(q).tolist(),
                              expected=f"{self._n} finite values")
        out = (q < r.lower_limits - POSITION_SLACK) | (q > r.upper_limits + POSITION_SLACK)
        if np.any(out):
            j = int(np.argmax(out))
            raise DriverError(
                f"joint {j + 1} at {q[j]:.4g} rad is outside the robot file's limits: wrong "
                "robot file, joint order or unit", source=r.name, field=f"q[{j}]",
                value=float(q[j]), expected=f"{r.lower_limits[j]:.4g}..{r.upper_limits[j]:.4g}"
                " rad")

    def _require_open(self) -> None:
        if not self.opened:
            raise DriverError(f"the {self.controller} driver is not open", field="state",
                              value="closed", expected="open() first")

    def _raise_if_broken(self) -> None:
        err = self.link_error
        if err is not None:
            raise DriverError(f"{self.controller} link lost: {err.detail}", field="link",
                              value=err.kind.value, expected="a live connection")

    @property
    def stats(self) -> LinkStats:
        """Counters of the transport (received, timeouts, packets superseded before they were
        read, lost packets by sequence number, ...)."""
        return self.client.stats

    @property
    def link_error(self) -> LinkError | None:
        """The link failure, if any (closed connection or port, socket error, refusal)."""
        return self.client.error

    # ----------------------------------------------------------------- protocol specifics

    @abstractmethod
    def _connect(self) -> None:
        """Open the sockets and run the handshake (DriverError on failure)."""

    @abstractmethod
    def _disconnect(self) -> None:
        """End the stream and close the sockets (best effort, never raises)."""

    @abstractmethod
    def _receive(self, timeout: float) -> S | None:
        """The newest packet within ``timeout``, or None."""

    @abstractmethod
    def _positions(self, sample: S) -> Array:
        """The packet's joint positions [rad], shape (n,)."""

    @abstractmethod
    def _sequence(self, sample: S) -> int:
        """The packet's cycle number (+1 per controller cycle)."""

    @abstractmethod
    def _fill(self, fb: DriverFeedback, sample: S) -> None:
        """Fill the feedback from a packet."""

    @abstractmethod
    def _send(self, q: Array) -> None:
        """Send the target [rad] answering the newest packet."""

    @abstractmethod
    def _limits(self) -> CycleLimits:
        """The limits the controller enforces on consecutive targets."""

    def _start_target(self, first: S) -> Array:
        """The controller's target when the stream starts [rad] (default: the positions)."""
        return self._positions(first)

    def _answer_late(self, sample: S) -> bool:
        """Whether ``sample`` reports that the controller did not take our answer to the
        packet before it in time (default: the protocol does not tell)."""
        return False

    def _after_late_answer(self) -> None:
        """The limiter follows what the controller did instead of our late answer (default:
        back to the state before it, then a cycle without a target)."""
        assert self.limiter is not None
        self.limiter.retract(self.extrapolates)

    def _rejected(self, sample: S, late: bool) -> bool:
        """Whether ``sample``'s feedback reports ``COMMAND_REJECTED`` (default: every late
        answer; a controller that tolerates isolated ones may wait for a run)."""
        return late

    def _answered_previous(self, sample: S) -> bool:
        """Whether our last answer was to the packet just before ``sample``."""
        return self._answered is not None and self._sequence(sample) - self._answered == 1

    def _started(self, first: S) -> None:
        """Called once the first packet is checked (e.g. to answer it at once)."""

    def _no_data_hint(self) -> str:
        return "a packet within the timeout: is the controller streaming?"
