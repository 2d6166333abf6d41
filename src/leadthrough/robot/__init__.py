"""Robot descriptions: URDF + drive TOML (see :mod:`leadthrough.robot.drive_file`)."""

from leadthrough.robot.description import BUILTIN_ROBOTS, Robot, builtin_robot_path, load_robot
from leadthrough.robot.drive_file import DriveFile, JointDrive, parse_drive_file

__all__ = [
    "BUILTIN_ROBOTS",
    "DriveFile",
    "JointDrive",
    "Robot",
    "builtin_robot_path",
    "load_robot",
    "parse_drive_file",
]
