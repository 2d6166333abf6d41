"""The robot TOML ("drive file"): per-joint drive data and which URDF it belongs to.

A robot is a URDF (kinematics and nominal "CAD" link inertias) plus this TOML file. Layout::

    [robot]
    name = "er20"                 # short name, recorded in params files
    urdf = "er20.urdf"            # path relative to this TOML file, or ...
    # urdf_package = "example-robot-data"   # ... a path inside an installed package
    tcp_frame = "flange"          # URDF link/frame used as TCP (flange)
    description = "free text"
    locked_joints = { finger_joint = 0.0 }  # optional: URDF joints frozen at a value

    [joints.joint_1]              # one table per actuated URDF joint, keyed by joint name
    gear_ratio = 147.0            # R, motor turns per joint turn [-], > 0
    torque_constant = 0.85        # Kt, motor torque per current [N·m/A], > 0
    max_current = 14.1            # [A], > 0
    max_torque = 1764.0           # joint side [N·m], > 0
    position_limits = [-3.05, 3.05]  # [rad], lower < upper
    velocity_limit = 2.9          # [rad/s], > 0
    acceleration_limit = 8.0      # [rad/s²], > 0
    encoder_counts = 131072       # counts per motor revolution, integer > 0
    rotor_inertia = 5.2e-4        # motor + gear input inertia, motor side [kg·m²], >= 0
    rated_power = 2000.0          # optional [W]

Every value is validated here, once; errors name the file, the field and the value.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from leadthrough.errors import RobotFileError
from leadthrough.fileio import require_file

__all__ = ["DriveFile", "JointDrive", "parse_drive_file"]


@dataclass(frozen=True)
class JointDrive:
    """Drive data of one joint (all joint-side unless stated).

    Attributes:
        name: URDF joint name.
        gear_ratio: Gear ratio R [-] (motor angle = R · joint angle).
        torque_constant: Motor torque constant Kt [N·m/A], motor side.
        max_current: Maximum motor current [A].
        max_torque: Maximum joint torque [N·m].
        position_limits: (lower, upper) joint position [rad].
        velocity_limit: Maximum joint speed [rad/s].
        acceleration_limit: Maximum joint acceleration [rad/s²].
        encoder_counts: Encoder counts per motor revolution [-].
        rotor_inertia: Motor rotor + gear input inertia, motor side [kg·m²].
        rated_power: Rated motor power [W], or None when not given.
    """

    name: str
    gear_ratio: float
    torque_constant: float
    max_current: float
    max_torque: float
    position_limits: tuple[float, float]
    velocity_limit: float
    acceleration_limit: float
    encoder_counts: int
    rotor_inertia: float
    rated_power: float | None = None

    @property
    def torque_per_amp(self) -> float:
        """Joint torque per motor current, R·Kt [N·m/A]."""
        return self.gear_ratio * self.torque_constant

    @property
    def encoder_resolution(self) -> float:
        """Joint-side position quantum of the motor encoder [rad]."""
        return 2.0 * math.pi / (self.encoder_counts * self.gear_ratio)


@dataclass(frozen=True)
class DriveFile:
    """Parsed robot TOML.

    Attributes:
        path: The TOML file.
        name: Robot name.
        urdf_path: Resolved URDF file.
        tcp_frame: URDF frame used as TCP / flange.
        description: Free text.
        locked_joints: URDF joints frozen at a fixed value [rad or m].
        joints: Drive data keyed by URDF joint name (file order).
    """

    path: Path
    name: str
    urdf_path: Path
    tcp_frame: str
    description: str
    locked_joints: dict[str, float]
    joints: dict[str, JointDrive]


def _positive(path: Path, field: str, value: Any, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise RobotFileError("not a number", source=path, field=field, value=value,
                             expected="a finite number >= 0" if allow_zero else
                             "a finite number > 0")
    v = float(value)
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        raise RobotFileError("out of range", source=path, field=field, value=value,
                             expected="a finite number >= 0" if allow_zero else
                             "a finite number > 0")
    return v


def _require(path: Path, table: dict[str, Any], key: str, prefix: str) -> Any:
    if key not in table:
        raise RobotFileError("missing", source=path, field=f"{prefix}{key}",
                             expected="the field to be present")
    return table[key]


def _resolve_urdf(path: Path, robot: dict[str, Any]) -> Path:
    urdf = _require(path, robot, "urdf", "robot.")
    if not isinstance(urdf, str) or not urdf:
        raise RobotFileError("not a path", source=path, field="robot.urdf", value=urdf,
                             expected="a non-empty string")
    package = robot.get("urdf_package")
    if package is not None:
        return _resolve_in_package(path, str(package), urdf)
    urdf_path = Path(urdf)
    if not urdf_path.is_absolute():
        urdf_path = path.parent / urdf_path
    require_file(urdf_path, "URDF file", "an existing URDF file", RobotFileError, source=path,
                 field="robot.urdf", value=str(urdf_path))
    return urdf_path


def _resolve_in_package(path: Path, package: str, relative: str) -> Path:
    import importlib.metadata as md

    try:
        files = md.files(package) or []
    except md.PackageNotFoundError as e:
        raise RobotFileError("package not installed", source=path, field="robot.urdf_package",
                             value=package, expected=f"'pip install {package}'") from e
    for f in files:
        if str(f).replace("\\", "/").endswith(relative):
            located = Path(str(f.locate()))
            if located.is_file():
                return located
    raise RobotFileError(f"not found in package '{package}'", source=path, field="robot.urdf",
                         value=relative, expected="a file shipped by that package")


def _parse_joint(path: Path, name: str, table: Any) -> JointDrive:
    prefix = f"joints.{name}."
    if not isinstance(table, dict):
        raise RobotFileError("not a table", source=path, field=f"joints.{name}", value=table,
                             expected="a [joints.NAME] table")
    known = {"gear_ratio", "torque_constant", "max_current", "max_torque", "position_limits",
             "velocity_limit", "acceleration_limit", "encoder_counts", "rotor_inertia",
             "rated_power"}
    for key in table:
        if key not in known:
            raise RobotFileError("unknown field", source=path, field=prefix + key,
                                 value=table[key], expected=f"one of {sorted(known)}")

    def num(key: str, allow_zero: bool = False) -> float:
        return _positive(path, prefix + key, _require(path, table, key, prefix),
                         allow_zero=allow_zero)

    limits = _require(path, table, "position_limits", prefix)
    if (not isinstance(limits, list) or len(limits) != 2
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in limits)):
        raise RobotFileError("malformed", source=path, field=prefix + "position_limits",
                             value=limits, expected="[lower, upper] in rad")
    lo, hi = float(limits[0]), float(limits[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise RobotFileError("lower must be below upper", source=path,
                             field=prefix + "position_limits", value=limits,
                             expected="finite lower < upper [rad]")
    counts = _require(path, table, "encoder_counts", prefix)
    if isinstance(counts, bool) or not isinstance(counts, int) or counts <= 0:
        raise RobotFileError("out of range", source=path, field=prefix + "encoder_counts",
                             value=counts, expected="an integer > 0")
    power = table.get("rated_power")
    return JointDrive(
        name=name,
        gear_ratio=num("gear_ratio"),
        torque_constant=num("torque_constant"),
        max_current=num("max_current"),
        max_torque=num("max_torque"),
        position_limits=(lo, hi),
        velocity_limit=num("velocity_limit"),
        acceleration_limit=num("acceleration_limit"),
        encoder_counts=int(counts),
        rotor_inertia=num("rotor_inertia", allow_zero=True),
        rated_power=None if power is None else _positive(path, prefix + "rated_power", power),
    )


def parse_drive_file(path: Path) -> DriveFile:
    """Read and validate a robot TOML file.

    Args:
        path: The robot TOML file.

    Returns:
        The parsed file, with the URDF path resolved.

    Raises:
        RobotFileError: The file is missing, is not TOML, or a field is missing or out of range.
    """
    path = Path(path)
    require_file(path, "robot file", "an existing robot TOML file", RobotFileError)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise RobotFileError(f"not valid TOML: {e}", source=path) from e
    robot = doc.get("robot")
    if not isinstance(robot, dict):
        raise RobotFileError("missing", source=path, field="robot",
                             expected="a [robot] table with name, urdf and tcp_frame")
    name = _require(path, robot, "name", "robot.")
    tcp = _require(path, robot, "tcp_frame", "robot.")
    for key, val in (("name", name), ("tcp_frame", tcp)):
        if not isinstance(val, str) or not val:
            raise RobotFileError("not a string", source=path, field=f"robot.{key}", value=val,
                                 expected="a non-empty string")
    locked_raw = robot.get("locked_joints", {})
    if not isinstance(locked_raw, dict):
        raise RobotFileError("malformed", source=path, field="robot.locked_joints",
                             value=locked_raw, expected="a table {joint = value}")
    locked: dict[str, float] = {}
    for jn, val in locked_raw.items():
        if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
            raise RobotFileError("not a number", source=path, field=f"robot.locked_joints.{jn}",
                                 value=val, expected="a finite joint value")
        locked[str(jn)] = float(val)
    joints_raw = doc.get("joints")
    if not isinstance(joints_raw, dict) or not joints_raw:
        raise RobotFileError("missing", source=path, field="joints",
                             expected="one [joints.NAME] table per actuated joint")
    joints = {str(jn): _parse_joint(path, str(jn), t) for jn, t in joints_raw.items()}
    return DriveFile(
        path=path,
        name=str(name),
        urdf_path=_resolve_urdf(path, robot),
        tcp_frame=str(tcp),
        description=str(robot.get("description", "")),
        locked_joints=locked,
        joints=joints,
    )
