"""Rigid motions of the guiding cycle, compiled (Numba, ``nopython``, cached on disk).

The guiding cycle works on poses given as a rotation R, shape (3, 3), and a position p [m],
shape (3,) (no ``pin.SE3`` objects: building one costs more than the arithmetic). These are the
few Lie-group operations it needs, with Pinocchio's conventions (twists linear first, the
``log6`` twist in the axes of the first pose); ``tests/test_control_kinematics.py`` checks each
against ``pin.log6``, ``pin.exp6`` and ``pin.exp3`` to 1e-12, near the identity and near a half
turn too.

* :func:`log6_between`: log6(T_a⁻¹·T_b), the twist (in T_a's axes) that moves T_a onto T_b in
  unit time: the IK's error and residual;
* :func:`integrate_tool`: T·exp6(ν·dt), a twist in tool axes held for dt;
* :func:`integrate_base`: a twist in base axes at the TCP held for dt: p + v·dt, exp3(ω·dt)·R;
* :func:`rotate_to_tool` / :func:`rotate_to_base`: a twist or wrench between base and tool axes;
* :func:`copy_pose`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["copy_pose", "integrate_base", "integrate_tool", "log6_between", "rotate_to_base",
           "rotate_to_tool"]

Array = NDArray[np.float64]

#: Below this angle [rad] the coefficients of exp and log use their Taylor series (the closed
#: forms cancel: at 0.1 rad they keep 13 digits, the series' first omitted term is < 1e-15).
_SERIES_ANGLE = 0.1


@njit(cache=True, nogil=True)
def _exp_coefficients(th2: float) -> tuple[float, float, float]:
    """sin θ/θ, (1 − cos θ)/θ² and (θ − sin θ)/θ³ for θ² = ``th2``."""
    th = math.sqrt(th2)
    if th < _SERIES_ANGLE:
        a = 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0 * (1.0 - th2 / 42.0))
        b = 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0 * (1.0 - th2 / 56.0))
        c = 1.0 / 6.0 - th2 / 120.0 * (1.0 - th2 / 42.0 * (1.0 - th2 / 72.0))
        return a, b, c
    s, co = math.sin(th), math.cos(th)
    return s / th, (1.0 - co) / th2, (th - s) / (th2 * th)


@njit(cache=True, nogil=True)
def _rotate_left(wx: float, wy: float, wz: float, a: float, b: float, rotation: Array,
                 rotation_out: Array, left: bool) -> None:
    """``rotation_out`` = E·R (``left``) or R·E, E = exp3(ω) = 1 + a·[ω]× + b·[ω]×² given a,
    b; ``rotation_out`` must not alias ``rotation``."""
    e00 = 1.0 - b * (wy * wy + wz * wz)
    e11 = 1.0 - b * (wx * wx + wz * wz)
    e22 = 1.0 - b * (wx * wx + wy * wy)
    e01, e10 = b * wx * wy - a * wz, b * wx * wy + a * wz
    e02, e20 = b * wx * wz + a * wy, b * wx * wz - a * wy
    e12, e21 = b * wy * wz - a * wx, b * wy * wz + a * wx
    if left:
        for c in range(3):
            r0, r1, r2 = rotation[0, c], rotation[1, c], rotation[2, c]
            rotation_out[0, c] = e00 * r0 + e01 * r1 + e02 * r2
            rotation_out[1, c] = e10 * r0 + e11 * r1 + e12 * r2
            rotation_out[2, c] = e20 * r0 + e21 * r1 + e22 * r2
    else:
        for r in range(3):
            r0, r1, r2 = rotation[r, 0], rotation[r, 1], rotation[r, 2]
            rotation_out[r, 0] = r0 * e00 + r1 * e10 + r2 * e20
            rotation_out[r, 1] = r0 * e01 + r1 * e11 + r2 * e21
            rotation_out[r, 2] = r0 * e02 + r1 * e12 + r2 * e22


@njit(cache=True, nogil=True)
def integrate_base(rotation: Array, position: Array, twist: Array, dt: float,
                   rotation_out: Array, position_out: Array) -> None:
    """Pose after one cycle of a base-axes twist at the TCP: p + v·dt, exp3(ω·dt)·R.

    Args:
        rotation: R, shape (3, 3).
        position: p [m], shape (3,).
        twist: (v, ω) in base axes [m/s, rad/s], shape (6,).
        dt: Duration [s].
        rotation_out: The new R, shape (3, 3); must not alias ``rotation``.
        position_out: The new p [m], shape (3,).
    """
    wx, wy, wz = twist[3] * dt, twist[4] * dt, twist[5] * dt
    a, b, _ = _exp_coefficients(wx * wx + wy * wy + wz * wz)
    _rotate_left(wx, wy, wz, a, b, rotation, rotation_out, True)
    for r in range(3):
        position_out[r] = position[r] + twist[r] * dt


@njit(cache=True, nogil=True)
def integrate_tool(rotation: Array, position: Array, twist: Array, dt: float,
                   rotation_out: Array, position_out: Array) -> None:
    """Pose after one cycle of a tool-axes twist: T·exp6(ν·dt).

    exp6(v, ω) = (exp3(ω), V(ω)·v) with V = 1 + (1 − cos θ)/θ²·[ω]× + (θ − sin θ)/θ³·[ω]×².

    Args:
        rotation: R, shape (3, 3).
        position: p [m], shape (3,).
        twist: ν = (v, ω) in tool axes [m/s, rad/s], shape (6,).
        dt: Duration [s].
        rotation_out: The new R, shape (3, 3); must not alias ``rotation``.
        position_out: The new p [m], shape (3,); must not alias ``position``.
    """
    vx, vy, vz = twist[0] * dt, twist[1] * dt, twist[2] * dt
    wx, wy, wz = twist[3] * dt, twist[4] * dt, twist[5] * dt
    a, b, c = _exp_coefficients(wx * wx + wy * wy + wz * wz)
    # V·v = v + b·ω×v + c·ω×(ω×v)
    cx, cy, cz = wy * vz - wz * vy, wz * vx - wx * vz, wx * vy - wy * vx
    dx, dy, dz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    tx, ty, tz = vx + b * cx + c * dx, vy + b * cy + c * dy, vz + b * cz + c * dz
    for r in range(3):
        position_out[r] = (position[r] + rotation[r, 0] * tx + rotation[r, 1] * ty
                           + rotation[r, 2] * tz)
    _rotate_left(wx, wy, wz, a, b, rotation, rotation_out, False)


@njit(cache=True, nogil=True)
def log6_between(rotation_a: Array, position_a: Array, rotation_b: Array, position_b: Array,
                 out: Array) -> float:
    """The twist log6(T_a⁻¹·T_b) in T_a's axes, linear first (``pin.log6``), and its norm.

    The rotation part goes through the unit quaternion of R = R_aᵀ·R_b (Shepperd's method,
    accurate at every angle up to a half turn), ω = 2·atan2(‖u‖, w)·u/‖u‖; the translation
    part is V(ω)⁻¹·p with p = R_aᵀ·(p_b − p_a) and
    V⁻¹ = 1 − ½·[ω]× + (1/θ² − cot(θ/2)/(2θ))·[ω]×².

    Args:
        rotation_a: R_a, shape (3, 3).
        position_a: p_a [m], shape (3,).
        rotation_b: R_b, shape (3, 3).
        position_b: p_b [m], shape (3,).
        out: (v, ω) [m, rad], shape (6,).

    Returns:
        √(‖v‖² + ‖ω‖²) [m and rad, mixed].
    """
    # R = R_aᵀ·R_b, p = R_aᵀ·(p_b − p_a)
    r00 = r01 = r02 = r10 = r11 = r12 = r20 = r21 = r22 = 0.0
    for i in range(3):
        a0, a1, a2 = rotation_a[i, 0], rotation_a[i, 1], rotation_a[i, 2]
        b0, b1, b2 = rotation_b[i, 0], rotation_b[i, 1], rotation_b[i, 2]
        r00 += a0 * b0
        r01 += a0 * b1
        r02 += a0 * b2
        r10 += a1 * b0
        r11 += a1 * b1
        r12 += a1 * b2
        r20 += a2 * b0
        r21 += a2 * b1
        r22 += a2 * b2
    d0 = position_b[0] - position_a[0]
    d1 = position_b[1] - position_a[1]
    d2 = position_b[2] - position_a[2]
    px = rotation_a[0, 0] * d0 + rotation_a[1, 0] * d1 + rotation_a[2, 0] * d2
    py = rotation_a[0, 1] * d0 + rotation_a[1, 1] * d1 + rotation_a[2, 1] * d2
    pz = rotation_a[0, 2] * d0 + rotation_a[1, 2] * d1 + rotation_a[2, 2] * d2
    # quaternion (w, x, y, z) of R, from its largest component (Shepperd)
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(max(1.0 + tr, 0.0))
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r11 - r00 - r22, 0.0))
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 + r22 - r00 - r11, 0.0))
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    u = math.sqrt(x * x + y * y + z * z)
    norm_q = math.sqrt(u * u + w * w)
    if u < 1e-6 * norm_q:
        # 2·atan2(u, w)/u = (2/w)·(1 − u²/(3w²) + …): the rest is below 1e-24
        k = 2.0 / w * (1.0 - u * u / (3.0 * w * w))
    else:
        k = 2.0 * math.atan2(u, w) / u
    wx, wy, wz = k * x, k * y, k * z
    th2 = wx * wx + wy * wy + wz * wz
    th = math.sqrt(th2)
    if th < _SERIES_ANGLE:
        beta = 1.0 / 12.0 + th2 / 720.0 * (1.0 + th2 / 42.0 * (1.0 + th2 / 40.0))
    else:
        beta = 1.0 / th2 - 0.5 * math.cos(0.5 * th) / (math.sin(0.5 * th) * th)
    # v = p − ½·ω×p + β·ω×(ω×p)
    cx, cy, cz = wy * pz - wz * py, wz * px - wx * pz, wx * py - wy * px
    dx, dy, dz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    out[0] = px - 0.5 * cx + beta * dx
    out[1] = py - 0.5 * cy + beta * dy
    out[2] = pz - 0.5 * cz + beta * dz
    out[3], out[4], out[5] = wx, wy, wz
    return math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + th2)


@njit(cache=True, nogil=True)
def copy_pose(rotation: Array, position: Array, rotation_out: Array, position_out: Array) -> None:
    """Copy a pose given as rotation, shape (3, 3), and position, shape (3,)."""
    for r in range(3):
        for c in range(3):
            rotation_out[r, c] = rotation[r, c]
        position_out[r] = position[r]


@njit(cache=True, nogil=True)
def rotate_to_tool(rotation: Array, base: Array, tool: Array) -> None:
    """A twist or wrench from base axes to tool axes: Rᵀ applied to each half (may not alias).

    Args:
        rotation: R, tool axes in the base frame, shape (3, 3).
        base: 6-vector in base axes.
        tool: Output 6-vector in tool axes.
    """
    for i in (0, 3):
        for r in range(3):
            tool[i + r] = (rotation[0, r] * base[i] + rotation[1, r] * base[i + 1]
                           + rotation[2, r] * base[i + 2])


@njit(cache=True, nogil=True)
def rotate_to_base(rotation: Array, tool: Array, base: Array) -> None:
    """A twist or wrench from tool axes to base axes: R applied to each half (may not alias)."""
    for i in (0, 3):
        for r in range(3):
            base[i + r] = (rotation[r, 0] * tool[i] + rotation[r, 1] * tool[i + 1]
                           + rotation[r, 2] * tool[i + 2])
