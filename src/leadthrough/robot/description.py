"""A robot: Pinocchio model from the URDF plus the drive data from the robot TOML.

Use :func:`load_robot` with a built-in name (``er20``, ``ur5``, ``ur10``, ``panda``) or a path to a
robot TOML file.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import RobotFileError, UnknownRobotError
from leadthrough.fileio import require_file
from leadthrough.robot.drive_file import DriveFile, JointDrive, parse_drive_file

__all__ = ["BUILTIN_ROBOTS", "Robot", "builtin_robot_path", "load_robot"]

_DATA_DIR = Path(__file__).parent / "data"
BUILTIN_ROBOTS: tuple[str, ...] = ("er20", "ur5", "ur10", "panda")

_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}


@dataclass(frozen=True, eq=False)
class Robot:
    """A robot description ready for dynamics and simulation.

    Attributes:
        name: Robot name.
        drive_file: The parsed robot TOML.
        model: Pinocchio model of the actuated joints (locked joints removed), nominal inertias.
        joints: Drive data per actuated joint, in Pinocchio joint order.
        tcp_frame: Name of the TCP / flange frame.
        tcp_frame_id: Pinocchio frame index of the TCP.
    """

    name: str
    drive_file: DriveFile
    model: pin.Model
    joints: tuple[JointDrive, ...]
    tcp_frame: str
    tcp_frame_id: int

    @property
    def n(self) -> int:
        """Number of actuated joints."""
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joint names, in order."""
        return tuple(j.name for j in self.joints)

    def _array(self, attr: str) -> NDArray[np.float64]:
        return np.array([float(getattr(j, attr)) for j in self.joints])

    @cached_property
    def gear_ratio(self) -> NDArray[np.float64]:
        """Gear ratios R [-], shape (n,)."""
        return self._array("gear_ratio")

    @cached_property
    def torque_constant(self) -> NDArray[np.float64]:
        """Motor torque constants Kt [N·m/A], shape (n,)."""
        return self._array("torque_constant")

    @cached_property
    def torque_per_amp(self) -> NDArray[np.float64]:
        """Joint torque per motor current R·Kt [N·m/A], shape (n,)."""
        return self.gear_ratio * self.torque_constant

    @cached_property
    def max_current(self) -> NDArray[np.float64]:
        """Max motor current [A], shape (n,)."""
        return self._array("max_current")

    @cached_property
    def max_torque(self) -> NDArray[np.float64]:
        """Max joint torque [N·m], shape (n,)."""
        return self._array("max_torque")

    @cached_property
    def lower_limits(self) -> NDArray[np.float64]:
        """Lower joint position limits [rad], shape (n,)."""
        return np.array([j.position_limits[0] for j in self.joints])

    @cached_property
    def upper_limits(self) -> NDArray[np.float64]:
        """Upper joint position limits [rad], shape (n,)."""
        return np.array([j.position_limits[1] for j in self.joints])

    @cached_property
    def velocity_limit(self) -> NDArray[np.float64]:
        """Joint speed limits [rad/s], shape (n,)."""
        return self._array("velocity_limit")

    @cached_property
    def acceleration_limit(self) -> NDArray[np.float64]:
        """Joint acceleration limits [rad/s²], shape (n,)."""
        return self._array("acceleration_limit")

    @cached_property
    def rotor_inertia(self) -> NDArray[np.float64]:
        """Motor-side rotor inertia [kg·m²], shape (n,)."""
        return self._array("rotor_inertia")

    @cached_property
    def reflected_rotor_inertia(self) -> NDArray[np.float64]:
        """Joint-side rotor inertia M_j = R²·J_motor [kg·m²], shape (n,)."""
        return self.gear_ratio**2 * self.rotor_inertia

    @cached_property
    def encoder_resolution(self) -> NDArray[np.float64]:
        """Joint-side encoder quantum [rad], shape (n,)."""
        return self._array("encoder_resolution")

    def current_to_torque(self, current: NDArray[np.float64]) -> NDArray[np.float64]:
        """Joint torque from motor current, τ = R·Kt·i.

        Args:
            current: Motor currents [A], shape (..., n).

        Returns:
            Joint torques [N·m], shape (..., n).
        """
        return np.asarray(current, dtype=float) * self.torque_per_amp

    def torque_to_current(self, torque: NDArray[np.float64]) -> NDArray[np.float64]:
        """Motor current producing a joint torque, i = τ / (R·Kt).

        Args:
            torque: Joint torques [N·m], shape (..., n).

        Returns:
            Motor currents [A], shape (..., n).
        """
        return np.asarray(torque, dtype=float) / self.torque_per_amp

    def neutral(self) -> NDArray[np.float64]:
        """Mid-range configuration clipped to 0 where 0 is inside the limits [rad], shape (n,)."""
        return np.clip(np.zeros(self.n), self.lower_limits, self.upper_limits)


def builtin_robot_path(name: str) -> Path:
    """Path of a built-in robot's TOML file.

    Raises:
        UnknownRobotError: ``name`` is not a built-in robot.
    """
    if name not in BUILTIN_ROBOTS:
        raise UnknownRobotError("unknown robot", field="robot", value=name,
                                expected=f"one of {', '.join(BUILTIN_ROBOTS)} or a robot TOML path")
    return _DATA_DIR / f"{name}.toml"


def load_robot(spec: str | Path = "er20") -> Robot:
    """Load a built-in robot by name, or a user robot from its TOML file.

    Args:
        spec: Built-in name (``er20``, ``ur5``, ``ur10``, ``panda``) or path to a robot TOML.

    Returns:
        The robot, with its Pinocchio model reduced to the actuated joints.

    Raises:
        UnknownRobotError: ``spec`` is neither a built-in name nor an existing file.
        RobotFileError: The URDF or TOML is invalid or they do not match.
    """
    text = str(spec)
    if text in BUILTIN_ROBOTS:
        path = builtin_robot_path(text)
    else:
        path = Path(text)
        if not path.exists():
            if path.suffix.lower() not in {".toml", ".urdf"} and "/" not in text:
                raise UnknownRobotError("unknown robot", field="robot", value=text,
                                        expected=f"one of {', '.join(BUILTIN_ROBOTS)} "
                                                 "or a path to a robot TOML file")
            require_file(path, "robot file", "an existing robot TOML file", RobotFileError)
        if path.suffix.lower() == ".urdf":
            raise RobotFileError("a robot is a TOML drive file that names its URDF", source=path,
                                 expected="the robot TOML file (with [robot] urdf = ...)")
    return _build(parse_drive_file(path))


def _build(drive: DriveFile) -> Robot:
    try:
        full = pin.buildModelFromUrdf(str(drive.urdf_path))
    except (RuntimeError, ValueError) as e:
        raise RobotFileError(f"URDF could not be parsed: {e}", source=drive.urdf_path) from e

    urdf_joints = [full.names[i] for i in range(1, full.njoints)]
    for jn in drive.locked_joints:
        if jn not in urdf_joints:
            raise RobotFileError("locked joint not in URDF", source=drive.path,
                                 field=f"robot.locked_joints.{jn}",
                                 expected=f"one of {urdf_joints}")
    for jn in drive.joints:
        if jn not in urdf_joints:
            raise RobotFileError("joint not in URDF", source=drive.path, field=f"joints.{jn}",
                                 expected=f"one of the URDF joints {urdf_joints}")
        if jn in drive.locked_joints:
            raise RobotFileError("joint is both driven and locked", source=drive.path,
                                 field=f"joints.{jn}", expected="either a drive or a lock")
    for jn in urdf_joints:
        if jn not in drive.joints and jn not in drive.locked_joints:
            raise RobotFileError("drive file is missing a joint", source=drive.path,
                                 field=f"joints.{jn}",
                                 expected=f"a [joints.{jn}] table or an entry in "
                                          "robot.locked_joints")

    model = full
    if drive.locked_joints:
        q_ref = pin.neutral(full)
        ids = []
        for jn, val in drive.locked_joints.items():
            jid = full.getJointId(jn)
            q_ref[full.joints[jid].idx_q] = val
            ids.append(jid)
        model = pin.buildReducedModel(full, ids, q_ref)

    joints: list[JointDrive] = []
    for i in range(1, model.njoints):
        jm = model.joints[i]
        jn = model.names[i]
        if jm.shortname() not in _REVOLUTE or jm.nq != 1:
            raise RobotFileError("unsupported joint type", source=drive.urdf_path,
                                 field=f"joint {jn}", value=jm.shortname(),
                                 expected="revolute joints with limits (lock other joints with "
                                          "robot.locked_joints)")
        jd = drive.joints[jn]
        lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
        tol = 1e-9
        if jd.position_limits[0] < lo - tol or jd.position_limits[1] > hi + tol:
            raise RobotFileError("position limits exceed the URDF limits", source=drive.path,
                                 field=f"joints.{jn}.position_limits",
                                 value=list(jd.position_limits),
                                 expected=f"within the URDF limits [{lo:.4f}, {hi:.4f}] rad")
        joints.append(jd)

    if not model.existFrame(drive.tcp_frame):
        frames = sorted({f.name for f in model.frames})
        raise RobotFileError("TCP frame not in URDF", source=drive.path, field="robot.tcp_frame",
                             value=drive.tcp_frame, expected=f"one of {frames}")
    # Apply the drive file's position limits to the Pinocchio model too, so that every consumer
    # (random sampling, IK) sees the same limits.
    model.lowerPositionLimit = np.array([j.position_limits[0] for j in joints])
    model.upperPositionLimit = np.array([j.position_limits[1] for j in joints])
    model.velocityLimit = np.array([j.velocity_limit for j in joints])
    model.effortLimit = np.array([j.max_torque for j in joints])
    return Robot(
        name=drive.name,
        drive_file=drive,
        model=model,
        joints=tuple(joints),
        tcp_frame=drive.tcp_frame,
        tcp_frame_id=int(model.getFrameId(drive.tcp_frame)),
    )
