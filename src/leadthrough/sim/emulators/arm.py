"""The arm behind an emulated controller: the simulated robot stepped at 1 ms under cycle
targets, with the controller's own checks, stops and command log.

Every controller cycle (8/4 ms J519, 2/8 ms RTDE, 4 ms RSI) the protocol layer hands
:meth:`EmulatedArm.command` a joint target (or :meth:`EmulatedArm.hold` when none came); the
arm checks it against the controller's limits, then interpolates to it over the next cycle,
feeding the simulator position and velocity every millisecond. The interpolation is a cubic
Hermite segment from where the arm is, with the velocity it has, to the target, arriving with the
cycle's mean velocity: position and velocity are continuous from one cycle to the next, so the
acceleration spreads over the cycle as a real controller's interpolator spreads it. (A linear
segment with the cycle's mean velocity as feed-forward steps the velocity at every cycle start:
the servo then delivers each cycle's acceleration as a torque spike in the first milliseconds,
and a controller sampling the currents once per cycle, in phase with those spikes, reports
currents without most of the inertial torque: an 8 ms J519 recording identified 12 % held-out
torque error against 5 % at 1 kHz.) A target that fails a
check is refused and starts a controlled stop (each joint decelerates at the robot's
acceleration limit; an E-stop at twice that), after which the arm is in ``FAULT`` until
:meth:`EmulatedArm.reset`. Every command is counted, the refusals for a limit are kept
(:class:`CommandRecord`, the first 1000), and an audit re-checks each target the arm executes
against the one before, independently of the checks that accepted it:
:meth:`EmulatedArm.violations` lets a test confirm that no non-finite target and no jump beyond
the limits was ever executed. Nothing is kept per accepted command: an hour at 4 ms is 900 000
commands, and kept as Python objects (even only the last 10 000) the garbage collector's passes
over them stalled the 1 ms loop by 5 to 80 ms.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.robot.description import Robot
from leadthrough.sim.emulators.operator import EmulatedOperator
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.sensors import Feedback

__all__ = ["ArmPhase", "CommandRecord", "EmulatedArm", "MotionLimits", "StopKind"]

Array = NDArray[np.float64]

#: Violations and limit refusals kept (each also counted).
_KEEP_FEW = 1_000


class ArmPhase(StrEnum):
    """What the arm is doing."""

    IDLE = "idle"          # holding, no stream
    RUNNING = "running"    # following cycle targets
    STOPPING = "stopping"  # controlled stop in progress
    FAULT = "fault"        # stopped after a fault; reset needed


class StopKind(StrEnum):
    """Why the arm stopped."""

    REQUEST = "request"        # the client ended the motion (not a fault)
    WATCHDOG = "watchdog"      # commands stopped coming
    LIMIT = "limit"            # a command beyond the limits or not finite
    ESTOP = "estop"            # emergency stop
    PROTECTIVE = "protective"  # protective stop


@dataclass(frozen=True)
class MotionLimits:
    """Limits a controller enforces on consecutive cycle targets (None: not checked).

    Attributes:
        velocity: [rad/s], shape (n,).
        acceleration: [rad/s²], shape (n,).
        jerk: [rad/s³], shape (n,).
        tolerance: Relative slack on every limit (rounding of degrees, float32).
    """

    velocity: Array | None
    acceleration: Array | None = None
    jerk: Array | None = None
    tolerance: float = 1e-3

    @classmethod
    def of(cls, robot: Robot, *, acceleration: bool, jerk_per_accel: float | None) -> MotionLimits:
        """The drive file's limits; jerk = ``jerk_per_accel`` × acceleration [1/s] if given."""
        acc = robot.acceleration_limit.copy()
        return cls(velocity=robot.velocity_limit.copy(), acceleration=acc if acceleration else None,
                   jerk=acc * jerk_per_accel if jerk_per_accel is not None else None)


@dataclass(frozen=True)
class CommandRecord:
    """One command the controller received.

    Attributes:
        t: Simulation time at reception [s].
        q: Target [rad] as received (may be non-finite).
        accepted: Whether the arm executed it.
        reason: Why it was refused ("" when accepted).
    """

    t: float
    q: tuple[float, ...]
    accepted: bool
    reason: str


class EmulatedArm:
    """A :class:`~leadthrough.sim.robot.SimRobot` driven by cycle targets.

    Args:
        robot: Robot description.
        seed: Simulator seed.
        cycle: Controller cycle [s] (a whole number of 1 ms steps).
        limits: What :meth:`command` checks besides finiteness and the position limits.
        q0: Start pose [rad] (default: the robot's neutral pose).
    """

    def __init__(self, robot: Robot, seed: int, cycle: float, limits: MotionLimits,
                 q0: Array | None = None, operator: EmulatedOperator | None = None) -> None:
        self.robot = robot
        self.operator = operator
        self.sim = SimRobot(robot, SimConfig(seed=seed), q0=q0, operator=operator)
        self.dt = float(self.sim.config.timestep)
        self.steps = max(1, round(cycle / self.dt))
        self.cycle = self.steps * self.dt
        self.limits = limits
        q = self.sim.q_command
        self._from, self._to = q.copy(), q.copy()
        self._v = np.zeros(robot.n)      # target velocity of the current cycle
        self._a = np.zeros(robot.n)      # its change over the last cycle
        self._k = 0
        self._q, self._qd = q.copy(), np.zeros(robot.n)
        self._v_from = np.zeros(robot.n)  # velocity at the start of the cycle's segment
        self.phase = ArmPhase.IDLE
        self.stop_kind: StopKind | None = None
        self.stop_reason = ""
        self._decel = robot.acceleration_limit.copy()
        self.refusals: list[CommandRecord] = []  # refused for what they asked (first ones)
        self.commands = self.accepted = 0
        self._violations: list[str] = []
        self._violation_count = 0
        self._executed_count = 0
        self._last_executed: Array | None = None  # the audit's previous cycle target
        self._pin = robot.model.createData()

    # ---------------------------------------------------------------------------- commands
    @property
    def target(self) -> Array:
        """The latest accepted cycle target [rad] (copy)."""
        return self._to.copy()

    @property
    def target_velocity(self) -> Array:
        """Velocity of the current cycle's interpolation [rad/s] (copy)."""
        return self._v.copy()

    @property
    def moving(self) -> bool:
        """Whether the commanded motion is not at rest."""
        return bool(np.any(np.abs(self._qd) > 1e-6))

    def check(self, q: Array) -> str:
        """Why the controller would refuse target ``q`` now ("" if it would accept it)."""
        if q.shape != (self.robot.n,) or not np.all(np.isfinite(q)):
            return "target not finite"
        r = self.robot
        if np.any(q < r.lower_limits) or np.any(q > r.upper_limits):
            return "target outside the joint position limits"
        lim, T = self.limits, self.cycle
        v = (q - self._to) / T
        a = (v - self._v) / T
        for name, value, bound in (("velocity", v, lim.velocity),
                                   ("acceleration", a, lim.acceleration),
                                   ("jerk", (a - self._a) / T, lim.jerk)):
            if bound is not None and np.any(np.abs(value) > bound * (1 + lim.tolerance)):
                j = int(np.argmax(np.abs(value) / bound))
                return (f"joint {j + 1} {name} {abs(value[j]):.4g} beyond the limit "
                        f"{bound[j]:.4g}")
        return ""

    def command(self, q: Array, t: float, refusal: StopKind = StopKind.LIMIT) -> bool:
        """Take the target of the coming cycle (a refused one starts a stop).

        Args:
            q: Target [rad], shape (n,).
            t: Reception time [s], for the log.
            refusal: Kind of the stop a refused target starts (a UR controller makes a
                protective stop, a FANUC or KUKA one stops on a limit alarm).

        Returns:
            Whether the target was accepted.
        """
        q = np.asarray(q, dtype=float)
        if self.phase in (ArmPhase.STOPPING, ArmPhase.FAULT):
            self._count(t, q, f"arm {self.phase}")
            return False
        reason = self.check(q)
        self._count(t, q, reason)
        if reason:
            self.stop(refusal, reason)
            return False
        if not np.all(np.isfinite(q)):
            self._violation(f"accepted non-finite command at t={t:.3f}")
        self._advance(q)
        self.phase = ArmPhase.RUNNING
        if self.operator is not None:
            self.operator.stream_started(self.sim.time)
        return True

    def refuse(self, q: tuple[float, ...], t: float, reason: str) -> None:
        """Log a command the protocol layer refused and start a limit stop."""
        self._count(t, np.asarray(q, dtype=float), reason)
        self.stop(StopKind.LIMIT, reason)

    def _count(self, t: float, q: Array, reason: str) -> None:
        """Count a command (``reason`` "": accepted); keep a refusal for a limit."""
        self.commands += 1
        if not reason:
            self.accepted += 1
        elif not reason.startswith("arm ") and len(self.refusals) < _KEEP_FEW:
            self.refusals.append(CommandRecord(t, tuple(q.tolist()), False, reason))

    def hold(self, extrapolate: bool = False) -> None:
        """No target this cycle: keep the last one, or continue at the last velocity (the
        controller's own motion: only the position limits apply, its zero acceleration is
        what the next target's checks start from)."""
        if self.phase is ArmPhase.RUNNING:
            q = self._to + self._v * self.cycle if extrapolate else self._to.copy()
            if np.any(q < self.robot.lower_limits) or np.any(q > self.robot.upper_limits):
                q = self._to.copy()
            self._advance(q)

    def _advance(self, q: Array) -> None:
        self._audit(q)
        v = (q - self._to) / self.cycle
        self._a = (v - self._v) / self.cycle
        self._v = v
        self._v_from = self._qd.copy()  # the velocity the arm has: continuous across cycles
        self._from, self._to = self._q.copy(), q.copy()
        self._k = 0

    def stop(self, kind: StopKind, reason: str) -> None:
        """Start a controlled stop (an E-stop decelerates twice as hard)."""
        if self.phase in (ArmPhase.STOPPING, ArmPhase.FAULT):
            return
        self.phase, self.stop_kind, self.stop_reason = ArmPhase.STOPPING, kind, reason
        scale = 2.0 if kind is StopKind.ESTOP else 1.0
        self._decel = self.robot.acceleration_limit * scale

    def reset(self) -> None:
        """Clear a fault: hold where the arm is (IDLE)."""
        self.phase, self.stop_kind, self.stop_reason = ArmPhase.IDLE, None, ""
        self._to, self._v, self._a = self._q.copy(), np.zeros(self.robot.n), np.zeros(
            self.robot.n)
        self._audit(self._q)

    # ------------------------------------------------------------------------------ steps
    def step(self) -> None:
        """Advance 1 ms: interpolate (or decelerate) the command, step the simulator."""
        if self.phase is ArmPhase.RUNNING:
            if self._k >= self.steps:  # no target for this cycle: rest at the last one
                self._qd[:] = 0.0
            else:
                self._k += 1
                self._hermite(self._k / self.steps)
        elif self.phase is ArmPhase.STOPPING:
            speed = np.maximum(np.abs(self._qd) - self._decel * self.dt, 0.0)
            self._qd[:] = np.sign(self._qd) * speed
            self._q += self._qd * self.dt
            if not self._qd.any():
                self.phase = (ArmPhase.IDLE if self.stop_kind is StopKind.REQUEST
                              else ArmPhase.FAULT)
                self._to, self._v = self._q.copy(), np.zeros(self.robot.n)
        if self.operator is not None and self.operator.due(self.sim.time):
            self.operator.start(self.sim.time, self.tcp_position(self._q))
        self.sim.command(self._q, self._qd)
        self.sim.step()

    def _hermite(self, u: float) -> None:
        """Position and velocity at fraction ``u`` of the cycle's segment (see the module doc):
        from (``_from``, ``_v_from``) to (``_to``, ``_v``) over one cycle."""
        T = self.cycle
        h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
        h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
        d00, d10 = (6 * u**2 - 6 * u) / T, 3 * u**2 - 4 * u + 1
        d01, d11 = (-6 * u**2 + 6 * u) / T, 3 * u**2 - 2 * u
        self._q[:] = h00 * self._from + h10 * T * self._v_from + h01 * self._to + h11 * T * self._v
        self._qd[:] = d00 * self._from + d10 * self._v_from + d01 * self._to + d11 * self._v

    def sample(self) -> Feedback:
        """The newest sample (time, encoder positions, measured currents, sequence)."""
        return self.sim.read()

    def tcp_position(self, q: Array) -> Array:
        """TCP position at ``q`` [m], base frame, shape (3,)."""
        pin.framesForwardKinematics(self.robot.model, self._pin, q)
        return np.array(self._pin.oMf[self.robot.tcp_frame_id].translation)

    def tcp_pose(self, q: Array) -> tuple[float, ...]:
        """TCP pose at ``q``: X Y Z [mm] and fixed-axis X-Y-Z angles (roll, pitch, yaw) [deg].

        KUKA's A B C are (yaw, pitch, roll) and FANUC's W P R are (roll, pitch, yaw).
        """
        model, data = self.robot.model, self._pin
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[self.robot.tcp_frame_id]
        rpy = pin.rpy.matrixToRpy(M.rotation)
        return tuple((M.translation * 1000.0).tolist()) + tuple(np.degrees(rpy).tolist())

    # ------------------------------------------------------------------------------ audit
    def _audit(self, q: Array) -> None:
        """Re-check a cycle target the arm is about to follow against the one before: not
        finite, outside the position limits, or a step faster than the velocity limit."""
        k = self._executed_count
        self._executed_count += 1
        lo, hi, vmax = self.robot.lower_limits, self.robot.upper_limits, self.limits.velocity
        prev = self._last_executed
        if not np.all(np.isfinite(q)) or np.any(q < lo) or np.any(q > hi):
            self._violation(f"cycle target {k} not finite or outside the position limits")
        elif prev is not None and vmax is not None and np.any(
                np.abs(q - prev) > vmax * (1 + self.limits.tolerance) * self.cycle):
            self._violation(f"cycle target {k} steps faster than the velocity limit")
        if self._last_executed is None:
            self._last_executed = q.copy()
        else:
            self._last_executed[:] = q

    def _violation(self, text: str) -> None:
        self._violation_count += 1
        if len(self._violations) < _KEEP_FEW:
            self._violations.append(text)

    def violations(self) -> list[str]:
        """What the arm executed that it should not have (should always be empty): an accepted
        non-finite command, a cycle target not finite or outside the joint limits, or a step
        between consecutive targets faster than the velocity limit (the first
        1000, and a count of the others).

        Returns:
            One description per violation.
        """
        out = list(self._violations)
        if self._violation_count > len(out):
            out.append(f"... and {self._violation_count - len(out)} more")
        return out
