"""A :class:`~leadthrough.drivers.protocol.Driver` on the simulated robot, with fault injection.

:class:`SimDriver` wraps a :class:`~leadthrough.sim.robot.SimRobot`: ``write`` sets its position
and velocity command, ``step`` advances it by one timestep, ``read`` delivers its newest sample.

Faults for safety tests are scheduled with :meth:`SimDriver.inject` on the sample time (the
``t`` of the feedback the fault corrupts), so a test can run an unmodified guiding loop and have
the feedback go bad mid-session:

* ``stale``: the controller stops delivering samples (sequence frozen): ``read`` returns False
  and leaves the feedback untouched; when the fault ends the sequence jumps by the missed count.
* ``nan_q`` / ``nan_current``: the delivered joint positions / currents are NaN.
* ``q_offset``: the delivered joint positions are off by ``offset`` [rad] (an encoder or
  following error: the robot is not where it reports).

The simulation itself is never touched by a fault: it keeps moving under the last command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from leadthrough.drivers.protocol import DriverFeedback, JointCommand
from leadthrough.errors import SimulationError
from leadthrough.sim.robot import SimRobot

__all__ = ["InjectedFault", "InjectedFaultKind", "SimDriver"]


class InjectedFaultKind(StrEnum):
    """Kinds of injected feedback fault (see the module doc)."""

    STALE = "stale"
    NAN_Q = "nan_q"
    NAN_CURRENT = "nan_current"
    Q_OFFSET = "q_offset"


@dataclass(frozen=True)
class InjectedFault:
    """A feedback fault active for samples with ``t_start <= t < t_end``.

    Attributes:
        kind: What goes wrong.
        t_start: First affected sample time [s].
        t_end: End of the fault [s] (inf: until cleared).
        joint: Affected joint index (``nan_q``, ``nan_current``, ``q_offset``); None: all joints.
        offset: Position offset for ``q_offset`` [rad].
    """

    kind: InjectedFaultKind
    t_start: float = 0.0
    t_end: float = math.inf
    joint: int | None = None
    offset: float = 0.0

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "kind", InjectedFaultKind(self.kind))
        except ValueError as e:
            raise SimulationError("unknown fault kind", field="fault.kind", value=self.kind,
                                  expected="one of " + ", ".join(
                                      k.value for k in InjectedFaultKind)) from e
        if not (math.isfinite(self.t_start) and self.t_end > self.t_start):
            raise SimulationError("bad fault window", field="fault.t_start/t_end",
                                  value=(self.t_start, self.t_end),
                                  expected="finite t_start < t_end [s]")
        if not math.isfinite(self.offset):
            raise SimulationError("not finite", field="fault.offset", value=self.offset,
                                  expected="finite offset [rad]")

    def active(self, t: float) -> bool:
        """Whether the fault affects the sample taken at ``t`` [s]."""
        return self.t_start <= t < self.t_end


class SimDriver:
    """Driver on a :class:`~leadthrough.sim.robot.SimRobot` (``simulated`` is True).

    Before the first :meth:`step` there is no sample: :meth:`read` returns False. The robot
    holds the simulator's current command (after ``SimRobot.reset``, the reset pose) until the
    first :meth:`write`.

    Args:
        sim: The simulated robot; the driver steps it, nobody else should.
        sample_jitter_s: Sample-time jitter the driver asks the simulator for: each sample is
            taken up to this long before the instant it is reported for
            (:meth:`~leadthrough.sim.robot.SimRobot.set_sample_jitter`) [s]; 0: none.
    """

    def __init__(self, sim: SimRobot, sample_jitter_s: float = 0.0) -> None:
        self.sim = sim
        if sample_jitter_s:
            sim.set_sample_jitter(sample_jitter_s)
        self._n = sim.robot.n
        self._dt = float(sim.config.timestep)
        self._last_seq = 0
        self._faults: list[InjectedFault] = []

    @property
    def n(self) -> int:
        """Number of joints."""
        return self._n

    @property
    def dt(self) -> float:
        """Servo period [s] (the simulator timestep)."""
        return self._dt

    @property
    def simulated(self) -> bool:
        """Always True: :meth:`step` advances the simulation and returns at once."""
        return True

    @property
    def time(self) -> float:
        """Simulation time [s] (the time of the next sample to be taken)."""
        return self.sim.time

    @property
    def faults(self) -> tuple[InjectedFault, ...]:
        """The injected faults."""
        return tuple(self._faults)

    def make_feedback(self) -> DriverFeedback:
        """A feedback for this robot, holding no sample yet."""
        return DriverFeedback.empty(self._n)

    def make_command(self) -> JointCommand:
        """A zero command for this robot (fill ``q`` before writing it)."""
        return JointCommand.zeros(self._n)

    def inject(self, fault: InjectedFault) -> None:
        """Schedule a feedback fault (see the module doc).

        Args:
            fault: The fault; its joint, if any, must be a joint of this robot.

        Raises:
            SimulationError: The joint index is out of range.
        """
        if fault.joint is not None and not (0 <= fault.joint < self._n):
            raise SimulationError("no such joint", field="fault.joint", value=fault.joint,
                                  expected=f"None or 0..{self._n - 1}")
        self._faults.append(fault)

    def clear_faults(self) -> None:
        """Remove all injected faults."""
        self._faults.clear()

    def read(self, fb: DriverFeedback) -> bool:
        """Fill ``fb`` with the newest sample if one arrived since the last read.

        Args:
            fb: Preallocated feedback, shapes (n,), filled in place.

        Returns:
            True if a new sample was written into ``fb``; False if none arrived (no step since
            the last read, no step yet, or a ``stale`` fault), ``fb`` then untouched.
        """
        sample = self.sim.read()
        if sample.sequence == 0 or sample.sequence == self._last_seq:
            return False
        active = [f for f in self._faults if f.active(sample.t)]
        if any(f.kind is InjectedFaultKind.STALE for f in active):
            return False
        self._last_seq = sample.sequence
        fb.t = sample.t
        fb.sequence = sample.sequence
        fb.q[:] = sample.q
        fb.current[:] = sample.current
        for f in active:
            idx = slice(None) if f.joint is None else f.joint
            if f.kind is InjectedFaultKind.NAN_Q:
                fb.q[idx] = np.nan
            elif f.kind is InjectedFaultKind.NAN_CURRENT:
                fb.current[idx] = np.nan
            elif f.kind is InjectedFaultKind.Q_OFFSET:
                fb.q[idx] += f.offset
        return True

    def write(self, cmd: JointCommand) -> None:
        """Set the simulator's position [rad] and velocity feed-forward [rad/s] command.

        Args:
            cmd: The command, shapes (n,), finite (copied).

        Raises:
            SimulationError: Wrong shapes or non-finite values (nothing is sent).
        """
        n = self._n
        if cmd.q.shape != (n,) or cmd.qd.shape != (n,):
            raise SimulationError("command has the wrong shape", field="cmd.q/cmd.qd",
                                  value=(cmd.q.shape, cmd.qd.shape), expected=f"({n},) each")
        # a sum of squares is NaN or inf iff an entry is (no temporary arrays)
        if not math.isfinite(float(np.dot(cmd.q, cmd.q) + np.dot(cmd.qd, cmd.qd))):
            raise SimulationError("command is not finite", field="cmd.q/cmd.qd",
                                  value=(cmd.q.tolist(), cmd.qd.tolist()),
                                  expected="finite joint positions and velocities")
        self.sim.command(cmd.q, cmd.qd)

    def step(self) -> None:
        """Advance the simulation by one servo period (returns at once)."""
        self.sim.step()
