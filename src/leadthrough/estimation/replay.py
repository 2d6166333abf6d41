"""Replay a recording through an external force estimator, one sample at a time.

Offline validation of the real-time estimator on logged data (e.g. against an F/T sensor)::

    est = ExternalForceEstimator(robot, params, noise_mean, EstimatorConfig(dt=0.008))
    result = replay(est, recording)          # result.wrench: (N, 6) in the estimator's frame

The estimator assumes a fixed sample period, so the recording must be sampled uniformly at the
configured ``dt`` (resample jittery logs first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.errors import DataError
from leadthrough.estimation.estimator import ExternalForceEstimator

__all__ = ["ReplayResult", "replay"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ReplayResult:
    """The estimator's output at every sample of a recording.

    Attributes:
        time: Sample times [s], shape (N,).
        tau_ext: External joint torque [N·m], shape (N, n).
        wrench: External wrench at the TCP [N, N·m], force first, shape (N, 6), in the
            estimator's frame (``wrench_base`` or ``wrench_tool`` by its config).
        status: Status of each update (:class:`~leadthrough.estimation.estimator.Status`
            values), shape (N,).
    """

    time: Array
    tau_ext: Array
    wrench: Array
    status: NDArray[np.int64]


def replay(estimator: ExternalForceEstimator, rec: Recording, max_jitter: float = 0.05
           ) -> ReplayResult:
    """Reset the estimator at the first sample and feed it the whole recording.

    Args:
        estimator: The estimator (its state is reset).
        rec: The recording, sampled at the estimator's ``dt``; joint torques are converted to
            currents with the robot's R·Kt when the log holds torque.
        max_jitter: Largest deviation of a sample interval from ``dt``, as a fraction of it.

    Returns:
        The estimates.

    Raises:
        DataError: The recording does not fit the robot or is not sampled at ``dt``.
    """
    robot = estimator.robot
    rec.check_robot(robot)
    dt = estimator.config.dt
    gaps = np.diff(rec.time)
    worst = float(np.max(np.abs(gaps - dt)))
    if worst > max_jitter * dt:
        k = int(np.argmax(np.abs(gaps - dt)))
        raise DataError("not sampled at the estimator's period", source=rec.source,
                        field="time", value=f"interval {gaps[k]:.6g} s at row {k + 1}",
                        expected=f"every interval within {100 * max_jitter:g} % of dt = {dt:g}"
                                 " s (resample the log, or set EstimatorConfig.dt)")
    current = rec.current if rec.current is not None else robot.torque_to_current(
        rec.joint_torque(robot))
    n, N = robot.n, rec.samples
    tau = np.empty((N, n))
    wrench = np.empty((N, 6))
    status = np.empty(N, dtype=np.int64)
    inp, out = estimator.make_input(), estimator.make_output()
    estimator.reset(rec.q[0])
    for k in range(N):
        inp.t = float(rec.time[k])
        inp.q[:] = rec.q[k]
        inp.current[:] = current[k]
        status[k] = int(estimator.update(inp, out))
        tau[k] = out.tau_ext
        wrench[k] = out.wrench
    return ReplayResult(time=rec.time.copy(), tau_ext=tau, wrench=wrench, status=status)
