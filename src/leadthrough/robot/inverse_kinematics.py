"""Inverse kinematics of the TCP pose: damped Newton (Levenberg–Marquardt) on SE(3) for any robot
file, with the branch selected by a predicate (a vendor configuration) or by a nearby joint
configuration (a UR controller's ``get_inverse_kin(pose, qnear)``).

Newton step on the pose error ``e = log6(T(q)⁻¹ · T*)`` (Pinocchio ``log6``) with the frame
Jacobian mapped through ``Jlog6``, as in Pinocchio's inverse-kinematics example
(``examples/inverse-kinematics.py`` of stack-of-tasks/pinocchio); the damping follows
Levenberg–Marquardt: λ shrinks after a step that lowers ‖e‖ and grows after one that does not
(rejected).

A pose has several solutions. :func:`solve_pose` starts from seeds drawn inside a box (the
joint limits intersected with the windows a configuration allows) whose own configuration
already matches (``accept``), nearest pose first, and returns every distinct converged solution
that ``accept`` takes: none means the pose cannot be reached in that configuration, two mean
the configuration does not single out one joint solution.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.robot.description import Robot

__all__ = ["IkResult", "newton_pose", "pose_of", "solve_near", "solve_pose"]

Array = NDArray[np.float64]

TOLERANCE = 1e-10  # ‖log6‖ at convergence [m, rad]
_MAX_ITER = 80
_DISTINCT = 1e-6  # [rad] two solutions closer than this are the same
BOX_SLACK = 1e-6  # [rad] a solution this far outside its box (a joint taught at exactly 0° and
# solved at −1e-11 rad, against a window [0°, 90°)) still counts as inside


class IkResult(NamedTuple):
    """One Newton run.

    Attributes:
        q: Final joint positions [rad], shape (n,).
        error: Final ‖log6(T(q)⁻¹ T*)‖ [m, rad].
        iterations: Newton steps taken.
    """

    q: Array
    error: float
    iterations: int

    @property
    def converged(self) -> bool:
        """True if the pose error is below the tolerance."""
        return self.error < TOLERANCE


def pose_of(robot: Robot, q: Array, data: pin.Data | None = None) -> pin.SE3:
    """TCP placement in the base frame for joint positions ``q`` [rad]."""
    data = robot.model.createData() if data is None else data
    pin.forwardKinematics(robot.model, data, np.asarray(q, dtype=float))
    return pin.updateFramePlacement(robot.model, data, robot.tcp_frame_id).copy()


def _error(robot: Robot, data: pin.Data, q: Array, target: pin.SE3) -> tuple[pin.SE3, Array]:
    pin.forwardKinematics(robot.model, data, q)
    err_pose = pin.updateFramePlacement(robot.model, data, robot.tcp_frame_id).actInv(target)
    return err_pose, pin.log6(err_pose).vector


def newton_pose(robot: Robot, target: pin.SE3, q0: Array, *, free: Array | None = None,
                data: pin.Data | None = None, max_iter: int = _MAX_ITER) -> IkResult:
    """Levenberg–Marquardt on SE(3) from ``q0``.

    Args:
        robot: The robot (its TCP frame).
        target: Desired TCP placement in the base frame.
        q0: Start [rad], shape (n,).
        free: Indices of the joints that move (default: all).
        data: Pinocchio data to reuse.
        max_iter: Step limit.

    Returns:
        The last iterate and its pose error (see :attr:`IkResult.converged`).
    """
    data = robot.model.createData() if data is None else data
    cols = np.arange(robot.n) if free is None else np.asarray(free)
    q = np.array(q0, dtype=float)
    err_pose, e = _error(robot, data, q, target)
    cost, lam = float(e @ e), 1e-3
    for it in range(max_iter):
        if math.sqrt(cost) < TOLERANCE:
            return IkResult(q, math.sqrt(cost), it)
        J = pin.computeFrameJacobian(robot.model, data, q, robot.tcp_frame_id, pin.LOCAL)
        Je = -pin.Jlog6(err_pose.inverse()) @ J[:, cols]
        H = Je.T @ Je
        g = Je.T @ e
        step = np.linalg.solve(H + lam * (np.diag(np.diag(H)) + 1e-9 * np.eye(cols.size)), -g)
        trial = q.copy()
        trial[cols] += step
        t_pose, t_e = _error(robot, data, trial, target)
        t_cost = float(t_e @ t_e)
        if t_cost < cost:
            q, err_pose, e, cost = trial, t_pose, t_e, t_cost
            lam = max(lam * 0.1, 1e-12)
        else:
            lam = min(lam * 10.0, 1e8)
    return IkResult(q, math.sqrt(cost), max_iter)


def _nearest_turn(q: Array, q_ref: Array, lo: Array, hi: Array) -> Array:
    """Each joint shifted by whole turns to lie nearest ``q_ref`` within [lo, hi]."""
    out = q.copy()
    for j in range(q.size):
        k0 = round((q_ref[j] - q[j]) / (2.0 * math.pi))
        options = [q[j] + 2.0 * math.pi * k for k in (k0 - 1, k0, k0 + 1)]
        inside = [v for v in options if lo[j] - BOX_SLACK <= v <= hi[j] + BOX_SLACK] or options
        ref = float(q_ref[j])
        out[j] = min(inside, key=lambda v: abs(v - ref))
    return out


def solve_near(robot: Robot, target: pin.SE3, q_near: Array) -> IkResult:
    """The solution a UR controller takes for ``movel``: the one nearest ``q_near``.

    Newton from ``q_near`` (the previous waypoint's joints), then each joint moved by whole
    turns to the value nearest ``q_near`` within the joint limits, as UR's
    ``get_inverse_kin(x, qnear)`` picks the solution closest to ``qnear``.

    Args:
        robot: The robot.
        target: TCP placement.
        q_near: Joint positions to stay near [rad], shape (n,).

    Returns:
        The result (check :attr:`IkResult.converged`).
    """
    res = newton_pose(robot, target, q_near)
    q = _nearest_turn(res.q, np.asarray(q_near, dtype=float), robot.lower_limits,
                      robot.upper_limits)
    return IkResult(q, res.error, res.iterations)


def _seeds(robot: Robot, target: pin.SE3, box: tuple[Array, Array],
           accept: Callable[[Array], bool], rng: np.random.Generator, count: int,
           samples: int) -> list[Array]:
    """Up to ``count`` accepted samples of the box, nearest TCP pose to the target first."""
    lo, hi = box
    data = robot.model.createData()
    scored: list[tuple[float, Array]] = []
    for q in rng.uniform(lo, hi, size=(samples, lo.size)):
        if not accept(q):
            continue
        d = pose_of(robot, q, data).actInv(target)
        scored.append((float(np.linalg.norm(d.translation))
                       + 0.3 * float(np.linalg.norm(pin.log3(d.rotation))), q))
    scored.sort(key=lambda s: s[0])
    return [q for _, q in scored[:count]]


def solve_pose(robot: Robot, target: pin.SE3, box: tuple[Array, Array],
               accept: Callable[[Array], bool], *, starts: int = 6, max_starts: int = 30,
               samples: int = 400, seed: int = 0) -> list[Array]:
    """Every distinct joint solution of a pose that ``accept`` takes, found from seeds.

    Args:
        robot: The robot.
        target: TCP placement in the base frame.
        box: Lower and upper joint bounds [rad], each shape (n,): the joint limits intersected
            with the turn windows of the configuration (a solution is moved by whole turns
            into it).
        accept: Predicate on joint positions: the configuration matches.
        starts: Newton runs (from the best seeds) when one of them finds a solution.
        max_starts: Newton runs at most, while none has found one.
        samples: Candidate seeds drawn from the box.
        seed: Random seed (the search is deterministic for a given seed).

    Returns:
        Distinct accepted solutions inside the box (empty if none was found).
    """
    lo, hi = (np.array(b, dtype=float) for b in box)
    rng = np.random.default_rng(seed)
    found: list[Array] = []
    data = robot.model.createData()
    mid = 0.5 * (lo + hi)
    for run, q0 in enumerate(_seeds(robot, target, (lo, hi), accept, rng, max_starts, samples)):
        if run >= starts and found:
            break
        res = newton_pose(robot, target, q0, data=data)
        if not res.converged:
            continue
        q = _nearest_turn(res.q, mid, lo, hi)
        inside = bool(np.all(q >= lo - BOX_SLACK) and np.all(q <= hi + BOX_SLACK))
        if inside and accept(q) and all(np.max(np.abs(q - f)) > _DISTINCT for f in found):
            found.append(q)
    return found
