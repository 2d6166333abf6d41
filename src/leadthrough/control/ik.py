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

The IK keeps its settings, the kinematics of the last q and its work space in one record
(:func:`ik_dtype`); the step itself is compiled (:mod:`leadthrough.control.ik_step`) and the
guiding cycle runs it in its own compiled call. Pinocchio computes the kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.control import ik_step
from leadthrough.errors import ControlError, check_fields, check_period
from leadthrough.robot.description import Robot
from leadthrough.state_records import new_record, view

__all__ = ["DifferentialIK", "IKConfig", "IKResult", "ik_dtype"]

Array = NDArray[np.float64]


@cache
def ik_dtype(n: int) -> np.dtype[Any]:
    """The IK's record for ``n`` joints: settings, the kinematics at the last q, work space."""
    f8 = np.float64
    return np.dtype([
        # settings: per joint the position bounds [rad] (the limits less the margin), speed
        # limits [rad/s], largest velocity change per cycle a·dt [rad/s], 1/(2a) [s²/rad], and
        # the velocity change per cycle a planned stop may take [rad/s]; the cycle [s]; the
        # manipulability μ₀ below which the least squares are damped, and λ_max
        ("lower", f8, (n,)), ("upper", f8, (n,)), ("max_velocity", f8, (n,)),
        ("velocity_step", f8, (n,)), ("half_inverse_acceleration", f8, (n,)),
        ("stop_velocity_step", f8, (n,)), ("dt", f8),
        ("manipulability_threshold", f8), ("max_damping", f8),
        # kinematics at the last q: TCP pose [m], Jacobian in tool axes, J Jᵀ and its Cholesky
        # factor, μ and λ
        ("tcp_rotation", f8, (3, 3)), ("tcp_position", f8, (3,)), ("jacobian", f8, (6, n)),
        ("gram", f8, (6, 6)), ("gram_factor", f8, (6, 6)), ("manipulability", f8),
        ("damping", f8),
        # work space: the factor of J Jᵀ + λ²·1 and the solution, the log6 error [m, rad]
        ("solve_factor", f8, (6, 6)), ("solve_rhs", f8, (6,)), ("error", f8, (6,)),
    ])


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

    Attributes:
        record: The IK's record (:func:`ik_dtype`), read by field by the compiled step.

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
        self.record = new_record(ik_dtype(n))
        s = self._s = view(self.record)
        s.lower, s.upper = lo, hi
        s.max_velocity = robot.velocity_limit * cfg.velocity_scale
        s.velocity_step = amax * dt
        s.half_inverse_acceleration = 0.5 / amax
        s.stop_velocity_step = amax * dt * cfg.stop_acceleration_fraction
        s.dt = dt
        s.manipulability_threshold = cfg.manipulability_threshold
        s.max_damping = cfg.max_damping
        #: TCP pose at the last q: Pinocchio's own frame placement (``data.oMf``), updated in
        #: place by :meth:`compute_kinematics` (copy it to keep a pose).
        self.transform_tool_to_base: pin.SE3 = self._data.oMf[self._fid]

    @property
    def lower(self) -> Array:
        """Joint position bounds of the IK (the robot limits shrunk by the margin) [rad]."""
        return self._s.lower

    @property
    def upper(self) -> Array:
        """Upper joint position bounds of the IK [rad]."""
        return self._s.upper

    @property
    def jacobian(self) -> Array:
        """Frame Jacobian of the TCP in tool axes (``pin.LOCAL``) at the last q, shape (6, n)
        (the record's own array)."""
        return self._s.jacobian

    @property
    def rotation_tool_to_base(self) -> Array:
        """R of the TCP at the last q, shape (3, 3) (the record's own array)."""
        return self._s.tcp_rotation

    @property
    def translation_tool_to_base(self) -> Array:
        """p of the TCP at the last q [m], shape (3,) (the record's own array)."""
        return self._s.tcp_position

    @property
    def manipulability(self) -> float:
        """μ = √det(J Jᵀ) at the last q (of :meth:`compute_kinematics`)."""
        return float(self._s.manipulability)

    @property
    def damping(self) -> float:
        """λ of the damped least squares at the last q (of :meth:`compute_kinematics`)."""
        return float(self._s.damping)

    def stop_cycles(self, qd: Array) -> float:
        """Cycles a planned stop gives the joints to stop from ``qd``.

        Args:
            qd: Joint velocity [rad/s], shape (n,).

        Returns:
            max_j |q̇_j|/(f·a_j·dt) (not rounded), f the ``stop_acceleration_fraction`` and
            a_j the IK's joint acceleration limits.
        """
        return float(ik_step.joint_stop_cycles(qd, self._s.stop_velocity_step))

    def make_result(self) -> IKResult:
        """A preallocated result."""
        return IKResult(qd=np.zeros(self.n), qd_dls=np.zeros(self.n), q=np.zeros(self.n))

    def compute_kinematics(self, q: Array) -> None:
        """Jacobian, TCP pose, manipulability and damping at ``q`` (shape (n,) [rad])."""
        self.frame_kinematics(q)
        ik_step.update_manipulability_of(self.record)

    def frame_kinematics(self, q: Array) -> None:
        """Only the Pinocchio part of :meth:`compute_kinematics`: the TCP pose and Jacobian at
        ``q`` into the record (``manipulability``, ``damping`` and J Jᵀ are left as they were;
        the guiding cycle computes them in its compiled call)."""
        m, d, s = self._model, self._data, self._s
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacement(m, d, self._fid)   # in place: transform_tool_to_base
        s.jacobian = pin.getFrameJacobian(m, d, self._fid, pin.LOCAL)
        T = self.transform_tool_to_base
        s.tcp_rotation = T.rotation
        s.tcp_position = T.translation

    def jacobian_in_frame(self, frame: str, out: Array) -> None:
        """The TCP Jacobian at the last q in the controller's frame.

        Args:
            frame: ``"tool"`` (tool axes, ``pin.LOCAL``) or ``"base"`` (base axes at the TCP,
                ``pin.LOCAL_WORLD_ALIGNED``): blockdiag(R, R)·J_tool with R the TCP rotation.
            out: Result, shape (6, n); Jᵀ·w maps a wrench w in that frame to joint torques.
        """
        jacobian, rotation = self._s.jacobian, self._s.tcp_rotation
        if frame == "tool":
            out[:] = jacobian
            return
        np.matmul(rotation, jacobian[:3], out=out[:3])
        np.matmul(rotation, jacobian[3:], out=out[3:])

    def solve(self, q: Array, qd_previous: Array, target: pin.SE3, out: IKResult) -> None:
        """One DLS step toward ``target`` from ``q`` (after ``compute_kinematics(q)``): the
        compiled :func:`~leadthrough.control.ik_step.ik_step` the guiding cycle runs.

        Args:
            q: Joint position [rad], shape (n,): the one given to ``compute_kinematics``.
            qd_previous: Joint velocity of the last cycle [rad/s], shape (n,).
            target: TCP pose to reach at the end of the cycle.
            out: Result, filled in place.
        """
        scale, out.residual = ik_step.ik_step(self.record[0], target.rotation,
                                              target.translation, q, qd_previous, out.qd_dls,
                                              out.qd, out.q)
        out.scale = scale
        out.limited = scale < 1.0
