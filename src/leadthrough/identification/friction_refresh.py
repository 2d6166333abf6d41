"""Keeping the friction current: the identified friction rescaled from a short friction check.

Gear friction drifts over a working day: a robot calibrated cold in the morning has, after an
hour of production, lost tens of percent of its friction, the viscous part more than the
Coulomb part (grease viscosity falls with temperature; Bittencourt et al., "An extended friction
model to capture load and temperature effects in robot joints", IROS 2010; Simoni et al.,
"Friction modeling with temperature effects for industrial robot manipulators", IROS 2015;
Carlson et al., "Temperature dependent friction modeling of industrial robots", 2015). Hand
guiding runs exactly on that friction: a model whose friction is too high reads every motion
as the operator pulling back (and a release as a push), one too low reads motion as a push that
keeps the robot going.

The remedy kept here is the one that needs no model of the temperature: **a friction check
before guiding** (and whenever the operator asks, e.g. after a break or a shift of work): a
short friction sweep (:func:`leadthrough.excitation.friction_sweep.friction_check_config`, four
speeds from 0.01 to 0.3 rad/s, out and back, about 20 s), whose half-differences give each
joint's friction at those speeds with no link model involved
(:func:`~leadthrough.identification.friction_sweep.sweep_points`). The identified friction keeps
its shape (Stribeck velocities, the load term's share) and gets two scales per joint, fitted by
bounded weighted least squares to those points:

    F_check(v) ≈ a·L(v) + b·f4·v

where L(v) = f1 + f2·e_m(v) + f3·e_g(v) + f_cL·|τ_load| is the level part of eq. 15 with the load
term (τ_load: the identified links' gravity torque at the check's mean pose) and f4·v the viscous
part. The refreshed parameters are f1, f2, f3, f_cL scaled by a and f4 by b. When the check's
speeds cannot tell the viscous part from the level part (the viscous part under 5 % of the
friction at the fastest point), b = a. Both scales are bounded to [0.25, 4]. A level scale at
a bound is an error (a wrong params file or robot), not a drift: the level part is most of the
friction at guiding speeds. The viscous scale may end at a bound, and the result says so
(``viscous_at_bound``): the check's four speeds give the viscous part little leverage, and the
identification's split between Stribeck and viscous friction is the least certain part of eq.
15 (benchmarks/run_on.py, instance 1's joint 2: the sweep-based calibration's viscous part read
3.6 times the check's on the cold robot already).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from leadthrough.data.recording import Recording
from leadthrough.dynamics.friction import StribeckParameters
from leadthrough.dynamics.model import DriveModelParameters, FrictionModel
from leadthrough.dynamics.regressor import link_torque
from leadthrough.errors import DataError
from leadthrough.identification.friction_sweep import SweepPoints, sweep_points
from leadthrough.robot.description import Robot

__all__ = ["MAX_SCALE", "MIN_SCALE", "FrictionRefresh", "refresh_friction", "require_eq15"]

Array = NDArray[np.float64]

#: Bounds of the scales [-]: friction that changed more than this is not a drift.
MIN_SCALE, MAX_SCALE = 0.25, 4.0
#: Below this share of the friction at the fastest point the viscous part is not separable.
VISCOUS_SHARE = 0.05


@dataclass(frozen=True)
class FrictionRefresh:
    """A friction check's result.

    Attributes:
        params: The parameters with the friction rescaled.
        level_scale: a per joint: f1, f2, f3, f_cL scaled by it [-], shape (n,).
        viscous_scale: b per joint: f4 scaled by it [-], shape (n,).
        points: Friction points per joint (from the check).
        error_before: RMS relative error of the old friction at the points [-], shape (n,).
        error_after: Same for the refreshed friction [-], shape (n,).
        separable: Whether b was fitted apart from a, shape (n,).
        viscous_at_bound: Whether b ended at a bound of [0.25, 4] (the check asked for more;
            see the module doc), shape (n,).
    """

    params: DriveModelParameters
    level_scale: Array
    viscous_scale: Array
    points: SweepPoints
    error_before: Array
    error_after: Array
    separable: NDArray[np.bool_]
    viscous_at_bound: NDArray[np.bool_]


def _split(params: DriveModelParameters, robot: Robot, speeds: Array, load: float,
           j: int) -> tuple[Array, Array]:
    """Level part L(v) and viscous part f4·v of joint ``j``'s friction at ``speeds`` > 0."""
    s = params.stribeck
    assert s is not None
    qd = np.zeros((speeds.size, robot.n))
    qd[:, j] = speeds
    loads = np.full((speeds.size, robot.n), load)
    level_only = replace(params, stribeck=replace(s, f4=np.zeros(robot.n)))
    level = level_only.friction(qd, robot.gear_ratio, loads)[:, j]
    return level, s.f4[j] * speeds


def _fit(level: Array, viscous: Array, f: Array) -> tuple[float, float, bool]:
    """(a, b, separable) of one joint: bounded weighted least squares, relative weights."""
    w = 1.0 / np.maximum(np.abs(f), 1e-6 + 1e-3 * float(np.max(np.abs(f))))
    separable = bool(viscous.size >= 2 and np.max(viscous) >= VISCOUS_SHARE *
                     np.max(level + viscous))
    if separable:
        A = np.column_stack([level, viscous]) * w[:, None]
        sol = scipy.optimize.lsq_linear(A, f * w, bounds=(MIN_SCALE, MAX_SCALE))
        return float(sol.x[0]), float(sol.x[1]), True
    total = (level + viscous) * w
    a = float(np.dot(total, f * w) / max(float(np.dot(total, total)), 1e-300))
    a = min(max(a, MIN_SCALE), MAX_SCALE)
    return a, a, False


def require_eq15(params: DriveModelParameters, source: str | Path | None = None
                 ) -> StribeckParameters:
    """Parameters a friction check can rescale: eq. 15 friction; returns it.

    Args:
        params: The identified parameters.
        source: Their params file, if they were read from one (the message names it and its
            ``meta.friction_model``).

    Raises:
        DataError: Another friction model.
    """
    if params.friction_model is not FrictionModel.STRIBECK or params.stribeck is None:
        raise DataError("a friction check rescales eq. 15 friction (these parameters have "
                        "another friction model)", source=source,
                        field="friction_model" if source is None else "meta.friction_model",
                        value=params.friction_model.value,
                        expected="stribeck (identify with --method consistent "
                                 "--friction-sweep)")
    return params.stribeck


def refresh_friction(params: DriveModelParameters, check: Recording,
                     robot: Robot) -> FrictionRefresh:
    """Rescale the identified friction to a friction check (see the module doc).

    Args:
        params: Identified parameters with eq. 15 friction (identified with a friction sweep).
        check: Recording of a friction check (or any friction sweep) on the same robot, no
            external force.
        robot: The robot.

    Returns:
        The refreshed parameters and the fit's figures.

    Raises:
        DataError: Parameters without eq. 15 friction, a check with no usable pass on some
            joint, or a level scale outside [0.25, 4] (a wrong params file, robot or
            recording).
    """
    check.check_robot(robot)
    old = require_eq15(params)
    points = sweep_points(check, robot)
    q_mean = np.mean(check.q, axis=0)[None, :]
    zero = np.zeros_like(q_mean)
    gravity = link_torque(robot.model, params.phi, q_mean, zero, zero)[0]
    n = robot.n
    a, b = np.ones(n), np.ones(n)
    before, after = np.zeros(n), np.zeros(n)
    separable = np.zeros(n, dtype=bool)
    for j in range(n):
        v, f = np.abs(points.speed[j]), points.friction[j]
        if v.size < 2:
            raise DataError("too few usable passes in the friction check", source=check.source,
                            field=f"{robot.joint_names[j]}", value=int(v.size),
                            expected="2 or more speeds (excite --friction-check)")
        level, viscous = _split(params, robot, v, float(gravity[j]), j)
        a[j], b[j], separable[j] = _fit(level, viscous, f)
        if _at_bound(a[j]):
            raise DataError("the friction changed beyond a drift", source=check.source,
                            field=f"{robot.joint_names[j]} friction scale",
                            value=round(a[j], 3),
                            expected=f"within [{MIN_SCALE}, {MAX_SCALE}] of the params file's "
                                     "(the right params file and robot?)")
        before[j] = _rel_rms(level + viscous, f)
        after[j] = _rel_rms(a[j] * level + b[j] * viscous, f)
    stribeck = StribeckParameters(f1=old.f1 * a, f2=old.f2 * a, qd_sm=old.qd_sm.copy(),
                                  f3=old.f3 * a, qd_sg=old.qd_sg.copy(), f4=old.f4 * b)
    load = params.load_friction * a if params.load_friction.size else params.load_friction
    new = replace(params, stribeck=stribeck, load_friction=load)
    at_bound = separable & _at_bound(b)
    return FrictionRefresh(new, a, b, points, before, after, separable, at_bound)


def _at_bound(scale: float | Array) -> NDArray[np.bool_]:
    """Whether fitted scales ended at (within 0.1 % of) a bound of [MIN_SCALE, MAX_SCALE]
    (NaN counts as at a bound), elementwise."""
    s = np.asarray(scale)
    return ~((s > MIN_SCALE * 1.001) & (s < MAX_SCALE * 0.999))


def _rel_rms(model: Array, measured: Array) -> float:
    """RMS of (model − measured) / |measured|."""
    return float(np.sqrt(np.mean(((model - measured) / np.abs(measured)) ** 2)))
