"""Build a MuJoCo model from a robot's Pinocchio model (one body per actuated joint).

The kinematic tree, joint axes and frames come from the same URDF through Pinocchio, so the two
libraries describe the same robot. Link inertias are passed in (nominal or the simulator's
"true" ones), and so are the joint-side rotor inertias (MuJoCo armature), viscous damping and
friction loss. An optional payload body is welded at the TCP.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot

__all__ = ["TCP_SITE", "Payload", "build_mujoco_model"]

TCP_SITE = "tcp"
_AXES = {
    "JointModelRX": (1.0, 0.0, 0.0),
    "JointModelRY": (0.0, 1.0, 0.0),
    "JointModelRZ": (0.0, 0.0, 1.0),
}


@dataclass(frozen=True)
class Payload:
    """A rigid payload welded at the TCP.

    Attributes:
        mass: Mass [kg], > 0.
        com_tcp: Centre of mass in the TCP frame [m], shape (3,).
        inertia_com: Rotational inertia about the CoM, in the TCP frame [kg·m²], shape (3, 3).
            Defaults to a solid 10 cm sphere of that mass.
    """

    mass: float
    com_tcp: tuple[float, float, float] = (0.0, 0.0, 0.05)
    inertia_com: tuple[tuple[float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass > 0.0):
            raise SimulationError("payload mass must be positive", field="payload.mass",
                                  value=self.mass, expected="a finite mass > 0 kg")
        if not np.all(np.isfinite(self.com_tcp)) or len(self.com_tcp) != 3:
            raise SimulationError("payload CoM must be 3 finite numbers", field="payload.com_tcp",
                                  value=self.com_tcp, expected="(x, y, z) in metres")

    def inertia_matrix(self) -> NDArray[np.float64]:
        """Rotational inertia about the CoM [kg·m²], shape (3, 3)."""
        if self.inertia_com is None:
            return np.eye(3) * 0.4 * self.mass * 0.05**2
        return np.asarray(self.inertia_com, dtype=float)

    def as_pin_inertia(self) -> pin.Inertia:
        """The payload as a Pinocchio inertia expressed in the TCP frame."""
        return pin.Inertia(self.mass, np.asarray(self.com_tcp, dtype=float), self.inertia_matrix())


def _joint_axis(jm: pin.JointModel) -> tuple[float, float, float]:
    name = jm.shortname()
    if name in _AXES:
        return _AXES[name]
    axis = np.asarray(jm.extract().axis, dtype=float)
    return (float(axis[0]), float(axis[1]), float(axis[2]))


def _set_inertial(body: mujoco.MjsBody, inertia: pin.Inertia) -> None:
    inertia_com = np.asarray(inertia.inertia, dtype=float)
    body.explicitinertial = True
    body.mass = float(inertia.mass)
    body.ipos = np.asarray(inertia.lever, dtype=float)
    body.fullinertia = [inertia_com[0, 0], inertia_com[1, 1], inertia_com[2, 2],
                        inertia_com[0, 1], inertia_com[0, 2], inertia_com[1, 2]]


def build_mujoco_model(
    robot: Robot,
    inertias: list[pin.Inertia] | None = None,
    *,
    armature: NDArray[np.float64] | None = None,
    damping: NDArray[np.float64] | None = None,
    timestep: float = 1e-3,
    payload: Payload | None = None,
    stop_margin: float = np.deg2rad(2.0),
) -> mujoco.MjModel:
    """Compile a MuJoCo model of a robot.

    Args:
        robot: The robot.
        inertias: Link inertias in joint order; default the URDF (nominal) ones.
        armature: Joint-side rotor inertia per joint [kg·m²], shape (n,); default 0.
        damping: Viscous joint damping [N·m·s/rad], shape (n,); default 0.
        timestep: Physics step [s].
        payload: Optional payload welded at the TCP.
        stop_margin: Mechanical end stops lie this far beyond the software limits [rad].

    Returns:
        The compiled model. Bodies are named after the joints; the TCP is site ``"tcp"``.

    Raises:
        SimulationError: MuJoCo rejects the model (e.g. inconsistent inertia).
    """
    model = robot.model
    n = robot.n
    inertias = inertias if inertias is not None else [model.inertias[j] for j in range(1, n + 1)]
    arm = np.zeros(n) if armature is None else np.asarray(armature, dtype=float)
    damp = np.zeros(n) if damping is None else np.asarray(damping, dtype=float)

    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.option.timestep = timestep
    spec.option.gravity = np.asarray(model.gravity.linear, dtype=float)
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.degree = False  # joint ranges in radians

    bodies: dict[int, mujoco.MjsBody] = {0: spec.worldbody}
    for j in range(1, n + 1):
        placement = model.jointPlacements[j]
        parent = bodies[int(model.parents[j])]
        quat = pin.Quaternion(placement.rotation)
        body = parent.add_body(
            name=model.names[j],
            pos=np.asarray(placement.translation, dtype=float),
            quat=[quat.w, quat.x, quat.y, quat.z],
        )
        _set_inertial(body, inertias[j - 1])
        k = j - 1
        lo, hi = robot.lower_limits[k] - stop_margin, robot.upper_limits[k] + stop_margin
        body.add_joint(
            name=model.names[j],
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=_joint_axis(model.joints[j]),
            range=[lo, hi],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            armature=float(arm[k]),
            damping=float(damp[k]),
        )
        bodies[j] = body

    frame = model.frames[robot.tcp_frame_id]
    tcp_body = bodies[int(frame.parentJoint)]
    quat = pin.Quaternion(frame.placement.rotation)
    tcp_pos = np.asarray(frame.placement.translation, dtype=float)
    tcp_quat = [quat.w, quat.x, quat.y, quat.z]
    tcp_body.add_site(name=TCP_SITE, pos=tcp_pos, quat=tcp_quat)
    if payload is not None:
        pl = tcp_body.add_body(name="payload", pos=tcp_pos, quat=tcp_quat)
        _set_inertial(pl, payload.as_pin_inertia())

    try:
        return spec.compile()
    except ValueError as e:
        raise SimulationError(f"MuJoCo rejected the model of '{robot.name}': {e}") from e
