"""The arm behind an emulated controller: the simulated robot stepped at 1 ms under cycle
targets, with the controller's own checks, stops and command log.

Every controller cycle (8/4 ms J519, 2/8 ms RTDE, 4 ms RSI) the protocol layer hands
:meth:`EmulatedArm.command` a joint target (or :meth:`EmulatedArm.hold` when none came); the
arm checks it against the controller's limits, then interpolates linearly to it over the next
cycle, feeding the simulator position and velocity every millisecond. A target that fails a
check is refused and starts a controlled stop (each joint decelerates at the robot's
acceleration limit; an E-stop at twice that), after which the arm is in ``FAULT`` until
:meth:`EmulatedArm.reset`. Every command is logged (:class:`CommandRecord`) and
:meth:`EmulatedArm.violations` re-checks the accepted ones, so a test can confirm that no
non-finite target and no jump beyond the limits was ever executed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.robot.description import Robot
from leadthrough.sim.robot import Feedback, SimConfig, SimRobot

__all__ = ["ArmPhase", "CommandRecord", "EmulatedArm", "MotionLimits", "StopKind"]

Array = NDArray[np.float64]


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
                 q0: Array | None = None) -> None:
        self.robot = robot
        self.sim = SimRobot(robot, SimConfig(seed=seed), q0=q0)
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
        self.phase = ArmPhase.IDLE
        self.stop_kind: StopKind | None = None
        self.stop_reason = ""
        self._decel = robot.acceleration_limit.copy()
        self.log: list[CommandRecord] = []
        self.executed: list[Array] = []  # every cycle target the arm followed
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
            self.log.append(CommandRecord(t, tuple(q.tolist()), False, f"arm {self.phase}"))
            return False
        reason = self.check(q)
        self.log.append(CommandRecord(t, tuple(q.tolist()), not reason, reason))
        if reason:
            self.stop(refusal, reason)
            return False
        self._advance(q)
        self.phase = ArmPhase.RUNNING
        return True

    def refuse(self, q: tuple[float, ...], t: float, reason: str) -> None:
        """Log a command the protocol layer refused and start a limit stop."""
        self.log.append(CommandRecord(t, tuple(float(x) for x in q), False, reason))
        self.stop(StopKind.LIMIT, reason)

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
        self.executed.append(q.copy())
        v = (q - self._to) / self.cycle
        self._a = (v - self._v) / self.cycle
        self._v = v
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
        self.executed.append(self._q.copy())

    # ------------------------------------------------------------------------------ steps
    def step(self) -> None:
        """Advance 1 ms: interpolate (or decelerate) the command, step the simulator."""
        if self.phase is ArmPhase.RUNNING:
            if self._k >= self.steps:  # no target for this cycle: rest at the last one
                self._qd[:] = 0.0
            else:
                self._k += 1
                self._q[:] = self._from + (self._to - self._from) * (self._k / self.steps)
                self._qd[:] = self._v  # velocity feed-forward of the cycle
        elif self.phase is ArmPhase.STOPPING:
            speed = np.maximum(np.abs(self._qd) - self._decel * self.dt, 0.0)
            self._qd[:] = np.sign(self._qd) * speed
            self._q += self._qd * self.dt
            if not self._qd.any():
                self.phase = (ArmPhase.IDLE if self.stop_kind is StopKind.REQUEST
                              else ArmPhase.FAULT)
                self._to, self._v = self._q.copy(), np.zeros(self.robot.n)
        self.sim.command(self._q, self._qd)
        self.sim.step()

    def sample(self) -> Feedback:
        """The newest sample (time, encoder positions, measured currents, sequence)."""
        return self.sim.read()

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
    def violations(self) -> list[str]:
        """What the arm executed that it should not have (should always be empty).

        Replays every accepted command of the log and every cycle target the arm followed:
        a non-finite value, a position outside the joint limits, or a step between
        consecutive targets faster than the velocity limit.

        Returns:
            One description per violation.
        """
        out = [f"accepted non-finite command at t={r.t:.3f}" for r in self.log
               if r.accepted and not all(math.isfinite(x) for x in r.q)]
        lo, hi, vmax = self.robot.lower_limits, self.robot.upper_limits, self.limits.velocity
        prev = None
        for k, q in enumerate(self.executed):
            if not np.all(np.isfinite(q)) or np.any(q < lo) or np.any(q > hi):
                out.append(f"cycle target {k} not finite or outside the position limits")
            elif prev is not None and vmax is not None and np.any(
                    np.abs(q - prev) > vmax * (1 + self.limits.tolerance) * self.cycle):
                out.append(f"cycle target {k} steps faster than the velocity limit")
            prev = q
        return out
