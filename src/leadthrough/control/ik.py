"""Differential inverse kinematics: damped least squares with joint limits (Pinocchio).

One call per controller cycle (dt = 10 ms) turns the Cartesian TCP target into a joint velocity:

* error: e = log6(T(q)⁻¹·T_target), the twist in tool axes (``pin.LOCAL``) that moves the
  current TCP onto the target in unit time; ν = e/dt (feed-forward and correction in one);
* damped least squares: q̇ = Jᵀ(J Jᵀ + λ²·1)⁻¹·ν, with J the tool-frame Jacobian and
  λ² = λ_max²·(1 − (μ/μ₀)²) when the manipulability μ = √det(J Jᵀ) is below μ₀ (0 otherwise),
  the damping the estimator uses for its Jᵀ inverse;
* joint acceleration: if a joint's velocity would change by more than its acceleration limit
  times dt, the change is shortened (the same fraction for all joints);
* joint velocity and position: joint j may move toward its limit (shrunk by a margin) at most at
  min(v_max, v_brake(d)), d the distance left and v_brake the largest speed from which the
  discrete stop (speed lowered by a·dt per cycle, a the joint's acceleration limit) ends within
  d (≈ √(2·a·d)), so a joint brakes at its acceleration limit and stops on the margin, never
  beyond; the whole q̇ is scaled by one factor so that the TCP keeps its direction and only
  slows down, except that no joint is slowed by more than its own a·dt in a cycle (a fast joint
  then slows at its limit, and the TCP leaves its line while the bound brakes).

When a bound shortens the step (``IKResult.limited``) the Cartesian target is not reached; the
guiding controller then re-synchronises its target with the reached pose so that the IK never
has to catch up with a large error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.control import joint_kernels
from leadthrough.errors import ControlError, check_fields, check_period
from leadthrough.estimation.kernels import damping_of, gram_manipulability
from leadthrough.robot.description import Robot

__all__ = ["DifferentialIK", "IKConfig", "IKResult", "dls_damping"]

Array = NDArray[np.float64]


#: Damping λ of a damped pseudo-inverse (λ_max·√(1 − (μ/μ₀)²) below μ₀, else 0): the estimator's
#: compiled function, shared so that both use one formula.
dls_damping = damping_of


@dataclass(frozen=True)
class IKConfig:
    """Settings of the differential IK, validated once.

    Attributes:
        manipulability_threshold: μ₀ below which the least squares are damped.
        max_damping: λ_max [m, rad mixed: same units as the twist].
        joint_limit_margin: The IK stops each joint this far inside its position limits [rad].
        velocity_scale: Fraction of the robot's joint speed limits used, in (0, 1].
        acceleration_scale: Fraction of the robot's joint acceleration limits used (braking at
            the position limits, and the per-cycle change of q̇), in (0, 1].
        stop_acceleration_fraction: Fraction of those joint accelerations a planned stop may
            take for slowing the joints down, in (0, 1] (:meth:`DifferentialIK.stop_cycles`).
            The rest is left for the joint accelerations that the straight TCP path needs by
            itself (J̇·q̇, large near a singularity), so that the joints can follow the stop.
    """

    manipulability_threshold: float = 0.02
    max_damping: float = 0.05
    joint_limit_margin: float = 0.01
    velocity_scale: float = 1.0
    acceleration_scale: float = 1.0
    stop_acceleration_fraction: float = 0.5

    def __post_init__(self) -> None:
        check_fields("ik", self, [
            ("manipulability_threshold", self.manipulability_threshold > 0,
             "> 0 (keeps J Jᵀ + λ² invertible)"),
            ("max_damping", self.max_damping > 0, "> 0 (keeps J Jᵀ + λ² invertible)"),
            ("joint_limit_margin", 0 <= self.joint_limit_margin < 0.5, "0 <= margin < 0.5 rad"),
            ("velocity_scale", 0 < self.velocity_scale <= 1, "0 < scale <= 1"),
            ("acceleration_scale", 0 < self.acceleration_scale <= 1, "0 < scale <= 1"),
            ("stop_acceleration_fraction", 0 < self.stop_acceleration_fraction <= 1,
             "0 < fraction <= 1"),
        ], ControlError)


@dataclass
class IKResult:
    """One IK step, preallocated by :meth:`DifferentialIK.make_result` and filled in place.

    Attributes:
        qd: Joint velocity over the cycle [rad/s], shape (n,).
        qd_dls: Joint velocity the DLS step asked for before the joint bounds [rad/s], shape
            (n,): ahead of ``qd`` while the joints' accelerations hold them back.
        q: Joint position at the end of the cycle, q + q̇·dt [rad], shape (n,).
        scale: Fraction of the DLS step kept by the joint bounds (1 = none active).
        limited: Whether a joint bound shortened the step.
        residual: ‖log6(T(q)⁻¹·T_target)‖ before the step [m and rad, mixed].
    """

    qd: Array
    qd_dls: Array
    q: Array
    scale: float = 1.0
    limited: bool = False
    residual: float = 0.0


class DifferentialIK:
    """Damped-least-squares differential IK of the TCP with joint limits.

    Usage, per cycle: ``compute_kinematics(q)`` (Jacobian, TCP pose, μ at q), then read
    ``transform_tool_to_base`` / ``manipulability`` as needed, then ``solve(...)`` at the same q.

    Args:
        robot: The robot (Pinocchio model, TCP frame, joint limits).
        config: Settings.
        dt: Controller cycle [s].

    Raises:
        ControlError: ``dt`` not positive, or the margin leaves no room between the limits.
    """

    def __init__(self, robot: Robot, config: IKConfig | None = None, dt: float = 0.01) -> None:
        self.config = cfg = config if config is not None else IKConfig()
        check_period("dt", dt, ControlError)
        lo = robot.lower_limits + cfg.joint_limit_margin
        hi = robot.upper_limits - cfg.joint_limit_margin
        if not np.all(lo < hi):
            raise ControlError("margin larger than half a joint range",
                               field="ik.joint_limit_margin", value=cfg.joint_limit_margin,
                               expected="less than half of every joint's range")
        self.robot = robot
        self.dt = dt
        self.n = n = robot.n
        self._model = robot.model
        self._data = robot.model.createData()
        self._fid = robot.tcp_frame_id
        amax = robot.acceleration_limit * cfg.acceleration_scale
        #: All arrays of the IK, one buffer (``joint_kernels.ik_views``); the arrays below are
        #: its views.
        self.buffer = np.zeros(joint_kernels.ik_size(n))
        self.gram, self.scratch, self._err, self.jacobian, self.table = (
            joint_kernels.ik_views(self.buffer, n))
        #: Per-joint table, shape (``joint_kernels.IK_ROWS``, n): the bounds, speed limits,
        #: a·dt, 1/(2a) and the planned stop's a·dt (``joint_kernels.IK_*`` rows).
        self.table[:] = [lo, hi, robot.velocity_limit * cfg.velocity_scale, amax * dt,
                         0.5 / amax, amax * dt * cfg.stop_acceleration_fraction]
        #: Joint position bounds of the IK (the robot limits shrunk by the margin) [rad].
        self.lower = self.table[joint_kernels.IK_LOWER]
        self.upper = self.table[joint_kernels.IK_UPPER]
        #: Frame Jacobian of the TCP in tool axes (``pin.LOCAL``), shape (6, n), at the last q
        #: (a view of ``buffer``), with J Jᵀ and its Cholesky factor (``gram``, shape (2, 6, 6))
        #: and the least squares' work space (``scratch``, shape (7, 6)).
        #: TCP pose at the last q: Pinocchio's own frame placement (``data.oMf``), updated in
        #: place by :meth:`compute_kinematics` (copy it to keep a pose).
        self.transform_tool_to_base: pin.SE3 = self._data.oMf[self._fid]
        #: Views of its rotation, shape (3, 3), and translation [m], shape (3,): they follow it.
        self.rotation_tool_to_base: Array = self.transform_tool_to_base.rotation
        self.translation_tool_to_base: Array = self.transform_tool_to_base.translation
        #: μ = √det(J Jᵀ) at the last q.
        self.manipulability = 0.0
        #: λ of the damped least squares at the last q.
        self.damping = 0.0

    def stop_cycles(self, qd: Array) -> float:
        """Cycles a planned stop gives the joints to stop from ``qd``.

        Args:
            qd: Joint velocity [rad/s], shape (n,).

        Returns:
            max_j |q̇_j|/(f·a_j·dt) (not rounded), f the ``stop_acceleration_fraction`` and
            a_j the IK's joint acceleration limits.
        """
        return float(joint_kernels.joint_stop_cycles(qd, self.table[joint_kernels.IK_DV_STOP]))

    def make_result(self) -> IKResult:
        """A preallocated result."""
        return IKResult(qd=np.zeros(self.n), qd_dls=np.zeros(self.n), q=np.zeros(self.n))

    def compute_kinematics(self, q: Array) -> None:
        """Jacobian, TCP pose, manipulability and damping at ``q`` (shape (n,) [rad])."""
        self.frame_kinematics(q)
        self.manipulability = gram_manipulability(self.jacobian, self.gram[0], self.gram[1])
        self.damping = dls_damping(self.manipulability, self.config.manipulability_threshold,
                                   self.config.max_damping)

    def frame_kinematics(self, q: Array) -> None:
        """Only the Pinocchio part of :meth:`compute_kinematics`: the TCP pose and Jacobian at
        ``q`` (``manipulability``, ``damping`` and ``gram`` are left as they were; the guiding
        cycle computes them in its compiled call)."""
        m, d = self._model, self._data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacement(m, d, self._fid)   # in place: transform_tool_to_base
        self.jacobian[:] = pin.getFrameJacobian(m, d, self._fid, pin.LOCAL)

    def jacobian_in_frame(self, frame: str, out: Array) -> None:
        """The TCP Jacobian at the last q in the controller's frame.

        Args:
            frame: ``"tool"`` (tool axes, ``pin.LOCAL``) or ``"base"`` (base axes at the TCP,
                ``pin.LOCAL_WORLD_ALIGNED``): blockdiag(R, R)·J_tool with R the TCP rotation.
            out: Result, shape (6, n); Jᵀ·w maps a wrench w in that frame to joint torques.
        """
        if frame == "tool":
            out[:] = self.jacobian
            return
        R = self.rotation_tool_to_base
        np.matmul(R, self.jacobian[:3], out=out[:3])
        np.matmul(R, self.jacobian[3:], out=out[3:])

    def solve(self, q: Array, qd_previous: Array, target: pin.SE3, out: IKResult) -> None:
        """One DLS step toward ``target`` from ``q`` (after ``compute_kinematics(q)``).

        Args:
            q: Joint position [rad], shape (n,): the one given to ``compute_kinematics``.
            qd_previous: Joint velocity of the last cycle [rad/s], shape (n,).
            target: TCP pose to reach at the end of the cycle.
            out: Result, filled in place.
        """
        scale, out.residual = joint_kernels.ik_step(
            self.jacobian, self.gram, self.table, self.scratch, self._err, self.damping,
            self.dt, self.rotation_tool_to_base, self.translation_tool_to_base,
            target.rotation, target.translation, q, qd_previous, out.qd_dls, out.qd, out.q)
        out.scale = scale
        out.limited = scale < 1.0
