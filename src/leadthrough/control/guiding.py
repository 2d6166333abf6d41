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
   stop or after a release (:mod:`~leadthrough.control.release`: the force on an axis falling
   back from a peak of at least ``RELEASE_HOLD`` × δ by ``RELEASE_DROP`` × δ or more within
   about ``RELEASE_WINDOW_S``: the peak forgets slow drifts), breaking away takes the stopping
   friction: the paper's
   "larger friction once the force is removed", applied while the drives settle or unload.
   At rest the law's threshold counts from the estimate's slow drift (at no more than
   δ/``drift_s``: the servo's integral loading the gears' static friction;
   :mod:`~leadthrough.control.rest_drift`), which only ever holds the tool.
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

Steps 1–4 run as one compiled call (:func:`~leadthrough.control.guiding_cycle.guiding_cycle`)
on the named records of the controller (:mod:`~leadthrough.control.guiding_state`), its IK and
its supervisor; only the Pinocchio kinematics of a setpoint that moved, and eq. 36 (automatic
friction), run in Python before it (``benchmarks/guiding.py`` measures the cycle).

``update`` never raises, never reads the clock, and allocates no arrays of its own (Pinocchio
returns a new Jacobian when the setpoint moved, and eq. 36 its ``numpy.linalg`` results; a state
transition writes one entry of the supervisor's preallocated event ring).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import guiding_state
from leadthrough.control import safety_rules as rules
from leadthrough.control.auto_friction import AutoFriction
from leadthrough.control.guiding_cycle import guiding_cycle, not_started_cycle
from leadthrough.control.guiding_types import (
    CONTROLLERS,
    GuidingConfig,
    GuidingInput,
    GuidingOutput,
    GuidingStatus,
    adjusted_config,
)
from leadthrough.control.ik import DifferentialIK
from leadthrough.control.ik_step import update_manipulability_of
from leadthrough.control.safety import Event, Fault, SafetySupervisor, State
from leadthrough.errors import ControlError
from leadthrough.robot.description import Robot
from leadthrough.state_records import new_record, view

__all__ = [
    "CONTROLLERS",
    "GuidingConfig",
    "GuidingController",
    "GuidingInput",
    "GuidingOutput",
    "GuidingStatus",
]

Array = NDArray[np.float64]


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
        self._commissioned = cfg
        self.robot = robot
        self.n = n = robot.n
        self._auto: AutoFriction | None = None
        if cfg.friction_mode == "auto":
            if noise_mean is None:
                raise ControlError("needed for automatic friction", field="noise_mean",
                                   expected="τ̄_ω per joint (params file [noise] mean)")
            self._auto = AutoFriction(noise_mean, noise_std, cfg.auto_friction)
            if self._auto.n != n:
                raise ControlError("wrong size", field="noise_mean", value=self._auto.n,
                                   expected=f"{n} values")
        self._ik = DifferentialIK(robot, cfg.ik, cfg.dt)
        self._safety = SafetySupervisor(robot, cfg.safety, cfg.limits)
        #: The controller's record (:func:`~leadthrough.control.guiding_state.controller_dtype`).
        self.record = new_record(guiding_state.controller_dtype(n))
        self._s = view(self.record)
        guiding_state.write_settings(self._s, cfg)
        guiding_state.write_initial_state(self._s)
        self._jacobian_in_frame = np.zeros((6, n))
        # what a cycle runs on when given an input or output made for another robot
        self._bad_input, self._spare_output = GuidingInput(n), GuidingOutput(n)
        self._bad_input.q[:] = math.nan
        self._layouts = (self._bad_input.record.dtype, self._spare_output.record.dtype)

    # ----------------------------------------------------------------- set-up
    def make_input(self) -> GuidingInput:
        """A preallocated input."""
        return GuidingInput(self.n)

    def make_output(self) -> GuidingOutput:
        """A preallocated output."""
        out = GuidingOutput(self.n)
        out.friction[:] = self._s.friction
        out.stopping_friction[:] = self._s.stopping_friction
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
        s, ik = self._s, self._ik
        s.kinematics_fresh = False
        ik.compute_kinematics(q)
        p = ik.translation_tool_to_base
        if self._safety.workspace_clearance(p, 0.0) < 0.0:
            sc = self.config.safety
            raise ControlError("TCP outside the workspace box", field="q", value=p.tolist(),
                               expected=f"TCP within {sc.workspace_min} .. {sc.workspace_max} m, "
                                        f"{sc.workspace_margin} m inside")
        s.q_cmd = q
        s.qd_cmd = s.qd_dls = 0.0
        s.kinematics_fresh = s.kinematics_new = True
        self._update_auto_friction()
        guiding_state.write_reset_state(s, ik.rotation_tool_to_base, p, self._safety.has_box)
        self._safety.reset(t)

    def clear_fault(self, t: float = 0.0) -> bool:
        """Clear a latched fault once the robot is held at rest (FAULT → IDLE).

        The joint setpoint is kept; use :meth:`reset` to restart from another position.

        Returns:
            Whether the fault was cleared (False while the twist or the joints are still
            decelerating, or if not in FAULT).
        """
        s = self._s
        ok = self._safety.clear_fault(t, not (s.twist.any() or s.qd_cmd.any()))
        if ok:
            s.resync = True
        return ok

    def retune(self, config: GuidingConfig) -> None:
        """Change the settings an operator may change during a session, at rest: ``frame``,
        ``axes_enabled`` and ``virtual_friction`` (mass and fixed friction). The law's state
        that depends on the frame (the release detector) restarts.

        Args:
            config: The new settings; every other field as now.

        Raises:
            ControlError: Another setting differs, or the commanded motion is not at rest (the
                law's twist, in the old frame, would be read in the new one).
        """
        live = ("frame", "axes_enabled", "virtual_friction")
        if replace(config, **{k: getattr(self.config, k) for k in live}) != self.config:
            raise ControlError("only the frame, the axes and the virtual mass and friction can "
                               "change during a session", field="config",
                               expected="the session's settings but for " + ", ".join(live))
        s = self._s
        if s.twist.any() or s.qd_cmd.any():
            raise ControlError("the commanded motion is not at rest", field="config",
                               expected="a retune at rest")
        self.config = config
        guiding_state.write_live_settings(s, config)
        if self._auto is not None:
            s.kinematics_fresh = False   # eq. 36 again, in the new frame
        s.release_peak = s.release_smooth = s.rest_baseline = 0.0
        s.drift_fast = s.drift_slow = 0.0

    def trip(self, t: float, fault: Fault, value: float = math.nan, index: int = -1) -> None:
        """Latch ``fault`` from outside the cycle (a guiding loop's driver or controller-state
        fault): from the next cycle on, the commanded motion stops at the acceleration limit and
        holds, as for the controller's own faults (no-op while a fault is latched).

        Args:
            t: Time [s] (logged).
            fault: The fault.
            value: Its offending value (see :class:`Fault`).
            index: Joint or axis index, -1 if none.
        """
        self._safety.trip(t, fault, value, index)

    def adjust(self, *, frame: str | None = None, axes_enabled: Sequence[bool] | None = None,
               mass: tuple[float, float] | None = None,
               friction: tuple[float, float] | None = None) -> GuidingConfig:
        """Change what an operator may change: the frame, the enabled axes, the virtual mass
        and the fixed friction, the last two clamped to ``config.operator_limits``
        (:func:`~leadthrough.control.guiding_types.adjusted_config`).

        Call it between cycles, while the controller is IDLE or in FAULT: a change of frame
        or axes while the law is running would turn the motion (its twist and the release
        detector's state are kept in the controller's frame). With the automatic friction,
        eq. 36 is evaluated again in the new frame at the next cycle.

        Args:
            frame: ``"base"`` or ``"tool"``; None: unchanged.
            axes_enabled: 6 booleans (x, y, z, ωx, ωy, ωz); None: unchanged.
            mass: (translational [kg], rotational [kg·m²]); None: unchanged.
            friction: (translational [N], rotational [N·m]); None: unchanged.

        Returns:
            The settings now in force (``config``), with the clamped values.

        Raises:
            ControlError: GUIDING or STOPPING, or a change ``adjusted_config`` refuses
                (nothing is changed then).
        """
        state = self.state
        if state in (State.GUIDING, State.STOPPING):
            raise ControlError("settings change only while the robot is not guided",
                               field="state", value=state.name,
                               expected="IDLE or FAULT (release the enabling device)")
        cfg = adjusted_config(self.config, self._commissioned, frame=frame,
                              axes_enabled=axes_enabled, mass=mass, friction=friction)
        self.config = cfg
        guiding_state.write_settings(self._s, cfg)
        if self._auto is not None:
            self._s.kinematics_fresh = False   # eq. 36 again, in the new frame
        return cfg

    @property
    def state(self) -> State:
        """Current safety state."""
        return self._safety.state

    @property
    def fault(self) -> Fault:
        """The latched fault (``Fault.NONE`` unless in FAULT)."""
        return self._safety.fault

    def events_since(self, count: int) -> list[Event]:
        """The transitions logged after the first ``count``, oldest first."""
        return self._safety.events_since(count)

    @property
    def last_event(self) -> Event | None:
        """The latest logged state transition (with the fault, its value and index), or None
        before the first."""
        return self._safety.last_event

    @property
    def event_count(self) -> int:
        """Number of transitions logged since the controller was made (dropped ones too)."""
        return self._safety.event_count

    @property
    def events(self) -> list[Event]:
        """The logged state transitions, oldest first (a copy)."""
        return list(self._safety.events)

    @property
    def events_dropped(self) -> int:
        """Number of events dropped from the bounded log."""
        return self._safety.events_dropped

    def warm_up(self) -> None:
        """Load (or compile) every compiled function the cycle and a fault reset use, on copies
        of the records: the next cycle then runs at its steady-state speed. Call it before a
        real-time loop starts; it changes nothing of the controller's state."""
        sup = self._safety
        ctl, ik, sv, events = (self.record.copy(), self._ik.record.copy(), sup.record.copy(),
                               sup.event_ring.copy())
        inp, out = self.make_input(), self.make_output()
        inp.q[:] = self._s.q_cmd
        update_manipulability_of(ik)
        not_started_cycle(inp.record, ctl, sv, events, out.record)
        guiding_cycle(inp.record, ctl, ik, sv, events, out.record)
        rules.clear_fault(sv[0], events, 0.0, True)
        # what a reset, a trip from the loop and a fault reset run outside the cycle
        rules.reset(sv[0], events, 0.0)
        rules.trip(sv[0], events, 0.0, int(Fault.DRIVER_ERROR), math.nan, -1)
        rules.workspace_clearance(sv[0], self._s.pose_position, 0.0, 0.0)

    # ----------------------------------------------------------------- real time
    def update(self, inp: GuidingInput, out: GuidingOutput) -> GuidingStatus:
        """One controller cycle; fills ``out``; never raises.

        Args:
            inp: Measured feedback, estimated wrench and deadman.
            out: Setpoint, commanded pose and twist, state.

        Returns:
            ``GuidingStatus.OK``, or ``GuidingStatus.FAULT`` while a fault is latched.
        """
        s, sup = self._s, self._safety
        # a tuple compares its items by identity first: fast for the layouts of make_input
        if (inp.record.dtype, out.record.dtype) != self._layouts:
            return self._wrong_layout(inp, out)
        if not s.started:
            not_started_cycle(inp.record, self.record, sup.record, sup.event_ring, out.record)
            return GuidingStatus.FAULT
        if not s.kinematics_fresh:
            s.kinematics_fresh = s.kinematics_new = True
            if self._auto is None:
                self._ik.frame_kinematics(s.q_cmd)
            else:
                self._ik.compute_kinematics(s.q_cmd)
                self._update_auto_friction()
        state = guiding_cycle(inp.record, self.record, self._ik.record, sup.record,
                              sup.event_ring, out.record)
        return GuidingStatus.FAULT if state == State.FAULT else GuidingStatus.OK

    def _wrong_layout(self, inp: GuidingInput, out: GuidingOutput) -> GuidingStatus:
        """An input or output made for another robot: the cycle runs on a non-finite input
        (``Fault.NONFINITE_INPUT``, a stop at the limit), into a spare output if ``out`` cannot
        take it."""
        bad = self._bad_input
        bad.t = float(inp.record["t"][0]) if "t" in (inp.record.dtype.names or ()) else math.nan
        if out.record.dtype != self._spare_output.record.dtype:
            out = self._spare_output
        s = self._s
        if not s.started:
            not_started_cycle(bad.record, self.record, self._safety.record,
                              self._safety.event_ring, out.record)
            return GuidingStatus.FAULT
        guiding_cycle(bad.record, self.record, self._ik.record, self._safety.record,
                      self._safety.event_ring, out.record)
        return GuidingStatus.FAULT

    def _update_auto_friction(self) -> None:
        """Eq. 36 at the setpoint's pose (automatic friction only), after its
        ``compute_kinematics``."""
        if self._auto is None:
            return
        ik, s = self._ik, self._s
        ik.jacobian_in_frame(self.config.frame, self._jacobian_in_frame)
        self._auto.update(self._jacobian_in_frame, ik.manipulability, s.friction,
                          s.stopping_friction)
