"""Which inverse-kinematics branch a joint configuration is on: the shoulder, elbow and wrist
signs that robot controllers store with a Cartesian position (KUKA Status, FANUC configuration
string, ABB ``confdata.cfx``).

A 6-axis arm reaches most TCP poses with up to eight joint configurations (more with joints
that turn further than ±180°). The vendors single one out with three geometric indicators
plus the joint turns. This module computes the indicators for any robot file, from the joint
axes that Pinocchio gives (no DH table is assumed); :mod:`leadthrough.teach.programs.
configuration` encodes them in each vendor's format.

Axes ``A1 … A6`` are the robot's joints in order. Cartesian positions need a 6-axis arm whose
A2 and A3 are parallel and whose A5 can align A4 with A6 (every vendor arm, the built-in
``er20``, ``ur5``, ``ur10``); other robots get a clear error and export joint positions. A
7-axis arm is refused too: KUKA carries an LBR's redundancy as ``E1`` (the angle of joint 3), but
with joint 3 fixed the other six joints of e.g. the Panda have A2 not parallel to A3 and an offset
wrist, and on 3 of 30 random Panda poses two joint solutions shared the indicators and all joint
signs (measured with :mod:`leadthrough.robot.inverse_kinematics`), so no program could name the
taught joints.

Indicators (the vendors' definitions, generalised from their own geometry to any axes):

* **shoulder** ``s``: KUKA's Status bit 0 — the x value of the wrist point in the "A1
  coordinate system" (the base frame turned with A1): ``s < 0`` is KUKA's overhead area, ABB's
  "wrist centre behind axis 1", FANUC's ``B`` (back). The x axis of that frame is the direction
  ``±(z1 × z2)`` perpendicular to the axes of A1 and A2 (signed to point along the base x axis
  when A1 is at its zero: exactly KUKA's A1 frame on a vendor arm). The *wrist point* is the
  point of A6's axis closest to A5's axis: the wrist centre of a spherical wrist; on a UR-type
  wrist it is the point the analytic shoulder solution is computed for, so ``s`` changes sign
  exactly where the two shoulder solutions meet.
* **elbow** ``e``: KUKA's Status bit 1 (``A3 ≥ φ``, φ the A3 angle of the stretched arm), ABB's
  "wrist centre in front of / behind the lower arm": the sense of the bend at A3,
  ``e = (z1 × x1) · ((P3 − P2) × (W4 − P3))`` with P2, P3 the centres of A2 and A3 and W4 the point
  of A4's axis closest to A5's axis. ``e > 0``: the elbow above the line shoulder → wrist when
  the arm reaches forward ("elbow up"); the sign is intrinsic to the arm (it does not change
  when A1 turns the arm over to the back), as KUKA's axis-angle definition is.
* **wrist** ``w``: every vendor uses the sign of A5 (KUKA ``A5 ≤ 0``, ABB "axis 5 negative",
  FANUC flip). Generalised: ``w = wrap(q5 − q5⁰)`` in (−π, π], q5⁰ the A5 angle at which the axes
  of A4 and A6 are parallel (the wrist singularity; 0 on every vendor arm and on the built-in
  robots).

Sources: KUKA System Software 8.3, Operating and Programming Instructions for System
Integrators, section "Status" and "Turn" (quoted in robot-forum.com threads 7173 "x value of wrist
root point" and 13092 "KUKA KR5 Status and Turn bits"); Beckhoff TF5200 / ISG kernel
"Status & Turn (IS, IT)"; Siemens SINUMERIK programming manual 6FC5398-2EP40-0BA0, section 3.9
(STAT, TU); ABB RAPID reference manual, data type ``confdata``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.robot.description import Robot

__all__ = ["ArmStructure", "BranchValues", "arm_structure", "branch_values", "wrap_angle"]

Array = NDArray[np.float64]

_PARALLEL = 1e-6  # |sin| below which two axes count as parallel


class BranchValues(NamedTuple):
    """The branch indicators of one joint configuration (see the module docstring).

    Attributes:
        shoulder: x of the wrist point in the A1 frame [m] (< 0: overhead / back).
        elbow: Bend of the arm at A3 [m²] (> 0: elbow up in the forward reach).
        wrist: A5 angle from the wrist singularity, wrapped to (−π, π] [rad].
    """

    shoulder: float
    elbow: float
    wrist: float


@dataclass(frozen=True)
class ArmStructure:
    """The roles of a robot's joints for configuration data.

    Attributes:
        robot: Robot name.
        axes: Joint indices (0-based) of A1 … A6.
        forward_sign: +1 or −1: the sign that makes ``z1 × z2`` the A1 frame's x axis.
        wrist_zero: q5⁰, the A5 angle of the wrist singularity [rad], in (−π/2, π/2].
    """

    robot: str
    axes: tuple[int, ...]
    forward_sign: float
    wrist_zero: float


def wrap_angle(a: float) -> float:
    """An angle wrapped to (−π, π] [rad]."""
    w = math.remainder(a, 2.0 * math.pi)
    return math.pi if w == -math.pi else w


def _axes(robot: Robot, q: Array, data: pin.Data) -> tuple[Array, Array]:
    """Unit axis directions and their points closest to the origin, world frame, shape (n, 3)."""
    pin.computeJointJacobians(robot.model, data, q)
    J = data.J
    w = J[3:].T.copy()
    v = J[:3].T
    p = np.cross(w, v) / np.sum(w * w, axis=1)[:, None]
    return w / np.linalg.norm(w, axis=1)[:, None], p


def _cross(a: Array, b: Array) -> Array:
    """Cross product of two 3-vectors (``np.cross`` costs ~15 µs per call)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _closest_on_first(p1: Array, d1: Array, p2: Array, d2: Array) -> Array:
    """The point of line 1 (p1 + t·d1) closest to line 2; the foot of p2 if they are parallel."""
    n = _cross(d1, d2)
    nn = float(n @ n)
    if nn < _PARALLEL**2:
        return p1 + float((p2 - p1) @ d1) * d1
    t = float(_cross(p2 - p1, d2) @ n) / nn
    return p1 + t * d1


def _raw_values(s: ArmStructure, robot: Robot, q: Array, data: pin.Data) -> BranchValues:
    z, p = _axes(robot, q, data)
    a = s.axes
    x1 = s.forward_sign * _cross(z[a[0]], z[a[1]])
    norm = float(np.linalg.norm(x1))
    x1 = x1 / norm if norm > _PARALLEL else x1
    w6 = _closest_on_first(p[a[5]], z[a[5]], p[a[4]], z[a[4]])
    w4 = _closest_on_first(p[a[3]], z[a[3]], p[a[4]], z[a[4]])
    p2 = _closest_on_first(p[a[1]], z[a[1]], p[a[0]], z[a[0]])
    p3 = p[a[2]] + float((p2 - p[a[2]]) @ z[a[2]]) * z[a[2]]
    shoulder = float(x1 @ (w6 - p[a[0]]))
    elbow = float(_cross(z[a[0]], x1) @ _cross(p3 - p2, w4 - p3))
    return BranchValues(shoulder, elbow, wrap_angle(float(q[a[4]]) - s.wrist_zero))


def branch_values(structure: ArmStructure, robot: Robot, q: Array,
                  data: pin.Data | None = None) -> BranchValues:
    """The shoulder, elbow and wrist indicators of a joint configuration.

    Args:
        structure: From :func:`arm_structure`.
        robot: The robot.
        q: Joint positions [rad], shape (n,).
        data: Pinocchio data to reuse (optional).

    Returns:
        The indicators.
    """
    return _raw_values(structure, robot, np.asarray(q, dtype=float),
                       robot.model.createData() if data is None else data)


def _wrist_zero(robot: Robot, axes: tuple[int, ...], data: pin.Data) -> float:
    """q5⁰ from w(q5) = z5·(z4 × z6) = A·sin(q5 − q5⁰), which depends on q5 only."""
    q = robot.neutral()
    vals = []
    for q5 in (0.0, 0.5 * math.pi):
        q[axes[4]] = q5
        z, _ = _axes(robot, q, data)
        vals.append(float(z[axes[4]] @ _cross(z[axes[3]], z[axes[5]])))
    amplitude = math.hypot(vals[0], vals[1])
    if amplitude < 1e-3:
        raise TeachError("the axes of A4 and A6 never align: the wrist configuration (KUKA "
                         "Status bit 2, ABB cfx, FANUC flip) is undefined for this robot",
                         field="robot", value=robot.name,
                         expected="a wrist whose 5th axis is perpendicular to the 4th and "
                                  "6th; export joint positions instead (--joint-space)")
    zero = math.atan2(-vals[0], vals[1])
    if zero > 0.5 * math.pi + 1e-12:
        zero -= math.pi
    elif zero <= -0.5 * math.pi + 1e-12:
        zero += math.pi
    return zero


def arm_structure(robot: Robot) -> ArmStructure:
    """The roles of the robot's joints (A1 … A6) and the reference angles.

    Args:
        robot: A robot with 6 revolute joints.

    Returns:
        The structure.

    Raises:
        TeachError: Another number of joints, A2's axis parallel to A1's or not parallel to
            A3's, or a wrist whose 4th and 6th axes never align (the configuration would be
            undefined or would not single out one solution).
    """
    if robot.n == 7:
        raise TeachError("a 7-axis arm has no vendor configuration data that single out its "
                         "joints: with the redundancy parameter (joint 3, KUKA's E1) fixed, the "
                         "other six joints have A2 not parallel to A3, and shoulder, elbow, "
                         "wrist signs and turns leave several solutions", field="robot",
                         value=f"{robot.name} (7 joints)",
                         expected="a 6-axis arm for Cartesian positions; export joint "
                                  "positions instead (--joint-space)")
    if robot.n != 6:
        raise TeachError("Cartesian positions with configuration data need a 6-axis arm",
                         field="robot", value=f"{robot.name} ({robot.n} joints)",
                         expected="6 joints; export joint positions instead (--joint-space)")
    axes = (0, 1, 2, 3, 4, 5)
    data = robot.model.createData()
    q = robot.neutral()
    q[axes[0]] = 0.0
    z, _ = _axes(robot, q, data)
    x1 = _cross(z[axes[0]], z[axes[1]])
    if float(np.linalg.norm(x1)) < 1e-3:
        raise TeachError("the axes of A1 and A2 are parallel: the shoulder configuration is "
                         "undefined for this robot", field="robot", value=robot.name,
                         expected="A2 perpendicular to A1; export joint positions instead "
                                  "(--joint-space)")
    if float(np.linalg.norm(_cross(z[axes[1]], z[axes[2]]))) > 1e-6:
        raise TeachError("the axes of A2 and A3 are not parallel"
                         ": shoulder, elbow and wrist signs do not single out one joint "
                         "solution of a pose", field="robot", value=robot.name,
                         expected="a 6-axis arm with parallel A2 and A3 for Cartesian "
                                  "positions; export joint positions instead (--joint-space)")
    sign = float(np.sign(x1[0])) if abs(x1[0]) > 1e-9 else float(np.sign(x1[1]))
    return ArmStructure(robot=robot.name, axes=axes, forward_sign=sign,
                        wrist_zero=_wrist_zero(robot, axes, data))
