"""A :class:`~leadthrough.drivers.protocol.Driver` for Universal Robots arms over RTDE, with
the servo URScript program (:mod:`leadthrough.drivers.ur_rtde.script`).

:meth:`UrRtdeDriver.open` connects to RTDE (:class:`~leadthrough.drivers.ur_rtde.client.
RtdeClient`: protocol version 2, output recipe at the controller's rate, input recipe of the
program's registers), sends the program to the secondary interface (``script_port``; None if
the program is started another way, e.g. from the pendant) and waits until the program
reports itself running in its state register. The program idles in hold until the first
command, so the caller may finish its set-up after ``open``; from the first command on, its
watchdog stops the arm when commands stop for ``watchdog_timeout``.

Every data package (500 Hz e-Series, 125 Hz CB3) is a feedback sample:

* ``actual_q`` [rad] → ``q``, ``actual_current`` [A] → ``current``, ``timestamp`` [s] → ``t``
  and ``sequence`` (periods since the first package, so a lost package is a jump);
* ``actual_digital_input_bits`` → ``inputs`` (bit k = DI k: 0-7 standard, 8-15
  configurable, 16-17 tool);
* ``safety_mode`` 6 or 7 (system / robot emergency stop) → ``ESTOP``; 3, 5, 12 or 13
  (protective, safeguard, automatic-mode safeguard, three-position enabling stop) →
  ``PROTECTIVE_STOP``; 8 or 9 (violation, fault) → ``NOT_READY``; ``robot_mode`` other than
  7 (RUNNING), ``runtime_state`` other than 2 (PLAYING) or the program's state register
  other than 1 (running) → ``NOT_READY``.

Commands write the six targets, a watchdog counter (+1 per command) and mode 1 (servo) into
the input registers; targets pass a :class:`~leadthrough.drivers.cycle_limits.CycleLimiter`
with the robot file's joint speed limits (a ``servoj`` target too far from the last one makes
the controller stop with a protective stop; ``servoj`` smooths the targets itself, so their
acceleration is not limited here). The program echoes the counter of the targets it gave
``servoj`` in ``output_int_register_{R+1}``: a package whose echo is not our last command's
counter means that command came after the program's read (a slow client), and the arm held
the echoed targets for the cycle; the next command is judged from those (counted in
``late_answers``; not a refusal: the program only held a cycle). :meth:`UrRtdeDriver.close` writes
mode 2 (the program stops the arm with ``stopj`` and halts), then pauses and disconnects.

Mode, safety and runtime codes: Universal Robots' RTDE guide (output table) and the
``robot_mode`` / ``safety_mode`` enumerations of its client interface documentation.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from leadthrough.drivers.cycle_limits import CycleLimits
from leadthrough.drivers.link import LinkErrorKind
from leadthrough.drivers.protocol import ControllerState, DriverFeedback
from leadthrough.drivers.streaming import Array, StreamingDriver
from leadthrough.drivers.ur_rtde.client import DEFAULT_OUTPUTS, RtdeClient, RtdeState, ServoCommand
from leadthrough.drivers.ur_rtde.protocol import DEFAULT_PORT
from leadthrough.drivers.ur_rtde.script import (
    SECONDARY_PORT,
    Mode,
    ScriptState,
    ServoScriptParameters,
    servo_script,
    upload_script,
)
from leadthrough.errors import DriverError
from leadthrough.robot.description import Robot

__all__ = ["UrRtdeDriver", "controller_state"]

ROBOT_RUNNING = 7
RUNTIME_PLAYING = 2
ESTOP_MODES = frozenset((6, 7))
PROTECTIVE_MODES = frozenset((3, 5, 12, 13))
FAULT_MODES = frozenset((8, 9))
_KEEP_SENT = 64  # commands remembered for the program's echo (0.13 s at 500 Hz)


def controller_state(values: dict[str, object], register: str) -> ControllerState:
    """:class:`ControllerState` flags of an output data package (see the module doc).

    Args:
        values: The package's variables by name.
        register: Name of the program's state register (``output_int_register_R``).
    """
    safety = values.get("safety_mode")
    state = ControllerState.NORMAL
    if safety in ESTOP_MODES:
        state |= ControllerState.ESTOP
    elif safety in PROTECTIVE_MODES:
        state |= ControllerState.PROTECTIVE_STOP
    elif safety in FAULT_MODES:
        state |= ControllerState.NOT_READY
    if (values.get("robot_mode") != ROBOT_RUNNING
            or values.get("runtime_state") != RUNTIME_PLAYING
            or values.get(register) != ScriptState.RUNNING):
        state |= ControllerState.NOT_READY
    return state


class UrRtdeDriver(StreamingDriver[RtdeState]):
    """UR RTDE driver (see the module doc).

    Args:
        robot: Robot file of the arm (6 joints).
        host: Controller address.
        port: RTDE port (30004).
        script_port: Secondary interface port the program is sent to (30002); None: do not
            send it (it is started another way).
        frequency: RTDE output frequency [Hz]; None: the controller's (500 e-Series, 125 CB3).
        script: Program parameters (``period`` is set to the RTDE period).
        timeout: Longest wait for a data package [s]; None: 3 periods.
        connect_timeout: Longest wait for the handshake, the first package and the program
            start [s].
        margin: Fraction of the limits kept by the limiter.
    """

    controller = "UR RTDE"
    stop_method = ("mode 2 in the input registers: the servo program stops the arm (stopj) "
                   "and halts; RTDE paused")
    client: RtdeClient

    def __init__(self, robot: Robot, host: str, port: int = DEFAULT_PORT, *,
                 script_port: int | None = SECONDARY_PORT, frequency: float | None = None,
                 script: ServoScriptParameters | None = None, timeout: float | None = None,
                 connect_timeout: float = 2.0, margin: float = 0.95) -> None:
        if robot.n != 6:
            raise DriverError("UR arms have 6 joints", source=robot.name, field="robot.n",
                              value=robot.n, expected="6")
        period = 1.0 / frequency if frequency is not None else 0.002
        super().__init__(robot, period, timeout, connect_timeout, margin)
        self.host, self.script_port = host, script_port
        self.script = script if script is not None else ServoScriptParameters()
        self._fixed_timeout = timeout is not None
        reg = self.script.register_offset
        outputs = (*DEFAULT_OUTPUTS[:-1], f"output_int_register_{reg + 1}",
                   f"output_int_register_{reg}")
        self.client = RtdeClient(host, port, outputs=outputs, frequency=frequency,
                                 register_offset=self.script.register_offset,
                                 timeout=connect_timeout)
        self._register = outputs[-1]
        self._echo = outputs[-2]
        self._counter = 0
        # recent targets sent, by watchdog counter: row counter % _KEEP_SENT, preallocated
        self._sent = np.zeros((_KEEP_SENT, 6))
        self._sent_counter = np.full(_KEEP_SENT, -1, dtype=np.int64)
        self._reach = np.zeros((4, 6))  # _within_reach's step, bounds and result
        self._late_counter: int | None = None
        self._flags = ControllerState.NORMAL   # controller_state of the package _flags_of
        self._flags_of: RtdeState | None = None
        self._echoed: int | None = None  # the newest echo of the program
        self._last: RtdeState | None = None
        self._t0: float | None = None

    @property
    def last_state(self) -> RtdeState | None:
        """The newest data package, all variables of the output recipe."""
        return self._last

    def _connect(self) -> None:
        self.client.open()
        self._dt = 1.0 / float(self.client.frequency or 500.0)
        if not self._fixed_timeout:
            self.timeout = 3.0 * self._dt
        self._counter, self._t0 = 0, None
        self._sent_counter[:] = -1
        self._late_counter, self._echoed = None, None
        self._flags_of = None
        if self.script_port is None:
            return
        try:
            program = servo_script(dataclasses.replace(self.script, period=self._dt))
            upload_script(self.host, program, self.script_port, self.connect_timeout)
        except BaseException:
            self.client.close()
            raise

    def _started(self, first: RtdeState) -> None:
        """Wait until the program reports itself running."""
        deadline = time.monotonic() + self.connect_timeout
        state = first
        while state.values.get(self._register) != ScriptState.RUNNING:
            if time.monotonic() > deadline:
                raise DriverError(
                    "the servo program is not running", field=self._register,
                    value=state.values.get(self._register),
                    expected=f"{int(ScriptState.RUNNING)} within {self.connect_timeout} s (robot "
                    "powered on, in remote control, no protective stop; robot_mode "
                    f"{state.values.get('robot_mode')}, safety_mode "
                    f"{state.values.get('safety_mode')})")
            got = self._receive(0.1)
            self._raise_if_broken()
            state = got if got is not None else state

    def _limits(self) -> CycleLimits:
        # the controller checks the joint speed of servoj targets (a faster step is a
        # protective stop) and smooths them itself (lookahead_time, gain): speed only here
        return CycleLimits(self.robot.velocity_limit.copy())

    def _disconnect(self) -> None:
        err = self.client.error   # a refused stream still takes the stop; a broken socket not
        if self.opened and (err is None or err.kind is LinkErrorKind.PROTOCOL):
            self.client.send(ServoCommand(tuple(self.limiter.position) if self.limiter
                                          else (0.0,) * 6, self._counter + 1, Mode.STOP))
        self.client.close()

    def _receive(self, timeout: float) -> RtdeState | None:
        state = self.client.receive(timeout)
        if state is not None:
            self._last = state
        return state

    def _positions(self, sample: RtdeState) -> Array:
        return np.array(sample.q, dtype=float)

    def _sequence(self, sample: RtdeState) -> int:
        if self._t0 is None:  # periods since the first package (its phase is arbitrary)
            self._t0 = sample.timestamp
        return round((sample.timestamp - self._t0) / self._dt)

    def _fill(self, fb: DriverFeedback, sample: RtdeState) -> None:
        v = sample.values
        fb.t = sample.timestamp
        fb.sequence = self._sequence(sample)
        fb.q[:] = sample.q
        fb.current[:] = sample.current
        fb.state = int(self._state(sample))
        fb.inputs = int(v.get("actual_digital_input_bits", 0))
        fb.inputs_read = "actual_digital_input_bits" in v

    def _state(self, sample: RtdeState) -> ControllerState:
        """:func:`controller_state` of ``sample``, computed once per package (a step judges
        its answer by it, the read reports it)."""
        if sample is not self._flags_of:
            self._flags, self._flags_of = controller_state(sample.values, self._register), sample
        return self._flags

    def _sent_target(self, counter: int) -> Array | None:
        """The target sent with ``counter``, if among the last :data:`_KEEP_SENT` sent."""
        row = counter % _KEEP_SENT
        return self._sent[row] if self._sent_counter[row] == counter else None

    def _send(self, q: Array) -> None:
        q = self._within_reach(q)
        self._counter = (self._counter + 1) & 0x7FFFFFFF
        row = self._counter % _KEEP_SENT
        self._sent[row] = q
        self._sent_counter[row] = self._counter
        self.client.send(ServoCommand(tuple(q.tolist()), self._counter, Mode.SERVO))

    def _within_reach(self, q: Array) -> Array:
        """``q`` [rad] within one cycle at the limiter's speed of every target the arm may
        hold when it takes it: the newest echoed one and each sent after it (a late command
        may still be taken before this one). Usually that is the last target sent alone and
        the limiter's output passes unchanged; the targets are pairwise within that step, so
        the intersection is never empty."""
        if self._echoed is None:
            return q
        step, lo, hi, out = self._reach
        np.multiply(self.robot.velocity_limit, self.margin * self._dt, out=step)
        lo[:], hi[:] = -np.inf, np.inf
        for c in range(max(self._echoed, self._counter - _KEEP_SENT + 1), self._counter + 1):
            held = self._sent_target(c)
            if held is not None:
                np.maximum(lo, held - step, out=lo)
                np.minimum(hi, held + step, out=hi)
        np.maximum(lo, hi, out=hi)
        return np.clip(q, lo, hi, out=out)

    def _rejected(self, sample: RtdeState, late: bool) -> bool:
        """Never: the program's servoj repeats the last target, a held cycle, not a refusal."""
        return False

    def _answer_late(self, sample: RtdeState) -> bool:
        """Our last command missed the program's cycle: the package's echo (the counter of
        the targets servoj took) is not its counter (once per command: a client that is
        slow to answer sees several packages before its next one). Only while the controller
        is in a normal state with the program running: once a protective stop, an E-stop or
        the program's watchdog halts it (its state register keeps the last value the program
        wrote) no package echoes a newer counter, and that is the controller's state
        (:func:`controller_state`), not a late answer per package."""
        echo = sample.values.get(self._echo)
        if echo is None or self._answered is None:
            return False
        if self._state(sample) != ControllerState.NORMAL:
            return False
        if self._echoed is None and self._sent_target(int(echo)) is None:
            return False  # no echo of ours yet (a program that does not echo: never)
        self._echoed = int(echo)
        if self._echoed == self._counter or self._late_counter == self._counter:
            return False
        self._late_counter = self._counter
        return True

    def _after_late_answer(self) -> None:
        """The arm holds the targets servoj last took: the next command is judged from them
        (a retract would assume the command before the late one; under a slow client that
        one may be late too). Called by the step that judged the answer late: nothing has been
        sent since, the echoed target is still in the ring."""
        assert self.limiter is not None
        taken = self._sent_target(self._echoed) if self._echoed is not None else None
        if taken is not None:
            self.limiter.reset(taken)
        else:
            self.limiter.retract(self.extrapolates)

    def _no_data_hint(self) -> str:
        return "data packages: is RTDE enabled on the controller?"
