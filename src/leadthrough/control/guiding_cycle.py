"""One cycle of the guiding controller, compiled (Numba, ``nopython``, cached on disk).

:class:`~leadthrough.control.guiding.GuidingController` documents what a cycle does; this is
that cycle, from the safety checks to the output, as one compiled call on named records: the
input (:class:`~leadthrough.control.guiding_types.GuidingInput`), the controller's own record
(:mod:`leadthrough.control.guiding_state`), its IK's (:func:`~leadthrough.control.ik.ik_dtype`,
with the Pinocchio kinematics of the setpoint), its safety supervisor's and event ring
(:mod:`leadthrough.control.safety_rules`) and the output
(:class:`~leadthrough.control.guiding_types.GuidingOutput`). Only the Pinocchio kinematics of a
setpoint that moved and the automatic friction of eq. 36 run before it, in Python.

:func:`guiding_cycle` reads as the four steps of the controller's docstring and calls the
module that models each part: :mod:`~leadthrough.control.safety_rules` (checks, states),
:mod:`~leadthrough.control.release` (a hand letting go),
:mod:`~leadthrough.control.virtual_friction` (eq. 31–33) or
:mod:`~leadthrough.control.velocity_baseline` ([14]), :mod:`~leadthrough.control.limits`
(speed, acceleration, stops), :mod:`~leadthrough.control.se3` (pose integration, frames) and
:mod:`~leadthrough.control.ik_step` (the IK). Nothing here allocates, raises or reads the clock.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control import safety_rules as rules
from leadthrough.control.guiding_state import Law
from leadthrough.control.guiding_types import GuidingStatus
from leadthrough.control.hand_release import fresh_rise, let_go_step, level_let_go
from leadthrough.control.ik_step import ik_step, joint_stop_cycles, update_manipulability
from leadthrough.control.limits import decelerate_twist, limit_twist, twist_stop_cycles
from leadthrough.control.release import release_step
from leadthrough.control.rest_drift import drift_step
from leadthrough.control.safety_states import Fault, State
from leadthrough.control.se3 import (
    copy_pose,
    integrate_base,
    integrate_tool,
    log6_between,
    rotate_to_base,
    rotate_to_tool,
)
from leadthrough.control.velocity_baseline import velocity_baseline
from leadthrough.control.virtual_friction import virtual_friction

__all__ = ["guiding_cycle", "not_started_cycle"]

Array = NDArray[np.float64]
Record = Any     # a record of its part's dtype (compiled code reads it by field)
Records = NDArray[np.void]   # a record as Python passes it: a structured array of one element
Events = NDArray[np.void]


@njit(cache=True, nogil=True)
def guiding_cycle(inputs: Records, controller: Records, ik_records: Records,
                  supervisor: Records, events: Events, outputs: Records) -> int:
    """One cycle of a started controller, from the feedback to the output.

    Args:
        inputs: The input's record (``GuidingInput.record``).
        controller: The controller's record (``guiding_state.controller_dtype``), in place.
        ik_records: The IK's record, with the kinematics of the setpoint ``q_cmd``, in place.
        supervisor: The safety supervisor's record, in place.
        events: Its event ring, in place.
        outputs: The output's record (``GuidingOutput.record``), written.

    Returns:
        The safety state after the cycle.
    """
    inp, ctl, ik, sup, out = (inputs[0], controller[0], ik_records[0], supervisor[0],
                              outputs[0])
    t = inp.t
    # 1. the feedback and the estimator, the setpoint's kinematics, motion checks, deadman
    rules.check_feedback(sup, events, t, inp.sequence, inp.q, inp.current, inp.wrench_base,
                         ctl.q_cmd)
    if inp.estimator_status < 0:
        rules.trip(sup, events, t, Fault.ESTIMATOR, float(inp.estimator_status), -1)
    _setpoint_kinematics(ctl, ik)
    rules.check_motion(sup, events, t, ik.manipulability, ctl.q_cmd, ctl.qd_cmd, ctl.residual)
    rules.deadman(sup, events, t, inp.deadman)
    scale = rules.speed_scale(sup, ik.manipulability)
    _law_wrench(inp.wrench_base, ik.tcp_rotation, ctl.tool_frame, sup.inputs_finite,
                ctl.axis_mask, ctl.wrench)
    _rest_wrench(ctl, sup.state == State.GUIDING)
    # 2.–3. the next twist and pose: the law within the limits, or a stop
    joint_stop = -1.0   # cycles a stop gives the joints from the setpoint (-1: not computed)
    if sup.state == State.GUIDING:
        joint_stop = _guide(ctl, ik, sup, events, t, scale)
    if sup.state != State.GUIDING:
        joint_stop = _stop(ctl, ik, joint_stop)
    # 4. at rest: hold the setpoint; moving: the IK step to the next pose
    at_rest = _at_rest(ctl, ik, joint_stop)
    rules.stopped(sup, events, t, at_rest)
    for i in range(6):
        ctl.twist[i] = ctl.next_twist[i]
    if at_rest:
        _hold(ctl, ik)
    else:
        _step(ctl, ik)
    ctl.speed_scale = scale
    _write_output(ctl, ctl.q_cmd, out)
    out.manipulability = ik.manipulability
    out.ik_residual = ctl.residual
    _write_state(sup, out)
    return sup.state


@njit(cache=True, nogil=True)
def not_started_cycle(inputs: Records, controller: Records, supervisor: Records,
                      events: Events, outputs: Records) -> int:
    """A cycle before the first reset: the NOT_STARTED fault, holding wherever the robot was
    last measured (NaN before any finite measurement: there is no position to command).
    Takes the records as :func:`guiding_cycle`; returns the safety state."""
    inp, ctl, sup, out = inputs[0], controller[0], supervisor[0], outputs[0]
    rules.trip(sup, events, inp.t, Fault.NOT_STARTED, math.nan, -1)
    finite = True
    for j in range(inp.q.size):
        finite = finite and math.isfinite(inp.q[j])
    if finite:
        for j in range(inp.q.size):
            ctl.q_measured[j] = inp.q[j]
    _write_output(ctl, ctl.q_measured, out)
    out.speed_scale = out.ik_scale = 1.0
    _write_state(sup, out)
    return sup.state


@njit(cache=True, nogil=True)
def _setpoint_kinematics(ctl: Record, ik: Record) -> None:
    """μ and λ of new kinematics; the commanded pose re-synchronised with the setpoint's (after
    a joint bound shortened the IK step, or a cleared fault); the IK residual, unless the
    setpoint and the commanded pose are unchanged."""
    if ctl.kinematics_new:
        update_manipulability(ik)
        ctl.kinematics_new = False
    if ctl.resync:
        copy_pose(ik.tcp_rotation, ik.tcp_position, ctl.pose_rotation, ctl.pose_position)
        ctl.residual_fresh = False
        ctl.resync = False
    if not ctl.residual_fresh:
        ctl.residual = log6_between(ik.tcp_rotation, ik.tcp_position, ctl.pose_rotation,
                                    ctl.pose_position, ik.error)
        ctl.residual_fresh = True


@njit(cache=True, nogil=True)
def _law_wrench(wrench_base: Array, rotation: Array, tool: bool, finite: bool, mask: Array,
                out: Array) -> None:
    """The wrench the law sees: the estimate in the controller's frame, disabled axes zeroed;
    all NaN if the inputs are not finite (the law is then not run)."""
    if not finite:
        out[:] = math.nan
        return
    if tool:
        rotate_to_tool(rotation, wrench_base, out)
    else:
        out[:] = wrench_base
    for i in range(6):
        out[i] *= mask[i]


@njit(cache=True, nogil=True)
def _rest_wrench(ctl: Record, guiding: bool) -> None:
    """The virtual-friction law's input: guiding at rest, the estimate less its drift at rest
    (:mod:`leadthrough.control.rest_drift`); moving, the estimate (the baseline relaxes, and
    restarts from 0 when not guiding); not guiding and at rest (IDLE, a stop or a fault come
    to rest), the estimate, with the baseline at its level: what it reads before a press is
    no push, so a press moves the tool only on a rise over it."""
    resting = _is_zero(ctl.twist) and ctl.law == Law.VIRTUAL_FRICTION
    drift_step(ctl.wrench, ctl.friction, ctl.drift_rate, ctl.release_drop, ctl.dt,
               ctl.drift_alpha_fast,
               ctl.drift_alpha_slow, ctl.drift_span_s, ctl.drift_decay if guiding else 0.0,
               guiding and resting, resting and not guiding, ctl.drift_fast, ctl.drift_slow,
               ctl.rest_baseline, ctl.rest_wrench)


@njit(cache=True, nogil=True)
def _guide(ctl: Record, ik: Record, sup: Record, events: Events, t: float,
           speed_scale: float) -> float:
    """GUIDING: the law's twist within the limits and the next pose; with a workspace box, the
    check that the TCP could stop inside it from there (else the WORKSPACE fault). Returns the
    cycles a stop gives the joints from the setpoint (-1: not computed)."""
    at_rest = _is_zero(ctl.twist)
    # a release at rest restarts the release clock; while settling (at rest, within hold_s of
    # the last stop or release) breaking away takes the stopping friction
    released = release_step(ctl.wrench, ctl.friction, ctl.release_drop, ctl.release_hold,
                            ctl.release_alpha, ctl.release_forget, ctl.release_smooth,
                            ctl.release_peak, not at_rest)
    if released and at_rest:
        ctl.release_s = 0.0
    if ctl.hand_release:
        _hand_release(ctl, at_rest, released and at_rest)
    settling = at_rest and (ctl.rest_s < ctl.hold_s or ctl.release_s < ctl.hold_s)
    ctl.release_s += ctl.dt
    if ctl.hand_released:
        # the hand let go: to rest at the acceleration limit, whatever the estimate says
        decelerate_twist(ctl.twist, ctl.max_step,
                         joint_stop_cycles(ctl.qd_cmd, ik.stop_velocity_step), ctl.desired_twist)
    elif ctl.law == Law.VIRTUAL_FRICTION:
        virtual_friction(ctl.twist, ctl.rest_wrench,
                         ctl.stopping_friction if settling else ctl.friction,
                         ctl.stopping_friction, ctl.law_coefficients, ctl.desired_twist)
    else:
        velocity_baseline(ctl.twist, ctl.wrench, ctl.law_coefficients, ctl.velocity_alpha,
                          ctl.desired_twist)
    limit_twist(ctl.twist, ctl.desired_twist, ctl.max_speed, ctl.max_step, speed_scale,
                ctl.next_twist)
    _integrate(ctl)
    if not sup.has_box:
        return -1.0
    joint_stop = joint_stop_cycles(ctl.qd_cmd, ik.stop_velocity_step)
    # a stop starting next cycle lasts at most this long: the Cartesian one, or the joints'
    # from the faster of their velocity and the one the twist asks for (ahead while their
    # acceleration holds them back), plus this cycle's step
    stop = max(twist_stop_cycles(ctl.twist, ctl.max_step), joint_stop,
               joint_stop_cycles(ctl.qd_dls, ik.stop_velocity_step)) + 1.0
    v = ctl.next_twist
    speed = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    clearance = rules.workspace_clearance(sup, ctl.next_position, speed, stop * ctl.dt)
    if clearance < 0.0:
        # stop from the last cycle's twist, as planned (and checked) there
        rules.trip(sup, events, t, Fault.WORKSPACE, clearance, -1)
    else:
        ctl.stop_plan = stop
    return joint_stop


@njit(cache=True, nogil=True)
def _hand_release(ctl: Record, at_rest: bool, released_at_rest: bool) -> None:
    """The hand's state (:mod:`leadthrough.control.hand_release`): a letting go, in motion or
    at rest (``release.py``'s), starts the stop (``hand_released``, ``hand_release_s`` = 0;
    ``release_s`` = 0: the settling after a release). Only a fresh rise after the lockout
    ends it: a quick one, or once the drives have settled (``hold_s`` after the letting go) a
    rise of δ over the level the estimate settled to, which follows the drives' drift at rest
    (:mod:`leadthrough.control.rest_drift`: the baseline restarts from the estimate then).
    A letting go of a hold that level took up (``hand_release.level_let_go``) clears it, and
    it is taken again ``hold_s`` after the last such fall."""
    let_go = let_go_step(ctl.wrench, ctl.friction, ctl.hand_alpha, ctl.dt, ctl.hand_window_s,
                         ctl.hand_forget, ctl.hand_drop_fraction, ctl.hand_smooth,
                         ctl.hand_peak, ctl.hand_peak_age)
    if at_rest:
        # a fall in motion counts from the motion's peak; at rest release.py tells
        ctl.hand_peak[:] = ctl.hand_smooth
        ctl.hand_peak_age[:] = 0.0
    if (let_go and not at_rest) or released_at_rest:
        ctl.hand_released = True
        ctl.hand_settled = ctl.hand_level_taken = False
        ctl.hand_release_s = ctl.hand_settle_s = 0.0
        ctl.release_s = 0.0
    # a letting go of a hold the level took up (a quick fall back against it): the level is
    # taken again once the estimate has been quiet for hold_s
    if (level_let_go(ctl.hand_smooth, ctl.friction, ctl.release_drop, ctl.release_forget,
                     ctl.rest_baseline, ctl.hand_level_reference)
            and ctl.hand_level_taken):
        ctl.hand_settled = False
        ctl.hand_settle_s = 0.0
    # a quick rise is a grip; once the drives have settled, so is a rise of δ over the level
    # the estimate settled to, followed at the drives' drift rate (the law's rest input)
    if (ctl.hand_released and not ctl.hand_settled and at_rest
            and ctl.hand_settle_s >= ctl.hold_s):
        ctl.hand_settled = ctl.hand_level_taken = True
        for i in range(6):
            ctl.rest_baseline[i] = ctl.drift_fast[i]
            ctl.rest_wrench[i] = ctl.wrench[i] - ctl.drift_fast[i]
    rose = fresh_rise(ctl.hand_smooth, ctl.friction, ctl.hand_rise_forget, ctl.hand_reference)
    if ctl.hand_settled and at_rest:
        for i in range(6):
            rose = rose or abs(ctl.rest_wrench[i]) >= ctl.friction[i]
    if ctl.hand_released and ctl.hand_release_s >= ctl.hand_lockout_s and rose:
        ctl.hand_released = False
    ctl.hand_release_s += ctl.dt
    ctl.hand_settle_s += ctl.dt


@njit(cache=True, nogil=True)
def _stop(ctl: Record, ik: Record, joint_stop: float) -> float:
    """STOPPING, FAULT, IDLE: decelerate at the joints' pace, but never longer than the stop
    the last workspace check planned, and the next pose. Returns the joints' stop cycles."""
    if joint_stop < 0.0:
        joint_stop = joint_stop_cycles(ctl.qd_cmd, ik.stop_velocity_step)
    decelerate_twist(ctl.twist, ctl.max_step, min(joint_stop, ctl.stop_plan), ctl.next_twist)
    ctl.stop_plan = max(ctl.stop_plan - 1.0, 0.0)
    _integrate(ctl)
    return joint_stop


@njit(cache=True, nogil=True)
def _integrate(ctl: Record) -> None:
    """The next pose after one cycle of the next twist: T·exp6(ν·dt) in tool axes, or
    p + v·dt, exp3(ω·dt)·R in base axes."""
    if ctl.tool_frame:
        integrate_tool(ctl.pose_rotation, ctl.pose_position, ctl.next_twist, ctl.dt,
                       ctl.next_rotation, ctl.next_position)
    else:
        integrate_base(ctl.pose_rotation, ctl.pose_position, ctl.next_twist, ctl.dt,
                       ctl.next_rotation, ctl.next_position)


@njit(cache=True, nogil=True)
def _at_rest(ctl: Record, ik: Record, joint_stop: float) -> bool:
    """At rest: no twist, and joints slow enough to halt within one cycle's acceleration (else
    the IK keeps tracking the held pose and brakes them at their limits)."""
    if not _is_zero(ctl.next_twist):
        return False
    if _is_zero(ctl.qd_cmd):
        return True
    if joint_stop < 0.0:
        joint_stop = joint_stop_cycles(ctl.qd_cmd, ik.stop_velocity_step)
    return joint_stop * ctl.stop_fraction <= 1.0


@njit(cache=True, nogil=True)
def _hold(ctl: Record, ik: Record) -> None:
    """At rest. Coming to rest (a reset or an earlier rest cycle did this already, and the
    setpoint has not moved since): hold the setpoint bit for bit, its pose the target."""
    if ctl.rest_s == 0.0:
        for j in range(ctl.q_cmd.size):
            ctl.qd_cmd[j] = 0.0
            ctl.qd_dls[j] = 0.0
        copy_pose(ik.tcp_rotation, ik.tcp_position, ctl.pose_rotation, ctl.pose_position)
        ctl.residual_fresh = False
        ctl.ik_scale = 1.0
    ctl.rest_s += ctl.dt


@njit(cache=True, nogil=True)
def _step(ctl: Record, ik: Record) -> None:
    """Moving: the next pose becomes the commanded one and the IK steps the setpoint toward it;
    a step shortened by a joint bound re-synchronises the commanded pose next cycle."""
    ctl.rest_s = 0.0
    copy_pose(ctl.next_rotation, ctl.next_position, ctl.pose_rotation, ctl.pose_position)
    ik_scale, _ = ik_step(ik, ctl.pose_rotation, ctl.pose_position, ctl.q_cmd, ctl.qd_cmd,
                          ctl.qd_dls, ctl.qd_next, ctl.q_next)
    for j in range(ctl.q_cmd.size):
        ctl.q_cmd[j] = ctl.q_next[j]
        ctl.qd_cmd[j] = ctl.qd_next[j]
    ctl.kinematics_fresh = False
    ctl.residual_fresh = False
    ctl.resync = ik_scale < 1.0
    ctl.ik_scale = ik_scale


@njit(cache=True, nogil=True)
def _write_output(ctl: Record, q: Array, out: Record) -> None:
    """The output's arrays: the setpoint ``q`` and its velocity, the commanded pose as a 4×4
    transform, the twist in both frames, the law's wrench and both frictions, and the scales
    and rest time."""
    for j in range(q.size):
        out.q[j] = q[j]
        out.qd[j] = ctl.qd_cmd[j]
    rotation, T = ctl.pose_rotation, out.transform_tool_to_base
    for r in range(3):
        for c in range(3):
            T[r, c] = rotation[r, c]
        T[r, 3] = ctl.pose_position[r]
    T[3, 3] = 1.0
    if ctl.tool_frame:
        out.twist_tool[:] = ctl.twist
        rotate_to_base(rotation, ctl.twist, out.twist_base)
    else:
        out.twist_base[:] = ctl.twist
        rotate_to_tool(rotation, ctl.twist, out.twist_tool)
    for i in range(6):
        out.wrench[i] = ctl.wrench[i]
        out.friction[i] = ctl.friction[i]
        out.stopping_friction[i] = ctl.stopping_friction[i]
    out.speed_scale = ctl.speed_scale
    out.ik_scale = ctl.ik_scale
    out.rest_s = ctl.rest_s


@njit(cache=True, nogil=True)
def _write_state(sup: Record, out: Record) -> None:
    """The output's state, fault and status."""
    out.state = sup.state
    if sup.state == State.FAULT:
        out.fault = sup.fault
        out.status = GuidingStatus.FAULT
    else:
        out.fault = Fault.NONE
        out.status = GuidingStatus.OK


@njit(cache=True, nogil=True)
def _is_zero(x: Array) -> bool:
    """Whether every entry is exactly 0.0 (``not x.any()`` for a float vector)."""
    for i in range(x.size):  # noqa: SIM110 (a plain loop compiles to the fastest code)
        if x[i] != 0.0:
            return False
    return True
