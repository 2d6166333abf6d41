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
   the same numbers.

Steps 1–4 run as one compiled call (:func:`~leadthrough.control.cycle_kernel.controller_cycle`)
on the packed state of the controller, its IK and its supervisor; only the Pinocchio kinematics
of a setpoint that moved, and eq. 36 (automatic friction), run in Python before it
(``benchmarks/guiding.py`` measures the cycle).

``update`` never raises, never reads the clock, and allocates no arrays of its own (Pinocchio
allocates the Jacobian it returns, and eq. 36 its ``numpy.linalg`` results; a state transition
writes one row of the supervisor's preallocated event ring).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import cycle_kernel as ck
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
from leadthrough.control.safety import STATE_BY_CODE, Event, Fault, SafetySupervisor, State
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
        law: AdmittanceLaw = (
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
        lim = TwistLimiter(cfg.limits, cfg.dt)
        self._ik = ik = DifferentialIK(robot, cfg.ik, cfg.dt)
        self._safety = SafetySupervisor(robot, cfg.safety, cfg.limits)
        self._tool = cfg.frame == "tool"
        # the cycle's state, packed for its compiled call (cycle_kernel); the names are views
        self._state = np.zeros(ck.state_size(n))
        values, axes, self._rotations, self._positions, joints = ck.state_views(self._state, n)
        self._values, self._axes, self._joints = values, axes, joints
        self._twist = axes[gk.TWIST]
        self._friction = axes[gk.FRICTION]
        self._stop_friction = axes[gk.STOP_FRICTION]
        self._friction[:] = cfg.virtual_friction.friction
        self._stop_friction[:] = cfg.virtual_friction.stopping_friction
        axes[gk.LAW] = law.coefficients
        axes[gk.MASK] = [1.0 if a else 0.0 for a in cfg.axes_enabled]
        self._q_cmd = joints[ck.Q_CMD]
        self._qd_cmd = joints[ck.QD_CMD]
        joints[ck.MEASURED] = math.nan       # the last finite q before the first reset
        self._flags = flags = np.zeros(ck.FLAG_SLOTS, dtype=np.int64)
        flags[ck.TOOL] = int(self._tool)
        flags[ck.LAW_ID] = law.law_id
        values[ck.REST_S] = values[ck.RELEASE_S] = values[ck.STOP_PLAN] = math.inf
        values[ck.IK_SCALE] = values[ck.SPEED_SCALE] = 1.0
        # guiding_step's settings: hold, dt, release drop, smoothing weight, forgetting factor
        values[ck.STEP_SETTINGS:ck.STEP_SETTINGS + 5] = (
            cfg.settle_s + cfg.rezero_s, cfg.dt, RELEASE_DROP,
            cfg.dt / (RELEASE_SMOOTHING_S + cfg.dt), math.exp(-cfg.dt / RELEASE_WINDOW_S))
        values[ck.LAW_ALPHA] = law.alpha
        values[ck.MAX_SPEED:ck.MAX_SPEED + 2] = lim.max_speed
        values[ck.MAX_STEP:ck.MAX_STEP + 2] = lim.max_step
        values[ck.STOP_FRACTION] = cfg.ik.stop_acceleration_fraction
        values[ck.MU0] = cfg.ik.manipulability_threshold
        values[ck.MAX_DAMPING] = cfg.ik.max_damping
        self._Jc = np.zeros((6, n))
        sup = self._safety
        # the arguments of the compiled cycle after the input's, in its order
        self._cycle_args = (ik.rotation_tool_to_base, ik.translation_tool_to_base, ik.buffer,
                            self._state, flags, sup.buffer, sup.flags)

    # ----------------------------------------------------------------- set-up
    def make_input(self) -> GuidingInput:
        """A preallocated input."""
        n = self.n
        return GuidingInput(t=0.0, sequence=0, q=np.zeros(n), current=np.zeros(n),
                            wrench_base=np.zeros(6))

    def make_output(self) -> GuidingOutput:
        """A preallocated output."""
        out = GuidingOutput(np.zeros(ck.output_size(self.n)))
        out.friction[:] = self._friction
        out.stopping_friction[:] = self._stop_friction
        return out

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
        flags, values, ik = self._flags, self._values, self._ik
        flags[ck.KINEMATICS_FRESH] = 0
        ik.compute_kinematics(q)
        p = ik.translation_tool_to_base
        if self._safety.workspace_clearance(p, 0.0) < 0.0:
            sc = self.config.safety
            raise ControlError("TCP outside the workspace box", field="q", value=p.tolist(),
                               expected=f"TCP within {sc.workspace_min} .. {sc.workspace_max} m, "
                                        f"{sc.workspace_margin} m inside")
        self._q_cmd[:] = q
        self._joints[[ck.QD_CMD, ck.QD_DLS]] = 0.0
        flags[ck.KINEMATICS_FRESH] = flags[ck.KINEMATICS_NEW] = 1
        self._update_auto_friction()
        self._twist[:] = 0.0
        self._axes[[gk.PEAK, gk.SMOOTH]] = 0.0
        self._rotations[ck.CMD] = ik.rotation_tool_to_base
        self._positions[ck.CMD] = p
        flags[ck.RESIDUAL_FRESH] = flags[ck.RESYNC] = 0
        flags[ck.STARTED] = 1
        values[ck.STOP_PLAN] = 0.0 if self._safety.has_box else math.inf
        values[ck.RELEASE_S] = values[ck.REST_S] = math.inf
        self._safety.reset(t)

    def clear_fault(self, t: float = 0.0) -> bool:
        """Clear a latched fault once the robot is held at rest (FAULT → IDLE).

        The joint setpoint is kept; use :meth:`reset` to restart from another position.

        Returns:
            Whether the fault was cleared (False while the twist or the joints are still
            decelerating, or if not in FAULT).
        """
        ok = self._safety.clear_fault(t, not (self._twist.any() or self._qd_cmd.any()))
        if ok:
            self._flags[ck.RESYNC] = 1
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
        flags = self._flags
        if not flags[ck.STARTED]:
            return self._not_started(inp, out)
        if not flags[ck.KINEMATICS_FRESH]:
            flags[ck.KINEMATICS_FRESH] = flags[ck.KINEMATICS_NEW] = 1
            if self._auto is None:
                self._ik.frame_kinematics(self._q_cmd)
            else:
                self._ik.compute_kinematics(self._q_cmd)
                self._update_auto_friction()
        state = ck.controller_cycle(
            inp.t, inp.sequence, inp.deadman, inp.estimator_status, inp.q, inp.current,
            inp.wrench_base, *self._cycle_args, out.buffer)
        values = self._values
        out.state = STATE_BY_CODE[state]
        if state == State.FAULT:
            out.fault = self._safety.fault
            out.status = Status.FAULT
        else:
            out.fault = Fault.NONE
            out.status = Status.OK
        out.manipulability = values[ck.MANIPULABILITY]
        out.ik_residual = values[ck.RESIDUAL]
        out.speed_scale = values[ck.SPEED_SCALE]
        out.ik_scale = values[ck.IK_SCALE]
        out.rest_s = values[ck.REST_S]
        return out.status

    def _not_started(self, inp: GuidingInput, out: GuidingOutput) -> Status:
        """No setpoint yet: NOT_STARTED fault, holding wherever the robot was last measured
        (NaN before any finite measurement: there is no position to command)."""
        sup, measured = self._safety, self._joints[ck.MEASURED]
        sup.trip(inp.t, Fault.NOT_STARTED)
        if inp.q.shape == measured.shape and np.isfinite(inp.q).all():
            measured[:] = inp.q
        kernels.write_output(measured, self._qd_cmd, self._rotations[ck.CMD],
                             self._positions[ck.CMD], self._twist, self._tool,
                             self._axes[gk.WRENCH], self._friction, self._stop_friction, out.q,
                             out.qd, out.transform_tool_to_base, out.twist_base, out.twist_tool,
                             out.wrench, out.friction, out.stopping_friction)
        out.state, out.fault, out.status = sup.state, sup.fault, Status.FAULT
        out.speed_scale = out.ik_scale = 1.0
        out.rest_s = self._values[ck.REST_S]
        return out.status

    def _update_auto_friction(self) -> None:
        """Eq. 36 at the setpoint's pose (automatic friction only), after its
        ``compute_kinematics``."""
        if self._auto is None:
            return
        ik = self._ik
        ik.jacobian_in_frame(self.config.frame, self._Jc)
        self._auto.update(self._Jc, ik.manipulability, self._friction, self._stop_friction)
