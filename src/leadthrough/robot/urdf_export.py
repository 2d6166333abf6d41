"""Write a URDF carrying identified link inertias.

Pinocchio merges links attached by fixed (or locked) joints into the actuated link before them;
the identified parameters describe that merged body, expressed in the actuated joint's frame (the
URDF child-link frame). The export therefore puts the whole identified inertia on the actuated
joint's child link and removes the ``<inertial>`` of the links merged into it. Everything else in
the URDF is kept as it is.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import DataError, RobotFileError
from leadthrough.fileio import atomic_write
from leadthrough.robot.description import Robot

__all__ = ["write_urdf_with_inertias"]


def _fmt(v: float) -> str:
    return repr(float(v))


def write_urdf_with_inertias(robot: Robot, phi: NDArray[np.float64], path: str | Path) -> Path:
    """Copy the robot's URDF with the link inertias replaced by ``phi``.

    Args:
        robot: The robot (its URDF is the template).
        phi: Standard link parameters, shape (10·n,); must be physically consistent (m > 0).
        path: Output URDF.

    Returns:
        The path written.

    Raises:
        DataError: ``phi`` has the wrong size or a non-positive mass.
        RobotFileError: The template URDF cannot be parsed.
    """
    phi = np.asarray(phi, dtype=float)
    if phi.shape != (10 * robot.n,):
        raise DataError("wrong number of link parameters", field="phi", value=phi.shape,
                        expected=f"({10 * robot.n},)")
    try:
        tree = ET.parse(robot.drive_file.urdf_path)
    except ET.ParseError as e:
        raise RobotFileError(f"URDF could not be parsed: {e}",
                             source=robot.drive_file.urdf_path) from e
    root = tree.getroot()
    links = {el.get("name"): el for el in root.findall("link")}
    joints = root.findall("joint")
    children: dict[str, list[tuple[str, str]]] = {}
    child_of: dict[str, str] = {}
    for jel in joints:
        parent = jel.find("parent")
        child = jel.find("child")
        if parent is None or child is None:
            continue
        children.setdefault(str(parent.get("link")), []).append(
            (str(jel.get("name")), str(child.get("link"))))
        child_of[str(jel.get("name"))] = str(child.get("link"))
    actuated = set(robot.joint_names)
    for k, jn in enumerate(robot.joint_names):
        inertia = pin.Inertia.FromDynamicParameters(phi[10 * k:10 * k + 10].copy())
        if not inertia.mass > 0:
            raise DataError("link mass must be positive", field=f"links.{jn}.m",
                            value=float(inertia.mass), expected="> 0 kg")
        link_name = child_of[jn]
        link = links[link_name]
        # Remove inertials of links merged into this one (fixed/locked descendants).
        stack = [c for j2, c in children.get(link_name, []) if j2 not in actuated]
        while stack:
            name = stack.pop()
            el = links.get(name)
            if el is not None:
                for old in el.findall("inertial"):
                    el.remove(old)
            stack += [c for j2, c in children.get(name, []) if j2 not in actuated]
        for old in link.findall("inertial"):
            link.remove(old)
        inertial = ET.SubElement(link, "inertial")
        c = np.asarray(inertia.lever)
        ET.SubElement(inertial, "origin", xyz=" ".join(_fmt(v) for v in c), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=_fmt(inertia.mass))
        ic = np.asarray(inertia.inertia)
        ET.SubElement(inertial, "inertia", ixx=_fmt(ic[0, 0]), ixy=_fmt(ic[0, 1]),
                      ixz=_fmt(ic[0, 2]), iyy=_fmt(ic[1, 1]), iyz=_fmt(ic[1, 2]),
                      izz=_fmt(ic[2, 2]))
    root.insert(0, ET.Comment(" link inertias identified by leadthrough "))

    def write(tmp: Path) -> None:
        ET.indent(tree)
        tree.write(tmp, encoding="utf-8", xml_declaration=True)

    return atomic_write(path, write)
