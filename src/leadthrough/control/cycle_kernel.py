"""The guiding controller's cycle after the kinematics, as one compiled call (Numba, cached).

:class:`~leadthrough.control.guiding.GuidingController` documents what a cycle does; this is
that cycle, from the safety checks to the output, for a controller that has been started. Only
the kinematics of the joint setpoint (Pinocchio: TCP pose and Jacobian, when the setpoint has
moved) and the automatic friction of eq. 36 run before it in Python. Chained in Python the
cycle's thirty-odd small steps cost a dispatch each, more than their arithmetic (a moving
cycle took 16 µs chained in Python, 7 µs with this call and the kinematics before it);
``benchmarks/guiding.py`` measures the cycle. Each step is a kernel of its own module, called
here in order:
:mod:`~leadthrough.control.safety_kernels` (the state machine and its checks),
:mod:`~leadthrough.control.guiding_kernel` (release, law and limits in GUIDING),
:mod:`~leadthrough.control.kernels` (frames, stops, the output),
:mod:`~leadthrough.control.se3_kernels` (pose integration, the log6 error) and
:mod:`~leadthrough.control.joint_kernels` (the IK's damped least squares and joint bounds).

A compiled call costs about 60 ns per array argument, so each party's arrays are packed into
one buffer (one float64 buffer and, for the controller and the supervisor, one int64 array of
flags), and the kernel takes their views (no copies, no allocation). The controller's float
buffer holds, in order (:func:`state_views`; the names are the slots and rows):

* ``values`` (:data:`VALUE_SLOTS`,): scalars and settings;
* ``axes`` (``guiding_kernel.AXES_ROWS``, 6): per-axis vectors;
* ``rotations`` (2, 3, 3) and ``positions`` (2, 3): the commanded TCP pose (``CMD``) and the next
  one (``NEW``);
* ``joints`` (:data:`JOINT_ROWS`, n): joint setpoint and velocities.

The IK's (``DifferentialIK.buffer``, :func:`ik_views`): J Jᵀ and its factor (2, 6, 6), the least
squares' work space (7, 6), the log6 error (6,), the Jacobian (6, n) and the joint table
(:data:`IK_ROWS`, n). The supervisor's (``SafetySupervisor.buffer``, :func:`safety_views`): its
values, its joint bounds (``safety_kernels.JOINT_ROWS``, n) and its event ring. The output's
(``GuidingOutput.buffer``, :func:`output_views`): the commanded pose (4, 4), the twist in base
and in tool axes, the wrench, δ and δ_s (6 each), then the setpoint q and q̇ (n each).

Nothing here allocates, raises or reads the clock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.control import guiding_kernel as gk
from leadthrough.control import safety_kernels as sk
from leadthrough.control.joint_kernels import IK_DV_STOP, ik_step, ik_views, joint_stop_cycles
from leadthrough.control.kernels import (
    control_wrench,
    decelerate_twist,
    is_zero,
    twist_stop_cycles,
    write_output,
)
from leadthrough.control.se3_kernels import copy_pose, integrate_base, integrate_tool, log6_between
from leadthrough.estimation.kernels import damping_of, gram_manipulability

__all__ = [
    "FLAG_SLOTS",
    "JOINT_ROWS",
    "VALUE_SLOTS",
    "controller_cycle",
    "output_size",
    "output_views",
    "state_size",
    "state_views",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

# the two poses of ``rotations`` / ``positions``
CMD, NEW = 0, 1

# rows of ``joints``: setpoint, its velocity, the DLS velocity before the joint bounds, the IK
# step's result (position, velocity), the last finite measured position before the first reset
Q_CMD, QD_CMD, QD_DLS, Q_NEXT, QD_NEXT, MEASURED = range(6)
JOINT_ROWS = 6

# slots of ``flags``
STARTED = 0
KINEMATICS_FRESH = 1      # the IK's kinematics are those of the setpoint
KINEMATICS_NEW = 2        # ... and were computed since the last cycle (μ to be updated)
RESIDUAL_FRESH = 3        # RESIDUAL is that of the commanded pose from the setpoint
RESYNC = 4                # hold the setpoint's pose as the commanded one next cycle
TOOL = 5                  # setting: the controller's frame is the tool's
LAW_ID = 6                # setting: guiding_kernel.LAW_*
FLAG_SLOTS = 7

# slots of ``values``
REST_S = 0                # time at rest [s]
RELEASE_S = 1             # time since the last release at rest [s]
STOP_PLAN = 2             # cycles of the stop the last workspace check planned
RESIDUAL = 3              # ‖log6(T(q_cmd)⁻¹·T_cmd)‖
MANIPULABILITY = 4
DAMPING = 5               # λ of the IK at the setpoint
SPEED_SCALE = 6
IK_SCALE = 7
STEP_SETTINGS = 8         # 5 slots: guiding_kernel.guiding_step's settings (hold, dt, ...)
LAW_ALPHA = 13            # setting
MAX_SPEED = 14            # 2 settings: v_max, ω_max
MAX_STEP = 16             # 2 settings: a_max·dt, α_max·dt
STOP_FRACTION = 18        # setting: IKConfig.stop_acceleration_fraction
MU0 = 19                  # setting: IKConfig.manipulability_threshold
MAX_DAMPING = 20          # setting: IKConfig.max_damping
VALUE_SLOTS = 21


# the controller's buffer: values, axes, rotations, positions, then the joints
_AXES_AT = VALUE_SLOTS
_ROTATIONS_AT = _AXES_AT + gk.AXES_ROWS * 6
_POSITIONS_AT = _ROTATIONS_AT + 18
_JOINTS_AT = _POSITIONS_AT + 6
# the output's: pose, five 6-vectors, then q and q̇
_OUT_SIX_AT = 16
_OUT_Q_AT = _OUT_SIX_AT + 30


def state_size(n: int) -> int:
    """Length of the controller's buffer for ``n`` joints."""
    return _JOINTS_AT + JOINT_ROWS * n


def output_size(n: int) -> int:
    """Length of the output's buffer for ``n`` joints."""
    return _OUT_Q_AT + 2 * n


@njit(cache=True, nogil=True)
def state_views(state: Array, n: int) -> tuple[Array, Array, Array, Array, Array]:
    """``values``, ``axes``, ``rotations``, ``positions``, ``joints`` of the controller's
    buffer."""
    return (state[:VALUE_SLOTS], state[_AXES_AT:_ROTATIONS_AT].reshape((gk.AXES_ROWS, 6)),
            state[_ROTATIONS_AT:_POSITIONS_AT].reshape((2, 3, 3)),
            state[_POSITIONS_AT:_JOINTS_AT].reshape((2, 3)),
            state[_JOINTS_AT:_JOINTS_AT + JOINT_ROWS * n].reshape((JOINT_ROWS, n)))


@njit(cache=True, nogil=True)
def output_views(buffer: Array, n: int) -> tuple[Array, Array, Array, Array]:
    """``transform`` (4, 4), the five 6-vectors (5, 6: twist in base and in tool axes, wrench,
    δ, δ_s), ``q`` and ``qd`` (n,) of the output's buffer."""
    return (buffer[:_OUT_SIX_AT].reshape((4, 4)),
            buffer[_OUT_SIX_AT:_OUT_Q_AT].reshape((5, 6)), buffer[_OUT_Q_AT:_OUT_Q_AT + n],
            buffer[_OUT_Q_AT + n:_OUT_Q_AT + 2 * n])


@njit(cache=True, nogil=True)
def _integrate(tool: bool, rotations: Array, positions: Array, twist: Array, dt: float) -> None:
    """The next pose after one cycle of ``twist`` from the commanded one."""
    if tool:
        integrate_tool(rotations[CMD], positions[CMD], twist, dt, rotations[NEW], positions[NEW])
    else:
        integrate_base(rotations[CMD], positions[CMD], twist, dt, rotations[NEW],
                       positions[NEW])


@njit(cache=True, nogil=True)
def controller_cycle(t: float, sequence: int, deadman: bool, estimator_status: int,
                     q: Array, current: Array, wrench_base: Array,
                     fk_rotation: Array, fk_position: Array, ik_buffer: Array,
                     state: Array, flags: IntArray, sup_buffer: Array, sup_flags: IntArray,
                     out_buffer: Array) -> int:
    """One cycle of a started controller, from the feedback to the output.

    Args:
        t: Time [s].
        sequence: Feedback sequence number.
        deadman: Enabling input held.
        estimator_status: The estimator's status (negative: latched fault).
        q: Measured joint positions [rad], shape (n,).
        current: Measured motor currents [A], shape (n,).
        wrench_base: Estimated wrench in base axes at the TCP [N, N·m], shape (6,).
        fk_rotation: R of the TCP at the setpoint (the IK's kinematics), shape (3, 3).
        fk_position: p of the TCP at the setpoint [m], shape (3,).
        ik_buffer: The IK's buffer (:func:`ik_views`; its Jacobian at the setpoint).
        state: The controller's buffer (:func:`state_views`).
        flags: The controller's flags and integer settings.
        sup_buffer: The safety supervisor's buffer (:func:`safety_views`).
        sup_flags: Its flags.
        out_buffer: The output's buffer (:func:`output_views`), written.

    Returns:
        The safety state after the cycle.
    """
    n = (state.size - _JOINTS_AT) // JOINT_ROWS
    values, axes, rotations, positions, joints = state_views(state, n)
    gram, ik_scratch, err, jacobian, ik_table = ik_views(ik_buffer, n)
    sup_values, sup_joints, events = sk.safety_views(sup_buffer, n)
    q_cmd, qd_cmd, qd_dls = joints[Q_CMD], joints[QD_CMD], joints[QD_DLS]
    twist, new = axes[gk.TWIST], axes[gk.NEW]
    dt = values[STEP_SETTINGS + 1]
    tool = flags[TOOL] != 0
    dv_stop = ik_table[IK_DV_STOP]
    max_step = values[MAX_STEP:MAX_STEP + 2]
    sk.check_feedback(sup_flags, sup_values, sup_joints, events, t, sequence, q, current,
                      wrench_base, q_cmd)
    if estimator_status < 0:
        sk.trip(sup_flags, sup_values, events, t, sk.F_ESTIMATOR, float(estimator_status), -1)
    if flags[KINEMATICS_NEW]:
        mu = gram_manipulability(jacobian, gram[0], gram[1])
        values[MANIPULABILITY] = mu
        values[DAMPING] = damping_of(mu, values[MU0], values[MAX_DAMPING])
        flags[KINEMATICS_NEW] = 0
    if flags[RESYNC]:
        copy_pose(fk_rotation, fk_position, rotations[CMD], positions[CMD])
        flags[RESIDUAL_FRESH] = 0
        flags[RESYNC] = 0
    if not flags[RESIDUAL_FRESH]:
        values[RESIDUAL] = log6_between(fk_rotation, fk_position, rotations[CMD],
                                        positions[CMD], err)
        flags[RESIDUAL_FRESH] = 1
    residual, mu = values[RESIDUAL], values[MANIPULABILITY]
    # cycles a stop gives the joints from the setpoint; computed where needed (-1: not yet)
    joint_stop = -1.0
    sk.check_motion(sup_flags, sup_values, sup_joints, events, t, mu, q_cmd, qd_cmd, residual)
    sk.deadman(sup_flags, events, t, deadman)
    scale = sk.speed_scale(sup_values, mu)
    control_wrench(wrench_base, fk_rotation, tool, sup_flags[sk.INPUTS_FINITE] != 0,
                   axes[gk.MASK], axes[gk.WRENCH])
    if sup_flags[sk.STATE] == sk.GUIDING:
        values[RELEASE_S] = gk.guiding_step(
            axes, flags[LAW_ID], values[LAW_ALPHA], values[STEP_SETTINGS:STEP_SETTINGS + 5],
            values[MAX_SPEED:MAX_SPEED + 2], max_step, scale, values[REST_S],
            values[RELEASE_S], not tool, rotations[CMD], positions[CMD], rotations[NEW],
            positions[NEW])
        if tool:
            _integrate(True, rotations, positions, new, dt)
        if sup_flags[sk.HAS_BOX]:
            joint_stop = joint_stop_cycles(qd_cmd, dv_stop)
            # a stop starting next cycle lasts at most this long: the Cartesian one, or the
            # joints' from the faster of their velocity and the one the twist asks for (ahead
            # while their acceleration holds them back), plus this cycle's step
            stop = max(twist_stop_cycles(twist, max_step), joint_stop,
                       joint_stop_cycles(qd_dls, dv_stop)) + 1.0
            p = positions[NEW]
            speed = math.sqrt(new[0] * new[0] + new[1] * new[1] + new[2] * new[2])
            clearance = sk.workspace_clearance(sup_flags, sup_values, p, speed, stop * dt)
            if clearance < 0.0:
                # stop from the last cycle's twist, as planned (and checked) there
                sk.trip(sup_flags, sup_values, events, t, sk.F_WORKSPACE, clearance, -1)
            else:
                values[STOP_PLAN] = stop
    if sup_flags[sk.STATE] != sk.GUIDING:
        if joint_stop < 0.0:
            joint_stop = joint_stop_cycles(qd_cmd, dv_stop)
        # at the joints' pace, but never longer than the stop the last check planned
        decelerate_twist(twist, max_step, min(joint_stop, values[STOP_PLAN]), new)
        values[STOP_PLAN] = max(values[STOP_PLAN] - 1.0, 0.0)
        _integrate(tool, rotations, positions, new, dt)
    # at rest: no twist, and joints slow enough to halt within one cycle's acceleration (else
    # the IK keeps tracking the held pose and brakes them at their limits)
    at_rest = is_zero(new)
    if at_rest and not is_zero(qd_cmd):
        if joint_stop < 0.0:
            joint_stop = joint_stop_cycles(qd_cmd, dv_stop)
        at_rest = joint_stop * values[STOP_FRACTION] <= 1.0
    sk.stopped(sup_flags, events, t, at_rest)
    for i in range(6):
        twist[i] = new[i]
    if at_rest:
        if values[REST_S] == 0.0:
            # came to rest (a reset or an earlier rest cycle did this already, and the setpoint
            # has not moved since): hold the setpoint bit for bit, its pose the target
            for j in range(q_cmd.size):
                qd_cmd[j] = 0.0
                qd_dls[j] = 0.0
            copy_pose(fk_rotation, fk_position, rotations[CMD], positions[CMD])
            flags[RESIDUAL_FRESH] = 0
            values[IK_SCALE] = 1.0
        values[REST_S] += dt
    else:
        values[REST_S] = 0.0
        copy_pose(rotations[NEW], positions[NEW], rotations[CMD], positions[CMD])
        q_next, qd_next = joints[Q_NEXT], joints[QD_NEXT]
        ik_scale, _ = ik_step(jacobian, gram, ik_table, ik_scratch, err, values[DAMPING], dt,
                              fk_rotation, fk_position, rotations[CMD], positions[CMD], q_cmd,
                              qd_cmd, qd_dls, qd_next, q_next)
        for j in range(q_cmd.size):
            q_cmd[j] = q_next[j]
            qd_cmd[j] = qd_next[j]
        flags[KINEMATICS_FRESH] = 0
        flags[RESIDUAL_FRESH] = 0
        flags[RESYNC] = 1 if ik_scale < 1.0 else 0
        values[IK_SCALE] = ik_scale
    values[SPEED_SCALE] = scale
    out_transform, out_six, out_q, out_qd = output_views(out_buffer, n)
    write_output(q_cmd, qd_cmd, rotations[CMD], positions[CMD], twist, tool, axes[gk.WRENCH],
                 axes[gk.FRICTION], axes[gk.STOP_FRICTION], out_q, out_qd, out_transform,
                 out_six[0], out_six[1], out_six[2], out_six[3], out_six[4])
    return sup_flags[sk.STATE]
