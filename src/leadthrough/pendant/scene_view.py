"""The pendant's 3D view: the robot, the measured TCP path, the estimated force as an arrow, the
taught points with the welding line P1 → P2, and on the simulator the handle the mouse pushes
the tool with (:mod:`leadthrough.pendant.push`).

All of it is drawn with viser's scene nodes (three.js in the browser): the robot once
(:class:`~leadthrough.pendant.robot_scene.RobotScene`), then only poses and small arrays per
update. The path is re-sent at most :data:`PATH_HZ` times a second.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.pendant.backend import MarkedPoint
from leadthrough.pendant.robot_scene import RobotScene
from leadthrough.robot.description import Robot
from leadthrough.teach.path import forward_tcp

__all__ = ["FORCE_M_PER_N", "PATH_HZ", "SceneView"]

Array = NDArray[np.float64]

#: Length of the force arrows per newton [m/N] (100 N: 0.4 m).
FORCE_M_PER_N = 0.004
#: Changes below which nothing is sent again: TCP position [m], forces [N] (the page's
#: updates are Python work in the loop's process).
SAME_M, SAME_N = 1e-4, 0.5
#: Largest rate at which the TCP path is re-sent [Hz].
PATH_HZ = 4.0
#: TCP positions kept for the path (the oldest dropped), and the spacing that adds one [m].
PATH_POINTS, PATH_STEP_M = 4000, 0.001
_LABEL_OFFSET = np.array([0.0, 0.0, 0.04])
_RED, _BLUE, _GREEN, _PATH = (215, 38, 38), (30, 90, 220), (20, 150, 70), (30, 30, 30)


class SceneView:
    """The 3D scene of the pendant.

    Args:
        server: The viser server.
        robot: The robot.
        simulated: Add the push handle (the robot is a simulation).
    """

    def __init__(self, server: Any, robot: Robot, simulated: bool) -> None:
        scene = self._scene = server.scene
        self.robot, self.robot_view = robot, RobotScene(scene, robot)
        scene.add_grid("/floor", width=3.0, height=3.0, cell_size=0.1, section_size=0.5)
        arrow = {"shaft_radius": 0.008, "head_radius": 0.022, "head_length": 0.05}
        self._force = scene.add_arrows("/force", np.zeros((1, 2, 3)), _RED, **arrow)
        self._push = (scene.add_arrows("/push", np.zeros((1, 2, 3)), _BLUE, **arrow)
                      if simulated else None)
        self._path: list[Array] = []
        self._path_sent = (0, 0.0)
        self._points: list[Any] = []
        self._lock = threading.Lock()
        #: Whether the push handle is being dragged, and its position then [m].
        self.dragging, self.handle_m, self._ended = False, np.zeros(3), False
        #: The page (viser client id) that dragged the handle last.
        self.drag_client: int | None = None
        self.tcp_m = np.full(3, np.inf)
        self._forces = np.full(6, np.inf)
        self.handle = None
        if simulated:
            self.handle = scene.add_transform_controls(
                "/push_handle", scale=0.2, line_width=4.0, disable_rotations=True,
                depth_test=False)
            self.handle.on_update(self._dragged)

    async def _dragged(self, event: Any) -> None:
        """A drag's start, moves and end, in order (viser awaits ``async`` callbacks on its
        event loop, one after the other; plain ones may run out of order on a pool)."""
        with self._lock:
            self.dragging = event.phase != "end"
            self._ended = self._ended or event.phase == "end"
            self.handle_m = np.asarray(event.target.position, dtype=float)
            self.drag_client = event.client_id

    def drag_state(self) -> tuple[bool, bool, Array]:
        """(dragging, a drag ended since the last call, handle position [m]) as of now."""
        with self._lock:
            ended, self._ended = self._ended, False
            return self.dragging, ended, self.handle_m.copy()

    def update(self, q: Array, force_n: Array, push_n: Array | None) -> Array:
        """Pose the robot at measured ``q`` [rad] and draw the forces at its TCP.

        Args:
            q: Measured joint positions [rad], shape (n,).
            force_n: Estimated force, base frame [N], shape (3,).
            push_n: The mouse's push [N], shape (3,), or None.

        Returns:
            The TCP position [m], shape (3,).
        """
        tcp = self.robot_view.show(q)[:3, 3].copy()
        moved = np.linalg.norm(tcp - self.tcp_m) >= SAME_M
        self.tcp_m = tcp
        forces = np.concatenate([force_n, push_n if push_n is not None else np.zeros(3)])
        if moved or np.max(np.abs(forces - self._forces)) >= SAME_N:
            self._forces = forces
            self._force.points = _arrow(tcp, force_n)
            if self._push is not None and push_n is not None:
                self._push.points = _arrow(tcp, push_n)
        if self.handle is not None and not self.dragging and moved:
            self.handle.position = tcp
        self._extend_path(tcp)
        return tcp

    def _extend_path(self, tcp: Array) -> None:
        if not self._path or np.linalg.norm(tcp - self._path[-1]) >= PATH_STEP_M:
            self._path.append(tcp)
            del self._path[:-PATH_POINTS]
        count, sent_at = self._path_sent
        now = time.monotonic()
        if len(self._path) >= 2 and count != len(self._path) and now - sent_at >= 1 / PATH_HZ:
            pts = np.asarray(self._path)
            self._scene.add_line_segments("/tcp_path", np.stack([pts[:-1], pts[1:]], axis=1),
                                          _PATH, thickness=0.004)
            self._path_sent = (len(self._path), now)

    def show_points(self, points: Sequence[MarkedPoint]) -> None:
        """Draw the taught points (spheres and names) and the welding line P1 → P2."""
        for node in self._points:
            node.remove()
        self._points = []
        if not points:
            return
        poses = forward_tcp(self.robot, np.array([p.q for p in points])).position_base
        for k, (p, at) in enumerate(zip(points, poses, strict=True)):
            self._points.append(self._scene.add_icosphere(f"/points/{k}", radius=0.012,
                                                          color=_GREEN, position=at))
            self._points.append(self._scene.add_label(f"/point_labels/{k}", p.label,
                                                      position=at + _LABEL_OFFSET))
        ends = {p.label: at for p, at in zip(points, poses, strict=True)}
        if "P1" in ends and "P2" in ends:
            line = np.stack([ends["P1"], ends["P2"]])[None]
            self._points.append(self._scene.add_line_segments("/points/line", line, _GREEN,
                                                              thickness=0.008))


def _arrow(start: Array, force_n: Array) -> Array:
    """One arrow from ``start`` along ``force_n``, :data:`FORCE_M_PER_N` long per newton."""
    return np.stack([start, start + FORCE_M_PER_N * np.asarray(force_n)])[None]
