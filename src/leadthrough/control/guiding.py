"""The guiding controller: force in, joint position commands out, every 10 ms (ruckig style).

    ctl = GuidingController(robot, GuidingConfig())
    inp, out = ctl.make_input(), ctl.make_output()
    interp = HermiteInterpolator(robot.n, ctl.config.dt)        # 10 ms → 1 ms
    ctl.reset(q0); interp.reset(q0)
    every 10 ms:
        inp.t, inp.sequence, inp.deadman = ...
        inp.q[:], inp.current[:], inp.wrench_base[:] = ...     # measured q, i; estimated wrench
        status = ctl.update(inp, out)                           # out.q, out.qd: the setpoint
        interp.set_target(out.q, out.qd)
        every 1 ms: interp.update(cmd); send cmd.q, cmd.qd to the position-mode servo

One cycle:

1. safety checks of the feedback (:mod:`leadthrough.control.safety`), kinematics at the
   commanded joint position (Pinocchio), motion checks (singularity, joint limit, IK residual),
   deadman transitions;
2. GUIDING: the estimated wrench, rotated into the controller's frame (``"base"``: base axes at
   the TCP; ``"tool"``: tool axes) and masked by ``axes_enabled``, drives the law, virtual
   friction (eq. 31–33, :mod:`~leadthrough.control.virtual_friction`) or the velocity baseline
   [14] (:mod:`~leadthrough.control.velocity_baseline`), with fixed friction or eq. 36
   (:mod:`~leadthrough.control.auto_friction`). At rest, for ``settle_s + rezero_s`` after a
   stop or after a release (the force on an axis falling back from its peak by
   :data:`RELEASE_DROP` × δ or more within about :data:`RELEASE_WINDOW_S`: the peak forgets
   slow drifts), breaking away takes the stopping friction: the paper's
   "larger friction once the force is removed", applied while the drives settle or unload.
   Then the speed and acceleration limits
   (:mod:`~leadthrough.control.limits`, speed scaled down near singularities). STOPPING and
   FAULT: decelerate to zero at the acceleration limit, or slower if the joints need longer to
   stop (near a singularity; :meth:`~leadthrough.control.ik.DifferentialIK.stop_cycles`), so
   that the joints can follow the stop; IDLE: at rest;
3. the twist is integrated into the commanded TCP pose (tool frame: T·exp6(ν·dt); base frame:
   p + v·dt, exp3(ω·dt)·R); if the TCP could not stop inside the workspace box (less a 1 mm
   margin for the IK's residual) from there, over the longer of the Cartesian and the joints'
   stop, WORKSPACE fault and a stop instead;
4. differential IK (:mod:`~leadthrough.control.ik`) to the joint setpoint. A twist of exactly
   zero, once every joint is slow enough to halt within its acceleration limit, skips the IK:
   the joint setpoint is held bit for bit and q̇ = 0.0 exactly (until then the IK tracks the
   held pose and brakes the joints). While the setpoint and the commanded pose are unchanged,
   the cycle reuses their kinematics (FK, Jacobian, μ) and IK residual instead of recomputing
   the same numbers (a cycle at rest: 14 instead of 22 µs, ``benchmarks/guiding.py``).

``update`` never raises, never reads the clock, and allocates no arrays of its own (Pinocchio and
``numpy.linalg`` allocate their results; a state transition appends one event to the log).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.control import guiding_kernel as gk
from leadthrough.control import kernels
from leadthrough.control.admittance import AdmittanceLaw
from leadthrough.control.auto_friction import AutoFriction
from leadthrough.control.guiding_types import (
    CONTROLLERS,
    GuidingConfig,
    GuidingInput,
    GuidingOutput,
    Status,
)
from leadthrough.control.ik import DifferentialIK
from leadthrough.control.limits import TwistLimiter
from leadthrough.control.safety import Event, Fault, SafetySupervisor, State
from leadthrough.control.velocity_baseline import VelocityBaseline
from leadthrough.control.virtual_friction import VirtualFriction
from leadthrough.errors import ControlError
from leadthrough.robot.description import Robot

__all__ = [
    "CONTROLLERS",
    "GuidingConfig",
    "GuidingController",
    "GuidingInput",
    "GuidingOutput",
    "Status",
]

Array = NDArray[np.float64]

#: A release at rest: the (smoothed) force on an axis falls back from its peak by this fraction
#: of that axis's friction δ or more.
RELEASE_DROP = 0.5
#: Time constant of the first-order smoothing of the force for the release [s] (estimator noise
#: below δ must not look like a release).
RELEASE_SMOOTHING_S = 0.05
#: Time constant with which the release's peak forgets slow changes [s]: letting go drops the
#: estimate within ~0.2 s (the estimator's 3 Hz filter), while under a steady hand at rest the
#: estimate drifts by up to ~10 N/s as the drives' static friction takes up or gives back
#: load; such a drift must not renew the stopping friction again and again.
RELEASE_WINDOW_S = 0.3


class GuidingController:
    """Hand-guiding controller: law + limits + safety + differential IK, one call per cycle.

    Args:
        robot: The robot.
        config: Settings.
        noise_mean: Identified τ̄_ω per joint [N·m], shape (n,); required for
            ``friction_mode="auto"``.
        noise_std: Identified σ of τ_ω per joint [N·m], shape (n,); required for the auto
            friction's ``"std"`` and ``"mean+std"`` bases.

    Raises:
        ControlError: Invalid settings or noise vectors.
    """

    def __init__(self, robot: Robot, config: GuidingConfig | None = None,
                 noise_mean: Array | None = None, noise_std: Array | None = None) -> None:
        self.config = cfg = config if config is not None else GuidingConfig()
        self.robot = robot
        self.n = n = robot.n
        self._law: AdmittanceLaw = (
            VirtualFriction(cfg.virtual_friction, cfg.dt) if cfg.controller == "virtual-friction"
            else VelocityBaseline(cfg.velocity_baseline, cfg.dt))
        self._auto: AutoFriction | None = None
        if cfg.friction_mode == "auto":
            if noise_mean is None:
                raise ControlError("needed for automatic friction", field="noise_mean",
                                   expected="τ̄_ω per joint (params file [noise] mean)")
            self._auto = AutoFriction(noise_mean, noise_std, cfg.auto_friction)
            if self._auto.n != n:
                raise ControlError("wrong size", field="noise_mean", value=self._auto.n,
                                   expected=f"{n} values")
        self._limiter = TwistLimiter(cfg.limits, cfg.dt)
        self._ik = DifferentialIK(robot, cfg.ik, cfg.dt)
        self._ik_result = self._ik.make_result()
        self._safety = SafetySupervisor(robot, cfg.safety, cfg.limits)
        self._tool = cfg.frame == "tool"
        self._mask = np.array([1.0 if a else 0.0 for a in cfg.axes_enabled])
        # the per-axis state, one row per vector (guiding_kernel's layout); the names are views
        self._axes = axes = np.zeros((gk.AXES_ROWS, 6))
        self._twist = axes[gk.TWIST]
        self._twist_des = axes[gk.DESIRED]
        self._twist_new = axes[gk.NEW]
        self._wrench = axes[gk.WRENCH]
        self._friction = axes[gk.FRICTION]
        self._stop_friction = axes[gk.STOP_FRICTION]
        self._smooth = axes[gk.SMOOTH]  # the wrench smoothed for the release
        self._peak = axes[gk.PEAK]      # signed peak force per axis at rest since the release
        self._friction[:] = cfg.virtual_friction.friction
        self._stop_friction[:] = cfg.virtual_friction.stopping_friction
        axes[gk.LAW] = self._law.coefficients
        self._vdt = np.zeros(6)
        self._Jc = np.zeros((6, n))
        self._q_cmd = np.zeros(n)
        self._qd_cmd = np.zeros(n)
        self._measured_q = np.full(n, math.nan)   # the last finite q before the first reset
        # the commanded TCP pose and the next cycle's, two poses swapped when the step is taken;
        # the kernels write them through views of their rotation and translation (no SE3 is
        # built in the cycle)
        self._T_cmd = pin.SE3.Identity()
        self._R_cmd, self._p_cmd = self._T_cmd.rotation, self._T_cmd.translation
        self._T_new = pin.SE3.Identity()
        self._R_new, self._p_new = self._T_new.rotation, self._T_new.translation
        self._resync = False
        # the kinematics (FK, Jacobian, μ) of the IK are those of _q_cmd, and _residual is the
        # IK residual of _T_cmd from there: at rest neither changes, and the cycle reuses them
        self._kinematics_fresh = False
        self._residual_fresh = False
        self._residual = 0.0
        self._started = False
        self._rest_s = math.inf
        self._release_s = math.inf  # time since the force was removed at rest [s]
        # cycles of the stop the last workspace check planned (inf: no box, no plan)
        self._stop_plan = math.inf
        self._hold_s = cfg.settle_s + cfg.rezero_s
        # guiding_step's settings: hold, dt, release drop, smoothing weight, forgetting factor
        self._step_settings = np.array([self._hold_s, cfg.dt, RELEASE_DROP,
                                        cfg.dt / (RELEASE_SMOOTHING_S + cfg.dt),
                                        math.exp(-cfg.dt / RELEASE_WINDOW_S)])

    # ----------------------------------------------------------------- set-up
    def make_input(self) -> GuidingInput:
        """A preallocated input."""
        n = self.n
        return GuidingInput(t=0.0, sequence=0, q=np.zeros(n), current=np.zeros(n),
                            wrench_base=np.zeros(6))

    def make_output(self) -> GuidingOutput:
        """A preallocated output."""
        n = self.n
        return GuidingOutput(q=np.zeros(n), qd=np.zeros(n), transform_tool_to_base=np.eye(4),
                             twist_base=np.zeros(6), twist_tool=np.zeros(6),
                             wrench=np.zeros(6), friction=self._friction.copy(),
                             stopping_friction=self._stop_friction.copy())

    def reset(self, q: Array, t: float = 0.0) -> None:
        """(Re)start at rest at joint position ``q``, IDLE, any fault cleared.

        Pass the last commanded position (``out.q``) to continue without a position step, or
        the measured one when the robot is away from the command (e.g. after a following-error
        fault). The commanded velocity restarts from zero: reset a robot at rest (a moving
        one would be stopped within one cycle, beyond its acceleration limits).

        Args:
            q: Joint position [rad], shape (n,), within the joint limits.
            t: Time of the reset [s] (logged).

        Raises:
            ControlError: ``q`` of the wrong shape, not finite, outside the joint limits, or the
                TCP outside the workspace box (less its margin).
        """
        q = np.asarray(q, dtype=float)
        r = self.robot
        if q.shape != (self.n,) or not np.isfinite(q).all():
            raise ControlError("wrong size or not finite", field="q", value=q.tolist(),
                               expected=f"{self.n} finite joint positions [rad]")
        if np.any(q < r.lower_limits) or np.any(q > r.upper_limits):
            raise ControlError("outside the joint limits", field="q", value=q.tolist(),
                               expected=f"within {r.lower_limits.tolist()} .. "
                                        f"{r.upper_limits.tolist()} rad")
        # the IK's kinematics are those of q from here, not of the setpoint (if refused below)
        self._kinematics_fresh = False
        self._ik.compute_kinematics(q)
        p = self._ik.transform_tool_to_base.translation
        if self._safety.workspace_clearance(p, 0.0) < 0.0:
            sc = self.config.safety
            raise ControlError("TCP outside the workspace box", field="q", value=p.tolist(),
                               expected=f"TCP within {sc.workspace_min} .. {sc.workspace_max} m, "
                                        f"{sc.workspace_margin} m inside")
        self._q_cmd[:] = q
        self._kinematics_fresh = True
        self._qd_cmd[:] = 0.0
        self._ik_result.qd_dls[:] = 0.0
        self._stop_plan = math.inf if not self._safety.has_box else 0.0
        self._twist[:] = 0.0
        self._hold_fk()
        self._resync = False
        self._started = True
        self._release_s = math.inf
        self._peak[:] = 0.0
        self._smooth[:] = 0.0
        self._rest_s = math.inf
        self._safety.reset(t)

    def clear_fault(self, t: float = 0.0) -> bool:
        """Clear a latched fault once the robot is held at rest (FAULT → IDLE).

        The joint setpoint is kept; use :meth:`reset` to restart from another position.

        Returns:
            Whether the fault was cleared (False while the twist or the joints are still
            decelerating, or if not in FAULT).
        """
        ok = self._safety.clear_fault(t, kernels.is_zero(self._twist)
                                      and kernels.is_zero(self._qd_cmd))
        if ok:
            self._resync = True
        return ok

    @property
    def state(self) -> State:
        """Current safety state."""
        return self._safety.state

    @property
    def events(self) -> list[Event]:
        """The logged state transitions, oldest first (a copy)."""
        return list(self._safety.events)

    @property
    def events_dropped(self) -> int:
        """Number of events dropped from the bounded log."""
        return self._safety.events_dropped

    # ----------------------------------------------------------------- real time
    def update(self, inp: GuidingInput, out: GuidingOutput) -> Status:
        """One controller cycle; fills ``out``; never raises.

        Args:
            inp: Measured feedback, estimated wrench and deadman.
            out: Setpoint, commanded pose and twist, state.

        Returns:
            ``Status.OK``, or ``Status.FAULT`` while a fault is latched.
        """
        sup, ik, t = self._safety, self._ik, inp.t
        if not self._started:
            # no setpoint yet: hold wherever the robot was last measured (NaN before any
            # finite measurement: there is no position to command)
            sup.trip(t, Fault.NOT_STARTED)
            if inp.q.shape == self._measured_q.shape and np.isfinite(inp.q).all():
                self._measured_q[:] = inp.q
            self._write(out, 1.0)
            out.q[:] = self._measured_q
            return out.status
        sup.check_feedback(t, inp.sequence, inp.q, inp.current, inp.wrench_base, self._q_cmd)
        if inp.estimator_status < 0:
            sup.trip(t, Fault.ESTIMATOR, float(inp.estimator_status))
        if not self._kinematics_fresh:
            ik.compute_kinematics(self._q_cmd)
            self._kinematics_fresh = True
        if self._resync:
            self._hold_fk()
            self._resync = False
        if not self._residual_fresh:
            err = pin.log6(ik.transform_tool_to_base.actInv(self._T_cmd)).vector
            self._residual = kernels.norm(err)
            self._residual_fresh = True
        residual = self._residual
        mu = ik.manipulability
        twist, new = self._twist, self._twist_new
        # cycles a stop gives the joints (IKConfig.stop_acceleration_fraction) from the setpoint;
        # computed where needed (-1: not yet)
        joint_stop = -1.0
        sup.check_motion(t, mu, self._q_cmd, self._qd_cmd, residual)
        sup.deadman(t, inp.deadman)
        scale = sup.speed_scale(mu)
        kernels.control_wrench(inp.wrench_base, ik.rotation_tool_to_base, self._tool,
                               sup.inputs_finite, self._mask, self._wrench)
        if sup.state == State.GUIDING:
            if self._auto is not None:
                ik.jacobian_in_frame(self.config.frame, self._Jc)
                self._auto.update(self._Jc, mu, self._friction, self._stop_friction)
            # settling after a stop, or after a release at rest (the force on some axis falls
            # back from its peak: the gears unload, and the estimate swings the other way):
            # breaking away takes the stopping friction; then the law, the limits and (base
            # frame) the next pose, in one compiled call
            law, lim = self._law, self._limiter
            self._release_s = gk.guiding_step(
                self._axes, law.law_id, law.alpha, self._step_settings, lim.max_speed,
                lim.max_step, scale, self._rest_s, self._release_s, not self._tool,
                self._R_cmd, self._p_cmd, self._R_new, self._p_new)
            if self._tool:
                self._integrate(new)
            if sup.has_box:
                joint_stop = ik.stop_cycles(self._qd_cmd)
                # a stop starting next cycle lasts at most this long: the Cartesian one, or the
                # joints' from the faster of their velocity and the one the twist asks for
                # (ahead while their acceleration holds them back), plus this cycle's step
                stop = max(self._limiter.stop_cycles(twist), joint_stop,
                           ik.stop_cycles(self._ik_result.qd_dls)) + 1.0
                speed = kernels.norm(new[:3])
                clearance = sup.workspace_clearance(self._p_new, speed,
                                                    stop * self.config.dt)
                if clearance < 0.0:
                    # stop from the last cycle's twist, as planned (and checked) there
                    sup.trip(t, Fault.WORKSPACE, clearance)
                else:
                    self._stop_plan = stop
        if sup.state != State.GUIDING:
            if joint_stop < 0.0:
                joint_stop = ik.stop_cycles(self._qd_cmd)
            # at the joints' pace, but never longer than the stop the last check planned
            self._limiter.decelerate(twist, new, min(joint_stop, self._stop_plan))
            self._stop_plan = max(self._stop_plan - 1.0, 0.0)
            self._integrate(new)
        # at rest: no twist, and joints slow enough to halt within one cycle's acceleration
        # (else the IK keeps tracking the held pose and brakes them at their limits)
        at_rest = kernels.is_zero(new)
        if at_rest and not kernels.is_zero(self._qd_cmd):
            if joint_stop < 0.0:
                joint_stop = ik.stop_cycles(self._qd_cmd)
            at_rest = joint_stop * ik.config.stop_acceleration_fraction <= 1.0
        sup.stopped(t, at_rest)
        twist[:] = new
        res = self._ik_result
        if at_rest:
            if self._rest_s == 0.0:
                # came to rest (a reset or an earlier rest cycle did this already, and the
                # setpoint has not moved since): hold, the setpoint stays bit for bit, the
                # target is the pose of the setpoint
                self._qd_cmd[:] = 0.0
                res.qd_dls[:] = 0.0
                self._hold_fk()
                res.scale = 1.0
            self._rest_s += self.config.dt
        else:
            self._rest_s = 0.0
            self._take_new_pose()
            ik.solve(self._q_cmd, self._qd_cmd, self._T_cmd, res)
            self._q_cmd[:] = res.q
            self._kinematics_fresh = self._residual_fresh = False
            self._qd_cmd[:] = res.qd
            self._resync = res.limited
        out.manipulability = mu
        out.ik_residual = residual
        self._write(out, scale)
        return out.status

    def _integrate(self, twist: Array) -> None:
        """The next pose (``_T_new``) after one cycle of ``twist`` from the commanded one: tool
        frame T·exp6(ν·dt); base frame (axes of the base at the TCP) p + v·dt and
        exp3(ω·dt)·R (the TCP point moves with v)."""
        if self._tool:
            np.multiply(twist, self.config.dt, out=self._vdt)
            T = self._T_cmd * pin.exp6(self._vdt)
            gk.copy_pose(T.rotation, T.translation, self._R_new, self._p_new)
            return
        gk.integrate_base(self._R_cmd, self._p_cmd, twist, self.config.dt, self._R_new,
                          self._p_new)

    def _hold_fk(self) -> None:
        """The commanded pose becomes the pose of the joint setpoint (a copy of its FK)."""
        ik = self._ik
        gk.copy_pose(ik.rotation_tool_to_base, ik.translation_tool_to_base, self._R_cmd,
                     self._p_cmd)
        self._residual_fresh = False

    def _take_new_pose(self) -> None:
        """The next pose becomes the commanded one (the two poses swap)."""
        self._T_cmd, self._T_new = self._T_new, self._T_cmd
        self._residual_fresh = False
        self._R_cmd, self._R_new = self._R_new, self._R_cmd
        self._p_cmd, self._p_new = self._p_new, self._p_cmd

    def _write(self, out: GuidingOutput, scale: float) -> None:
        sup = self._safety
        kernels.write_output(self._q_cmd, self._qd_cmd, self._R_cmd, self._p_cmd, self._twist,
                             self._tool, self._wrench, self._friction, self._stop_friction,
                             out.q, out.qd, out.transform_tool_to_base, out.twist_base,
                             out.twist_tool, out.wrench, out.friction, out.stopping_friction)
        out.state = sup.state
        out.fault = sup.fault
        out.status = Status.FAULT if sup.state == State.FAULT else Status.OK
        out.speed_scale = scale
        out.ik_scale = self._ik_result.scale
        out.rest_s = self._rest_s
