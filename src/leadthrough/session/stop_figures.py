"""How a session's first fault ended, from its recording: the commanded TCP speed when the fault
latched, the largest commanded deceleration after it, the stop distance and time.

Three accelerations are measured, all of the *commanded* motion (what leadthrough sent, not
the robot's response):

* ``cycle_acc``: the guiding controller's Cartesian twist (``twist_cmd_base``), differenced
  over its own cycles: what the stop at the acceleration limit bounds;
* ``command_acc``: the TCP of the interpolated joint command (``q_cmd``, forward kinematics at
  each servo period), second-differenced with a lag of one controller cycle at every servo
  period: the command's acceleration averaged over a cycle;
* ``command_peak``: the same second-differenced at the servo period: the peak within a cycle.
  The interpolator (:class:`~leadthrough.control.interpolation.HermiteInterpolator`) commands
  the setpoints' quadratic B-spline: within each cycle the command accelerates at the
  setpoints' per-cycle rate, so at the limit a the peak is a too (it was up to 2.8a at 2 ms
  with cubics ending at the setpoints, before 2026-11-27). With one servo period per cycle
  (J519 at 8 ms) the samples are the setpoints' midpoints and all three coincide.

Both start one controller cycle before the fault (the last guided cycle's setpoint is where the
stop starts from) and run to the end of the recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.safety_states import Fault, State
from leadthrough.robot.description import Robot
from leadthrough.robot.inverse_kinematics import pose_of
from leadthrough.session_format import SessionLog

__all__ = ["StopFigures", "stop_figures"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StopFigures:
    """The first fault of a session and the commanded stop after it (see the module doc).

    Attributes:
        fault: The fault latched first (``Fault.NONE``: none).
        t_fault: The loop's time it latched [s] (NaN: none).
        speed_at_fault: Commanded TCP speed in the cycle before [m/s].
        cycle_acc: Largest commanded Cartesian acceleration of the controller's cycles from
            there on [m/s²].
        command_acc: Largest TCP acceleration of the interpolated joint command averaged over
            a controller cycle, from there on [m/s²].
        command_peak: Largest TCP acceleration of the interpolated joint command at the servo
            period, from there on [m/s²].
        distance: Commanded TCP travel from the fault to the end of the recording [m].
        stop_time: From the fault to the commanded motion's rest [s] (NaN: not at rest by the
            end of the recording).
        logged: A ``...->FAULT`` transition with the fault's name is among the events.
        latched_to_end: The fault state held to the end of the recording (a loop that ended
            on a lost link before its next controller cycle: the recording ended within a
            cycle of the fault).
    """

    fault: Fault
    t_fault: float
    speed_at_fault: float
    cycle_acc: float
    command_acc: float
    command_peak: float
    distance: float
    stop_time: float
    logged: bool
    latched_to_end: bool


def stop_figures(log: SessionLog, robot: Robot, cycle_s: float) -> StopFigures:
    """The figures of ``log``'s first fault (see :class:`StopFigures`).

    Args:
        log: A session's recording.
        robot: Its robot (forward kinematics of the joint command).
        cycle_s: The guiding controller's cycle [s] (a multiple of the servo period).
    """
    dt = float(log.time[1] - log.time[0]) if log.time.size > 1 else cycle_s
    every = max(1, round(cycle_s / dt))
    faulted = np.flatnonzero(log.state == int(State.FAULT))
    tripped = [e for e in log.events if e.kind == "transition" and e.label.endswith("FAULT")]
    if faulted.size:
        k, fault = int(faulted[0]), Fault(int(log.fault[faulted[0]]))
        latched = bool(np.all(log.state[k:] == int(State.FAULT)))
    elif tripped:       # the loop ended (link lost) before a controller cycle recorded it
        k = min(int(np.searchsorted(log.time, tripped[0].t)), log.time.size - 1)
        fault = Fault[tripped[0].cause.rsplit(":", 1)[-1]]
        latched = k >= log.time.size - every
    else:
        return StopFigures(Fault.NONE, math.nan, math.nan, math.nan, math.nan, math.nan,
                           math.nan, math.nan, False, False)
    start = max(k - every, 0)
    v = log.twist_cmd_base[start::every, :3]
    cycle_acc = (float(np.linalg.norm(np.diff(v, axis=0), axis=1).max()) / cycle_s
                 if len(v) > 1 else 0.0)
    data = robot.model.createData()
    p = np.array([pose_of(robot, q, data).translation for q in log.q_cmd[start:]])
    command_acc, command_peak = _second_difference(p, every, dt), _second_difference(p, 1, dt)
    distance = float(np.linalg.norm(np.diff(p[every:], axis=0), axis=1).sum()) if len(p) > every \
        else 0.0
    moving = np.flatnonzero(np.any(log.qd_cmd[k:] != 0.0, axis=1))
    rest = k + (int(moving[-1]) + 1 if moving.size else 0)
    stop_time = (float(log.time[rest] - log.time[k]) if rest < log.time.size else math.nan)
    logged = any(e.kind == "transition" and e.label.endswith("FAULT")
                 and e.cause.endswith(fault.name) for e in log.events)
    return StopFigures(fault, float(log.time[k]),
                       float(np.linalg.norm(log.twist_cmd_base[max(k - 1, 0), :3])),
                       cycle_acc, command_acc, command_peak, distance, stop_time, logged,
                       latched)


def _second_difference(p: Array, lag: int, step: float) -> float:
    """Largest |p[i + lag] - 2 p[i] + p[i - lag]| / (lag·step)² [m/s²] (0: too short)."""
    if len(p) <= 2 * lag:
        return 0.0
    second = p[2 * lag:] - 2 * p[lag:-lag] + p[:-2 * lag]
    return float(np.linalg.norm(second, axis=1).max()) / (lag * step) ** 2
