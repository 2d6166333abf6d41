"""The driver protocol: how the guiding loop talks to a position-mode robot controller.

A driver delivers feedback samples (time, encoder joint positions, measured motor currents,
sequence number and, where the controller reports them, its own state and its digital inputs)
and takes a joint position + velocity command every servo period ``dt`` (1 ms on the simulator;
2, 4 or 8 ms on real controllers). Nothing is allocated in the loop: the caller makes one
:class:`DriverFeedback` and one :class:`JointCommand` with :meth:`Driver.make_feedback` and
:meth:`Driver.make_command` and the driver fills or reads them in place (ruckig-style).

The loop, for every driver::

    fb, cmd = drv.make_feedback(), drv.make_command()
    drv.step()                      # first sample (the robot holds its last command)
    drv.read(fb)
    cmd.q[:] = fb.q; cmd.qd[:] = 0.0
    while running:
        drv.write(cmd)              # command for the coming period
        drv.step()                  # advance one servo period
        if not drv.read(fb):        # no new sample: fb still holds the previous one
            ...                     # stale feedback: count it, stop after a few
        ...                         # compute the next cmd from fb

Controller state and digital inputs: a real controller's driver also fills
:attr:`DriverFeedback.state` (:class:`ControllerState` flags: E-stop, protective stop, not ready
for streamed commands, a command not taken) and :attr:`DriverFeedback.inputs` (its digital
inputs as a bit word, ``inputs_read`` telling whether the sample carried them), and a controller
that reports joint torque instead of motor current (KUKA RSI) fills
:attr:`DriverFeedback.torque`. These fields have defaults (normal state, no inputs, no torque),
so drivers and callers that do not use them are unaffected.

Errors: a driver raises when the link fails (:class:`~leadthrough.errors.DriverError`, or any
exception). The loop never lets one escape: it latches a fault and stops at the acceleration
limit if the link still takes commands, else it stops commanding (the controller's own watchdog
then stops the robot). A driver whose calls can block may also provide ``abort()``, callable from
another thread, which makes a blocked ``step`` or ``read`` return by raising: the loop's watchdog
calls it when a call has blocked beyond its timeout.

Ending: a real controller's driver provides ``close()``: the stream's own clean end (the UR
servo program's stop mode, J519's stop packet, RSI's ``Stop`` flag), then the disconnect; it
never raises for what the link does, may be called again (a no-op) and says what it did in
``stop_method``. The loop calls it once it has ended, whatever ended it, before it finishes
the recording (:func:`~leadthrough.session.loop.run_session`).

Start: a real controller's driver may say ``answer_late_packets`` (RSI): a packet left
unanswered counts as late as one answered late, so the loop answers at its start (with a hold)
the packets that waited during its set-up too; otherwise it answers only those it waited for
(J519 refuses a late answer).

Pacing: :meth:`Driver.step` is where the loop waits for the next servo period. A simulated
driver (``simulated`` true) advances its physics by one period and returns at once, so a
simulated session runs as fast as the CPU allows (pace it with the wall clock only to watch
it); a real driver's ``step`` blocks until the controller's next cycle, which paces the loop in
real time.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntFlag
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = ["ControllerState", "Driver", "DriverFeedback", "JointCommand", "WrappedDriver"]

Array = NDArray[np.float64]


class ControllerState(IntFlag):
    """What a real controller reports about itself, as flags (0: normal, or not reported).

    Each driver documents how its controller's codes map onto these (e.g. UR ``safety_mode``
    3 is ``PROTECTIVE_STOP``, FANUC J519 status bits 0 and 2 cleared is ``NOT_READY``).
    """

    NORMAL = 0
    ESTOP = 1             # emergency stop
    PROTECTIVE_STOP = 2   # protective / safeguard stop
    NOT_READY = 4         # not in the mode that executes streamed commands (servo power off,
    #                       alarm, program not running, stream not accepted)
    COMMAND_REJECTED = 8  # the controller did not take the last command (refused or late)


@dataclass(slots=True, eq=False)
class DriverFeedback:
    """One feedback sample, preallocated and filled in place by :meth:`Driver.read`.

    Attributes:
        t: Sample time on the controller clock [s] (NaN before the first sample).
        q: Encoder joint positions [rad], shape (n,) (NaN before the first sample).
        current: Measured motor currents [A], shape (n,) (NaN before the first sample). A
            controller that reports joint torque instead fills the equivalent motor current
            ``torque / (R·Kt)`` of the robot file (see its driver) and :attr:`torque`.
        sequence: Controller sample counter: +1 per servo period, a jump means missed samples
            (-1 before the first sample).
        state: :class:`ControllerState` flags of the sample (0: normal or not reported).
        inputs: The controller's digital inputs, bit k = input k in the driver's numbering
            (0 when not reported).
        inputs_read: Whether this sample carried the digital inputs.
        torque: Joint torques reported by the controller [N·m], shape (n,), or None when the
            controller reports currents (or the caller did not ask for torque).
    """

    t: float
    q: Array
    current: Array
    sequence: int
    state: int = 0
    inputs: int = 0
    inputs_read: bool = False
    torque: Array | None = None

    @classmethod
    def empty(cls, n: int, torque: bool = False) -> DriverFeedback:
        """A feedback for ``n`` joints that holds no sample yet (NaN, sequence -1); with a
        torque array (NaN) if ``torque``."""
        return cls(t=float("nan"), q=np.full(n, np.nan), current=np.full(n, np.nan),
                   sequence=-1, torque=np.full(n, np.nan) if torque else None)


@dataclass(slots=True, eq=False)
class JointCommand:
    """The command of one servo period for a position-mode servo, written by
    :meth:`Driver.write`.

    Attributes:
        q: Commanded joint positions [rad], shape (n,).
        qd: Commanded joint velocities (velocity feed-forward) [rad/s], shape (n,).
    """

    q: Array
    qd: Array

    @classmethod
    def zeros(cls, n: int) -> JointCommand:
        """A command for ``n`` joints, all zero (fill ``q`` before writing it)."""
        return cls(q=np.zeros(n), qd=np.zeros(n))


@runtime_checkable
class Driver(Protocol):
    """A position-mode robot controller stepped at ``dt`` (see the module doc for the loop)."""

    @property
    def n(self) -> int:
        """Number of joints."""
        ...

    @property
    def dt(self) -> float:
        """Servo period [s]."""
        ...

    @property
    def simulated(self) -> bool:
        """True when :meth:`step` advances a simulation instead of waiting for the robot."""
        ...

    def make_feedback(self) -> DriverFeedback:
        """A feedback to fill with :meth:`read`, shapes (n,), holding no sample yet."""
        ...

    def make_command(self) -> JointCommand:
        """A command to fill and pass to :meth:`write`, shapes (n,)."""
        ...

    def read(self, fb: DriverFeedback) -> bool:
        """Fill ``fb`` with the newest sample if one arrived since the last read.

        Args:
            fb: Preallocated feedback (from :meth:`make_feedback`), filled in place.

        Returns:
            True if a new sample was written into ``fb``; False if none arrived (stale
            feedback, or no sample yet), in which case ``fb`` is left untouched.
        """
        ...

    def write(self, cmd: JointCommand) -> None:
        """Send the joint position [rad] and velocity [rad/s] command for the coming period.

        The robot keeps the last command until the next write. The arrays are copied, so
        ``cmd`` may be refilled at once.

        Args:
            cmd: The command, shapes (n,), finite.
        """
        ...

    def step(self) -> None:
        """Wait for the next servo period: a simulation advances one ``dt`` and returns at
        once; a real controller blocks until its next cycle."""
        ...


class WrappedDriver:
    """A driver that passes everything to the driver it wraps; subclasses override what they
    add to (e.g. :meth:`read`, to record or probe each sample).

    Args:
        driver: The driver doing the work.
    """

    def __init__(self, driver: Driver) -> None:
        self._driver = driver

    @property
    def n(self) -> int:
        """Number of joints."""
        return self._driver.n

    @property
    def dt(self) -> float:
        """Servo period [s]."""
        return self._driver.dt

    @property
    def simulated(self) -> bool:
        """That of the wrapped driver."""
        return self._driver.simulated

    def make_feedback(self) -> DriverFeedback:
        """A feedback of the wrapped driver."""
        return self._driver.make_feedback()

    def make_command(self) -> JointCommand:
        """A command of the wrapped driver."""
        return self._driver.make_command()

    def read(self, fb: DriverFeedback) -> bool:
        """Read from the wrapped driver."""
        return self._driver.read(fb)

    def write(self, cmd: JointCommand) -> None:
        """Write to the wrapped driver."""
        self._driver.write(cmd)

    def step(self) -> None:
        """Step the wrapped driver."""
        self._driver.step()

    def abort(self) -> None:
        """Abort a blocked call of the wrapped driver, if it can (see the module doc)."""
        abort = getattr(self._driver, "abort", None)
        if abort is not None:
            abort()

    @property
    def answer_late_packets(self) -> bool:
        """That of the wrapped driver (False if it has none)."""
        return bool(getattr(self._driver, "answer_late_packets", False))

    @property
    def stop_method(self) -> str:
        """How the wrapped driver's ``close`` ends the stream ("" if it has none)."""
        return str(getattr(self._driver, "stop_method", ""))

    def close(self) -> None:
        """Close the wrapped driver, if it can (see the module doc)."""
        close = getattr(self._driver, "close", None)
        if close is not None:
            close()
