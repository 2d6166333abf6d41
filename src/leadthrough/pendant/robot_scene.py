"""The robot in the pendant's 3D view: its URDF's visual geometry, posed by Pinocchio.

The URDF is parsed with yourdfpy (the URDF library viser's own ``ViserUrdf`` uses), each link's
visual elements (meshes, boxes, cylinders, spheres, with their origins and colours) become one
trimesh in the link's frame, and each is added to the viser scene once
(``add_mesh_trimesh``). A new joint configuration then only moves those nodes: the link poses
are Pinocchio's forward kinematics of the controller's model (``framesForwardKinematics``), the
model the estimator and the controller use, so the view shows the robot the loop computes with.

A URDF without visual geometry (the built-in er20 carries only kinematics and inertias) is drawn
from its kinematics instead: per link a cylinder from the link's origin to each child joint and
a housing around each joint axis, with radii growing with the link's mass. Unresolvable mesh
files are skipped with a warning (the rest of the robot is still drawn).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import trimesh
import yourdfpy
from numpy.typing import NDArray

from leadthrough.errors import DataWarning, RobotFileError
from leadthrough.robot.description import Robot

__all__ = ["LinkMesh", "RobotScene", "link_meshes"]

Array = NDArray[np.float64]

#: Joint motion below which the drawn robot is not moved again [rad] (0.01 mm at 1 m).
SAME_Q_RAD = 1e-5
#: Colour of generated links (RGBA 0–255): an industrial orange, and dark joint housings.
_LINK_RGBA = (236, 112, 20, 255)
_JOINT_RGBA = (60, 60, 64, 255)


@dataclass(frozen=True)
class LinkMesh:
    """The visual geometry of one link, in the link's frame.

    Attributes:
        link: Link name (a Pinocchio ``BODY`` frame of the robot's model).
        mesh: The geometry [m].
    """

    link: str
    mesh: trimesh.Trimesh


def link_meshes(robot: Robot) -> list[LinkMesh]:
    """The visual geometry of every link of a robot's URDF (generated if it has none).

    Raises:
        RobotFileError: The URDF cannot be parsed.
    """
    path = Path(robot.drive_file.urdf_path)
    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False)
    except Exception as e:  # yourdfpy raises what lxml and its own checks raise
        raise RobotFileError(f"URDF could not be read: {e}", source=path) from e
    resolve = partial(yourdfpy.filename_handler_magic, dir=str(path.parent))
    known = {f.name for f in robot.model.frames}
    meshes = []
    for link in urdf.robot.links:
        parts = [m for v in link.visuals if (m := _visual_mesh(v, resolve, path)) is not None]
        if parts and link.name in known:
            meshes.append(LinkMesh(link.name, _joined(parts)))
    return meshes if meshes else _generated_meshes(urdf, known)


def _visual_mesh(visual: Any, resolve: Any, urdf: Path) -> trimesh.Trimesh | None:
    """One ``<visual>`` as a mesh in its link's frame, coloured; None if not drawable."""
    g = visual.geometry
    if g.box is not None:
        mesh = trimesh.creation.box(extents=g.box.size)
    elif g.cylinder is not None:
        mesh = trimesh.creation.cylinder(radius=g.cylinder.radius, height=g.cylinder.length)
    elif g.sphere is not None:
        mesh = trimesh.creation.icosphere(radius=g.sphere.radius)
    elif g.mesh is not None:
        mesh = _load_mesh(resolve(g.mesh.filename), urdf)
        if mesh is None:
            return None
        if g.mesh.scale is not None:
            mesh.apply_scale(g.mesh.scale)
    else:
        return None
    if visual.origin is not None:
        mesh.apply_transform(visual.origin)
    color = getattr(getattr(visual, "material", None), "color", None)
    if color is not None and color.rgba is not None:
        return _colored(mesh, tuple(round(255 * c) for c in color.rgba))
    return mesh


def _load_mesh(filename: str, urdf: Path) -> trimesh.Trimesh | None:
    try:
        loaded = trimesh.load(filename, force="mesh")
    except Exception as e:  # trimesh raises many kinds; the robot is drawn without this part
        warnings.warn(f"{urdf}: mesh {filename} not drawn ({e})", DataWarning, stacklevel=3)
        return None
    return loaded if isinstance(loaded, trimesh.Trimesh) else None


def _generated_meshes(urdf: Any, known: set[str]) -> list[LinkMesh]:
    """A URDF without visuals drawn from its kinematics (see the module doc)."""
    masses = {link.name: (link.inertial.mass if link.inertial is not None else 1.0)
              for link in urdf.robot.links}
    parts: dict[str, list[trimesh.Trimesh]] = {name: [] for name in masses}
    for joint in urdf.robot.joints:
        origin = joint.origin if joint.origin is not None else np.eye(4)
        r = _radius(masses.get(joint.parent, 1.0))
        start, end = np.zeros(3), origin[:3, 3]
        if np.linalg.norm(end - start) > 1e-6:
            limb = trimesh.creation.cylinder(radius=r, segment=np.stack([start, end]))
            parts[joint.parent].append(_colored(limb, _LINK_RGBA))
            parts[joint.parent].append(_colored(trimesh.creation.icosphere(radius=r),
                                                _LINK_RGBA))
        if joint.type in ("revolute", "continuous", "prismatic") and joint.axis is not None:
            axis = np.asarray(joint.axis, dtype=float)
            rc = 1.15 * _radius(masses.get(joint.child, 1.0))
            housing = trimesh.creation.cylinder(radius=rc, segment=np.stack(
                [-1.2 * rc * axis, 1.2 * rc * axis]))
            parts[joint.child].append(_colored(housing, _JOINT_RGBA))
    children = {joint.child for joint in urdf.robot.joints}
    for name in masses.keys() - children:      # the root: a pedestal under its origin
        r = 1.4 * _radius(masses[name])
        parts[name].append(_colored(trimesh.creation.cylinder(
            radius=r, segment=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.6 * r]])), _JOINT_RGBA))
    return [LinkMesh(name, _joined(p)) for name, p in parts.items() if p and name in known]


def _radius(mass: float) -> float:
    """Radius of a generated limb of a link of ``mass`` [kg] [m]."""
    return 0.02 + 0.01 * math.sqrt(max(mass, 0.0))


def _colored(mesh: trimesh.Trimesh, rgba: tuple[int, ...]) -> trimesh.Trimesh:
    """``mesh`` in one colour (RGBA 0–255); a textured mesh loses its texture."""
    mesh.visual = trimesh.visual.ColorVisuals(mesh=mesh, face_colors=np.array(rgba, np.uint8))
    return mesh


def _joined(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One mesh of several (their colours kept)."""
    joined = trimesh.util.concatenate(parts)
    return joined if isinstance(joined, trimesh.Trimesh) else trimesh.Trimesh()


class RobotScene:
    """The robot as nodes of a viser scene, moved to a joint configuration by :meth:`show`.

    Args:
        scene: A viser scene (``ViserServer.scene``).
        robot: The robot.
        root: Name of the robot's node in the scene tree.
    """

    def __init__(self, scene: Any, robot: Robot, root: str = "/robot") -> None:
        self.robot = robot
        self._model = robot.model
        self._data = robot.model.createData()
        self._nodes = []
        self._shown: Array | None = None
        for part in link_meshes(robot):
            node = scene.add_mesh_trimesh(f"{root}/{part.link}", part.mesh)
            self._nodes.append((self._model.getFrameId(part.link, pin.BODY), node))

    def show(self, q: Array) -> Array:
        """Pose the robot at joint positions ``q`` [rad], shape (n,).

        Returns:
            The TCP pose, shape (4, 4) [m] (Pinocchio's forward kinematics of ``q``).

        The scene is only sent new poses when a joint moved by :data:`SAME_Q_RAD` or more
        since the last ones (every update is Python work in the loop's process).
        """
        pin.framesForwardKinematics(self._model, self._data, q)
        if self._shown is not None and np.max(np.abs(q - self._shown)) < SAME_Q_RAD:
            return np.asarray(self._data.oMf[self.robot.tcp_frame_id].homogeneous)
        self._shown = np.array(q, dtype=float)
        for frame_id, node in self._nodes:
            placement = self._data.oMf[frame_id]
            quat = pin.Quaternion(placement.rotation)
            node.position = placement.translation
            node.wxyz = (quat.w, quat.x, quat.y, quat.z)
        return np.asarray(self._data.oMf[self.robot.tcp_frame_id].homogeneous)
