"""How long a joint command takes to show in the measured position: the command-to-position lag
of a robot's controller interface, measured on a recording that logged what was commanded.

A command sent in one controller cycle is taken by the controller in a later one, and the
encoders report the motion later still (the interface's transport, the controller's
interpolation, the servo's lag). The estimator's friction follows the commanded velocity (see
``EstimatorConfig.friction_velocity``); sent at once, that velocity reverses before the joint
does, so at a reversal the model's friction turns over that much before the gear's. Delayed by
this lag (``EstimatorConfig.command_lag``, ``DriveModelParameters.command_lag``), it turns
over with the gear.

The lag is what best aligns the measured position with the delayed command: per joint that
moved, the delay ``d`` minimising the variance of ``q(t) − q_cmd(t − d)`` (a variance, so that
a constant following error such as a servo's sag under gravity does not count), on a grid of the
recording's period from one period below 0, refined by a parabola through the minimum; the
recording's lag is the median over those joints, clipped at 0.

A recording's ``q_cmd`` row is the command sent in the cycle whose sample is that row
(``leadthrough record`` stores it so; the estimator's ``qd_cmd`` input is the same command),
so the lag is directly the estimator's delay. (A ``guide`` session log stores the command
computed after its sample, sent in the next cycle: measured on it, the lag comes out one cycle
longer.) Measured, never taken from the simulator: on the in-process simulator the command
written before a step is tracked in that step (lag 0), on the emulated controllers one cycle
later (8 ms J519, 2 ms RTDE, 4 ms RSI), on a real one whenever it is.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_COMMAND_LAG_S

__all__ = ["MIN_COMMANDED_RANGE_RAD", "CommandLag", "measure_command_lag"]

Array = NDArray[np.float64]

#: A joint counts only when its command spans at least this much [rad] (0.5°): a joint that
#: barely moves aligns with any delay.
MIN_COMMANDED_RANGE_RAD = np.deg2rad(0.5)


class CommandLag(NamedTuple):
    """The command-to-position lag of a recording.

    Attributes:
        lag_s: The median over the joints that moved [s], to 0.1 ms.
        joints_s: Each joint's lag [s], shape (n,); NaN where the joint did not move enough.
        period_s: The recording's median sample period [s].
    """

    lag_s: float
    joints_s: Array
    period_s: float


def measure_command_lag(rec: Recording, max_lag_s: float = MAX_COMMAND_LAG_S
                        ) -> CommandLag | None:
    """The command-to-position lag of ``rec`` (see the module docstring).

    Args:
        rec: A recording with ``q_cmd`` (``leadthrough record`` writes it).
        max_lag_s: Longest lag searched [s].

    Returns:
        The lag, or None where the recording has no commands, too few samples or no joint
        that moved at least :data:`MIN_COMMANDED_RANGE_RAD`.
    """
    if rec.q_cmd is None or rec.time.size < 20:
        return None
    t, q, q_cmd = rec.time, rec.q, rec.q_cmd
    period = float(np.median(np.diff(t)))
    steps = max(1, int(max_lag_s / period))
    # from one period before 0, so that a lag under half a period is refined like any other
    delays = np.asarray(np.arange(-1, steps + 1) * period, dtype=np.float64)
    inner = (t >= t[0] + delays[-1]) & (t <= t[-1] - period)
    if np.count_nonzero(inner) < 10:
        inner = t >= t[0] + 0.5 * (t[-1] - t[0])
        delays = delays[delays <= 0.5 * (t[-1] - t[0])]
    joints = np.full(q.shape[1], np.nan)
    for j in range(q.shape[1]):
        if np.ptp(q_cmd[:, j]) < MIN_COMMANDED_RANGE_RAD:
            continue
        cost = np.array([np.var(q[inner, j] - np.interp(t[inner] - d, t, q_cmd[:, j]))
                         for d in delays])
        joints[j] = max(0.0, _refined_minimum(delays, cost))
    moved = np.isfinite(joints)
    if not moved.any():
        return None
    # each joint's lag lies on the searched grid, from 0 to max_lag_s; to 0.1 ms: finer means
    # nothing at the 1-8 ms of a controller's cycle
    lag = round(float(np.median(joints[moved])), 4)
    return CommandLag(lag_s=lag, joints_s=joints, period_s=period)


def _refined_minimum(delays: Array, cost: Array) -> float:
    """The grid's minimum, refined by a parabola through it and its neighbours."""
    k = int(np.argmin(cost))
    if k == 0 or k == cost.size - 1:
        return float(delays[k])
    c0, c1, c2 = cost[k - 1], cost[k], cost[k + 1]
    curvature = c0 - 2.0 * c1 + c2
    if curvature <= 0:
        return float(delays[k])
    shift = 0.5 * (c0 - c2) / curvature
    return float(delays[k] + shift * (delays[k + 1] - delays[k]))
