"""Run a commanded joint trajectory on the simulated robot and log everything at 1 kHz.

The log keeps what a real controller reports (time, encoder q, measured current, commanded q)
apart from the simulator's truth (true q, q̇, current, external torque, applied wrench).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError, SimulationError
from leadthrough.sim.robot import SimRobot

__all__ = ["SimLog", "SimTruthLog", "hold", "run_trajectory"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SimTruthLog:
    """Simulator truth per sample.

    Attributes:
        q: True joint positions [rad], shape (N, n).
        qd: True joint velocities [rad/s], shape (N, n).
        current: Actual motor currents before the sensor [A], shape (N, n).
        external_torque: Joint torque of the operator's wrench, J^T·F [N·m], shape (N, n).
        wrench_base: Operator wrench at the TCP, base frame [N, N·m], shape (N, 6).
    """

    q: Array
    qd: Array
    current: Array
    external_torque: Array
    wrench_base: Array


@dataclass(frozen=True)
class SimLog:
    """What the simulated controller reports, plus the truth.

    Attributes:
        time: Sample times [s], shape (N,).
        q: Encoder joint positions [rad], shape (N, n).
        current: Measured motor currents [A], shape (N, n).
        q_cmd: Commanded joint positions [rad], shape (N, n).
        truth: Simulator truth (never available on a real robot).
    """

    time: Array
    q: Array
    current: Array
    q_cmd: Array
    truth: SimTruthLog


def run_trajectory(
    sim: SimRobot,
    q_cmd: Array,
    qd_cmd: Array | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SimLog:
    """Execute a position trajectory sampled at the simulator timestep.

    Args:
        sim: The simulated robot (its current state is the start).
        q_cmd: Commanded joint positions [rad], shape (N, n).
        qd_cmd: Velocity feed-forward [rad/s], shape (N, n); default none.
        progress: Called as ``progress(done, total)`` every 1000 samples.

    Returns:
        The log, one row per step.

    Raises:
        DataError: Shapes do not match the robot, or values are not finite.
        SimulationError: The simulation became unstable (MuJoCo reset it).
    """
    q_cmd = np.asarray(q_cmd, dtype=float)
    n = sim.robot.n
    if q_cmd.ndim != 2 or q_cmd.shape[1] != n or q_cmd.shape[0] < 1:
        raise DataError("trajectory has the wrong shape", field="q_cmd", value=q_cmd.shape,
                        expected=f"(N, {n}) joint positions")
    if qd_cmd is not None:
        qd_cmd = np.asarray(qd_cmd, dtype=float)
        if qd_cmd.shape != q_cmd.shape:
            raise DataError("velocity feed-forward does not match the positions",
                            field="qd_cmd", value=qd_cmd.shape, expected=str(q_cmd.shape))
    if not np.all(np.isfinite(q_cmd)) or (qd_cmd is not None and not np.all(np.isfinite(qd_cmd))):
        raise DataError("trajectory has non-finite values", field="q_cmd",
                        expected="finite joint positions and velocities")
    N = q_cmd.shape[0]
    t = np.empty(N)
    q = np.empty((N, n))
    cur = np.empty((N, n))
    tq = np.empty((N, n))
    tqd = np.empty((N, n))
    tcur = np.empty((N, n))
    text = np.empty((N, n))
    wr = np.empty((N, 6))
    data = sim.mj_data
    for k in range(N):
        sim.command(q_cmd[k], None if qd_cmd is None else qd_cmd[k])
        t[k] = data.time
        tq[k] = data.qpos
        tqd[k] = data.qvel
        sim.step()
        fb = sim.read()
        q[k] = fb.q
        cur[k] = fb.current
        tcur[k] = sim.true_current
        text[k] = sim.true_external_torque
        wr[k] = sim.applied_wrench
        if progress is not None and (k + 1) % 1000 == 0:
            progress(k + 1, N)
        if k and t[k] <= t[k - 1]:
            # MuJoCo resets a simulation whose accelerations blow up (mjWARN_BADQACC)
            raise SimulationError("the simulation became unstable and was reset by MuJoCo",
                                  field="step", value=f"t = {t[k - 1]:.3f} s",
                                  expected="a payload, force and motion the robot can carry")
    return SimLog(time=t, q=q, current=cur, q_cmd=q_cmd.copy(),
                  truth=SimTruthLog(q=tq, qd=tqd, current=tcur, external_torque=text,
                                    wrench_base=wr))


def hold(sim: SimRobot, duration: float) -> SimLog:
    """Hold the current command for ``duration`` seconds and log it.

    Args:
        sim: The simulated robot.
        duration: Hold time [s], > 0.

    Returns:
        The log.
    """
    if not duration > 0.0:
        raise DataError("hold duration must be positive", field="duration", value=duration,
                        expected="> 0 s")
    steps = max(1, round(duration / sim.config.timestep))
    q_cmd = np.repeat(sim.q_command[None, :], steps, axis=0)
    return run_trajectory(sim, q_cmd)
