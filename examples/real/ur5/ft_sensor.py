"""The external F/T sensor of the UR5 logs of Kufieta 2014 (../shared/data/ur5-ft), as ground truth.

The robot signals load through the normal data layer (``columns.toml``, one file per signal,
joined on time). The F/T sensor is logged by another process on its own clock:
``log_force_sensor.csv`` holds t_ft [s], Fx Fy Fz [N], Tx Ty Tz [N·m] in the sensor frame, not
tared, at ≈ 210 Hz with jitter. Clocks: t_unix = start_time + t_robot = ft_start + t_ft, but the
robot's start_time is rounded to 0.1 s or 0.01 s, so the nominal offset is refined by
cross-correlation (:func:`align_ft`).

Frames. The sensor's mounting is not documented. Its axes are taken as the axes of ``tool0`` of
the example-robot-data URDF with the same sign (``R_TOOL_SENSOR`` = identity): on the moving run
No9 the sensorless force at the TCP in tool0 axes correlates with +F_sensor (Fz: r ≈ +0.93).
So the sensor reports the force the operator applies to the robot. (The dataset's facts.toml
says "reaction sign, −F_sensor"; our estimator's sign is the force *on* the robot, checked in
simulation, and the data contradict the reaction sign.) A residual rotation of ~15° about z fits
the data better; it is not applied, because it would be fitted on the test data.

The sensor origin is unknown (somewhere beyond the flange), and the operator pushed close to it
(sensor torques ≤ 0.8 N·m for 50 N), so only the force axes are a meaningful comparison.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.data.align import LagEstimate, estimate_lag, resample
from leadthrough.data.io import load_recording
from leadthrough.data.preprocess import PreprocessConfig, preprocess
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import DriveModelParameters, model_torque
from leadthrough.errors import DataError
from leadthrough.robot import Robot, load_robot

__all__ = [
    "COLUMNS",
    "FOLDER",
    "RUNS",
    "R_TOOL_SENSOR",
    "FTLog",
    "align_ft",
    "load_ft_log",
    "load_run",
    "load_ur5",
    "offline_force_tool",
]

Array = NDArray[np.float64]
FOLDER = Path(__file__).resolve().parent
COLUMNS = FOLDER / "columns.toml"
R_TOOL_SENSOR: Array = np.eye(3)
RUNS = {
    "No9": "Movement_No9_Singularity_Free_ForceSensor",
    "No10_Fx": "Movement_No10_Standstill_ForceSensor_Fx",
    "No10_All": "Movement_No10_Standstill_ForceSensor_All",
    "No9_NoDist": "Movement_No9_Singularity_Free_NoDist",
    "No6": "Movement_No6_Acc_slow_Verify_Model",
}


@dataclass(frozen=True)
class FTLog:
    """An F/T sensor log on the robot's clock.

    Attributes:
        time: Sample times on the robot clock [s], shape (M,): t_ft − offset_s.
        wrench_sensor: [Fx, Fy, Fz, Tx, Ty, Tz] [N, N·m] in the sensor frame, shape (M, 6).
        offset_s: The F/T sample at t_ft = t_robot + offset_s belongs to t_robot [s]
            (nominal start-time difference, plus the refinement once aligned).
        tare: The bias subtracted from ``wrench_sensor`` [N, N·m], shape (6,).
        source: The log file.
    """

    time: Array
    wrench_sensor: Array
    offset_s: float
    tare: Array
    source: str

    def force_tool(self, t_robot: Array) -> Array:
        """Sensor force in tool0 axes at robot times [N], shape (len(t_robot), 3)."""
        return resample(self.time, self.wrench_sensor[:, :3], t_robot) @ R_TOOL_SENSOR.T

    def wrench_tool(self, t_robot: Array) -> Array:
        """Sensor wrench in tool0 axes at robot times [N, N·m], shape (len(t_robot), 6).

        The torque is about the sensor's (unknown) origin, not about tool0's.
        """
        w = resample(self.time, self.wrench_sensor, t_robot)
        return np.hstack([w[:, :3] @ R_TOOL_SENSOR.T, w[:, 3:] @ R_TOOL_SENSOR.T])

    def shifted(self, extra_s: float) -> FTLog:
        """The log with ``extra_s`` more offset (sample t_robot + extra_s now belongs to t)."""
        return replace(self, time=self.time - extra_s, offset_s=self.offset_s + extra_s)


def _read(path: Path, columns: int) -> Array:
    if not path.is_file():
        raise DataError("F/T log file not found", source=path, expected="an existing file")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # genfromtxt warns about cut-off lines
        raw = np.genfromtxt(path, delimiter=",", invalid_raise=False)
    if raw.ndim < 2:
        raw = raw.reshape(-1, 1) if columns == 1 else raw.reshape(1, -1)
    if raw.shape[1] != columns:
        raise DataError("wrong column count", source=path, field="columns",
                        value=raw.shape[1], expected=f"{columns}")
    raw = raw[np.isfinite(raw).all(axis=1)]
    if raw.shape[0] == 0:
        raise DataError("no complete row", source=path, expected="numbers")
    return raw


def load_ft_log(run: Path, tare_until_s: float = 1.0) -> FTLog:
    """Read a run's F/T log, put it on the robot clock (nominal offset) and tare it.

    Args:
        run: The run folder (holding ``log_force_sensor.csv`` and the start times).
        tare_until_s: The bias is the mean over robot time [0, tare_until_s) [s]: the
            recordings start at rest with nobody touching the robot.

    Returns:
        The tared log on the robot clock.

    Raises:
        DataError: Missing or malformed files, or no sample in the tare window.
    """
    data = _read(run / "log_force_sensor.csv", 7)
    start = float(_read(run / "start_time.csv", 1)[0, 0])
    ft_start = float(_read(run / "log_force_sensor_start_time.csv", 1)[0, 0])
    keep = np.concatenate([[True], np.diff(data[:, 0]) > 0])
    data = data[keep]
    offset = start - ft_start
    t = data[:, 0] - offset
    rest = t < tare_until_s
    if not rest.any():
        raise DataError("no F/T sample in the tare window", source=run, field="tare_until_s",
                        value=tare_until_s, expected=f"> {t[0]:.3f} s")
    bias = data[rest, 1:].mean(axis=0)
    return FTLog(time=t, wrench_sensor=data[:, 1:] - bias, offset_s=offset, tare=bias,
                 source=str(run / "log_force_sensor.csv"))


def load_ur5() -> Robot:
    """The UR5 of ``robot.toml`` (drive gains of the UR controller)."""
    return load_robot(FOLDER / "robot.toml")


def load_run(data: Path, name: str) -> Recording:
    """A run's robot signals (q, current) through the data layer; ``name`` a key of RUNS."""
    if name not in RUNS:
        raise DataError("unknown run", field="run", value=name, expected=f"one of {list(RUNS)}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # cut-off last lines, dropped unpaired rows
        rec = load_recording(data / RUNS[name], COLUMNS)
    return Recording(time=rec.time, q=rec.q, current=rec.current, robot="ur5",
                     source=rec.source)


def offline_force_tool(robot: Robot, params: DriveModelParameters, rec: Recording,
                       cutoff_hz: float = 10.0) -> tuple[Array, Array]:
    """Zero-phase sensorless force at the TCP in tool0 axes, for time alignment only.

    τ_ext = τ̂_d(q, q̇, q̈) − τ_j from zero-phase filtered signals (no filter delay), then the
    force F minimising ‖J_vᵀ·F − τ_ext‖ with the tool0 Jacobian (LOCAL).

    Returns:
        Times [s], shape (N,), and force_tool [N], shape (N, 3).
    """
    cfg = PreprocessConfig(position_cutoff_hz=cutoff_hz, torque_cutoff_hz=cutoff_hz,
                           decimate_to_hz=None, trim_s=0.0)
    p = preprocess(rec, robot, cfg)
    tau_ext = model_torque(robot, params, p.q, p.qd, p.qdd) - p.torque
    data = robot.model.createData()
    force = np.empty((p.samples, 3))
    for k in range(p.samples):
        J = pin.computeFrameJacobian(robot.model, data, p.q[k], robot.tcp_frame_id, pin.LOCAL)
        force[k] = np.linalg.lstsq(J[:3].T, tau_ext[k], rcond=None)[0]
    return p.time, force


def align_ft(ft: FTLog, t_est: Array, force_est: Array, max_lag_s: float = 0.3
             ) -> tuple[FTLog, LagEstimate]:
    """Refine the clock offset by cross-correlating ‖F‖ of the sensor and of an estimate.

    Args:
        ft: The F/T log (nominal offset).
        t_est: Robot times of the estimate [s], shape (N,).
        force_est: A delay-free force estimate [N], shape (N, 3) (:func:`offline_force_tool`).
        max_lag_s: Largest refinement tried [s] (the start time's rounding is ≤ 0.05 s).

    Returns:
        The log shifted by the lag found, and the lag estimate.
    """
    lag = estimate_lag(t_est, np.linalg.norm(force_est, axis=1), ft.time,
                       np.linalg.norm(ft.wrench_sensor[:, :3], axis=1), max_lag_s=max_lag_s,
                       step_s=0.002)
    return ft.shifted(lag.lag_s), lag
