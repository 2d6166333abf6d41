"""A friction sweep: constant-velocity passes, out and back, at speeds from creep to fast.

Eq. 15's Stribeck terms live at joint speeds of a few hundredths of a rad/s, where an optimised
Fourier excitation (eq. 21's data) spends almost no time, and where it does (reversals), the
drive's friction is in its presliding transient, not on the steady Stribeck curve. Hand guiding
runs exactly there. The classic remedy is a friction experiment: hold each speed long enough for
the friction to settle, in both directions, over the same positions.

This module designs that trajectory. All joints move at once. Each speed is one *segment*: a
smooth ramp (cosine velocity profile, bounded acceleration) to +v, a cruise, a ramp to rest, a
pause, and then the exact time reversal at −v back to the start. Because the backward pass
retraces the forward one in reverse time, at every cruise sample the configuration of the
forward pass recurs on the backward pass with the velocity negated: gravity, the drives' offset
and the Coriolis/centrifugal torque (quadratic in q̇) are equal in both, so half the difference
of the two joint torques is the friction alone, with no link model involved
(:mod:`leadthrough.identification.friction_sweep`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError, check_fields
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.start_pose import checked_start
from leadthrough.robot.description import Robot

__all__ = ["FRICTION_CHECK", "FrictionSweep", "FrictionSweepConfig", "design_friction_sweep"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FrictionSweepConfig:
    """How the sweep is laid out.

    Attributes:
        speeds: Cruise speeds [rad/s, joint side], the same for every joint (capped at
            ``max_speed_fraction`` of each joint's velocity limit). Log-spaced from creep speed
            through the Stribeck region to fast.
        settle_displacement: Displacement the friction needs to settle after a ramp (several
            presliding lengths plus the servo's lag) [rad].
        measure_displacement: Displacement measured per cruise, after settling (each pass
            settles from its own end, so a cruise is 2·settle + measure) [rad]; the cruise time
            is clipped to [``min_cruise_s``, ``max_cruise_s``], but always leaves
            ``min_cruise_s`` after settling.
        min_cruise_s: Shortest cruise [s].
        max_cruise_s: Longest cruise [s].
        acceleration: Peak ramp acceleration [rad/s², joint side].
        pause_s: Rest between passes [s].
        max_speed_fraction: Cap of the speeds as a fraction of each joint's velocity limit.
        limit_margin: Distance kept from the joint limits [rad].
        rate_hz: Sample rate of the command [Hz].
    """

    speeds: tuple[float, ...] = (0.005, 0.01, 0.02, 0.035, 0.06, 0.1, 0.16, 0.25, 0.4, 0.7)
    settle_displacement: float = 0.004
    measure_displacement: float = 0.04
    min_cruise_s: float = 0.5
    max_cruise_s: float = 3.0
    acceleration: float = 1.0
    pause_s: float = 0.3
    max_speed_fraction: float = 0.5
    limit_margin: float = 0.05
    rate_hz: float = 1000.0

    def __post_init__(self) -> None:
        check_fields("friction_sweep", self, [
            ("speeds", len(self.speeds) >= 3 and all(math.isfinite(s) and s > 0
                                                     for s in self.speeds),
             "at least 3 finite speeds > 0 rad/s"),
            ("settle_displacement", math.isfinite(self.settle_displacement)
             and self.settle_displacement >= 0, ">= 0 rad"),
            ("measure_displacement", math.isfinite(self.measure_displacement)
             and self.measure_displacement > 0, "> 0 rad"),
            ("min_cruise_s", 0 < self.min_cruise_s <= self.max_cruise_s,
             "0 < min_cruise_s <= max_cruise_s"),
            ("max_cruise_s", math.isfinite(self.max_cruise_s), "finite"),
            ("acceleration", math.isfinite(self.acceleration) and self.acceleration > 0,
             "> 0 rad/s²"),
            ("pause_s", math.isfinite(self.pause_s) and self.pause_s >= 0, ">= 0 s"),
            ("max_speed_fraction", 0 < self.max_speed_fraction <= 1, "0 < fraction <= 1"),
            ("limit_margin", math.isfinite(self.limit_margin) and self.limit_margin >= 0,
             ">= 0 rad"),
            ("rate_hz", math.isfinite(self.rate_hz) and self.rate_hz > 0, "> 0 Hz"),
        ])


#: A friction check (:mod:`leadthrough.identification.friction_refresh`): the sweep cut to four
#: speeds, from the Stribeck region to guiding speed, shorter cruises (about 25 s in all). It
#: rescales an identified friction; it does not identify one.
FRICTION_CHECK = FrictionSweepConfig(speeds=(0.01, 0.03, 0.1, 0.3), measure_displacement=0.02,
                                     max_cruise_s=2.0)


@dataclass(frozen=True)
class FrictionSweep:
    """A designed sweep.

    Attributes:
        samples: The command at ``config.rate_hz``, starting and ending at rest at ``q_start``.
        q_start: Start (and end) configuration [rad], shape (n,).
        speeds: Cruise speed per segment and joint [rad/s], shape (S, n) (≥ 0; the forward
            pass moves toward the roomier side of each joint).
        direction: +1 or −1 per joint: the sign of the forward pass, shape (n,).
        cruise_s: Cruise time per segment [s], shape (S,).
        duration_s: Total length [s].
    """

    samples: TrajectorySamples
    q_start: Array
    speeds: Array
    direction: Array
    cruise_s: Array
    duration_s: float


def _profile(v: float, cruise_s: float, accel: float, dt: float) -> Array:
    """Speed profile of one pass (ramp, cruise, ramp), symmetric in time, sampled at dt."""
    ramp_s = math.pi * v / (2.0 * accel)               # cosine ramp: peak accel = accel
    k_ramp = max(2, math.ceil(ramp_s / dt))
    up = 0.5 * (1.0 - np.cos(np.pi * np.arange(k_ramp) / k_ramp))
    cruise = np.ones(max(1, round(cruise_s / dt)))
    return np.concatenate([up, cruise, up[::-1], [0.0]])


def design_friction_sweep(robot: Robot, q_start: Array | None = None,
                          config: FrictionSweepConfig | None = None) -> FrictionSweep:
    """Design the out-and-back constant-velocity sweep of every joint at once.

    Args:
        robot: The robot (joint limits, velocity limits).
        q_start: Start configuration [rad], shape (n,); default: the neutral pose.
        config: Layout.

    Returns:
        The sweep.

    Raises:
        DataError: ``q_start`` has the wrong size, is outside the limits, or leaves no room to
            move some joint.
    """
    cfg = config if config is not None else FrictionSweepConfig()
    n = robot.n
    q0 = checked_start(robot, q_start, cfg.limit_margin)
    lo = robot.lower_limits + cfg.limit_margin
    hi = robot.upper_limits - cfg.limit_margin
    room_pos, room_neg = hi - q0, q0 - lo
    direction = np.where(room_pos >= room_neg, 1.0, -1.0)
    room = np.maximum(room_pos, room_neg)
    dt = 1.0 / cfg.rate_hz
    cap = cfg.max_speed_fraction * robot.velocity_limit
    segments: list[Array] = []
    speeds, cruises = [], []
    for s in sorted(cfg.speeds):
        v = np.minimum(s, cap)
        # Both passes drop their first settle_displacement, from opposite ends of the cruise.
        # A very slow pass exceeds max_cruise_s rather than leave less than min_cruise_s.
        settle_s = 2.0 * cfg.settle_displacement / s
        cruise = max(float(np.clip(settle_s + cfg.measure_displacement / s, cfg.min_cruise_s,
                                   cfg.max_cruise_s)), settle_s + cfg.min_cruise_s)
        shape = _profile(float(np.max(v)), cruise, cfg.acceleration, dt)
        # Each joint's excursion is v·∫shape; shrink the speed of a joint that lacks room.
        travel = v * float(np.sum(shape)) * dt
        v = np.where(travel > room, v * room / np.maximum(travel, 1e-12), v)
        if np.any(v <= 0.0):
            j = int(np.argmin(v))
            raise DataError("no room to move the joint", field=f"q_start[{robot.joint_names[j]}]",
                            value=float(q0[j]), expected="a start away from both joint limits")
        pause = np.zeros(max(1, round(cfg.pause_s / dt)))
        one = np.concatenate([shape, pause])
        segments.append(np.concatenate([one, -one])[:, None] * (direction * v)[None, :])
        speeds.append(v)
        cruises.append(cruise)
    qd = np.concatenate([np.zeros((1, n)), *segments], axis=0)
    # Trapezoidal integration: the backward pass undoes the forward one exactly.
    q = q0 + np.concatenate([np.zeros((1, n)), np.cumsum(0.5 * (qd[1:] + qd[:-1]) * dt, axis=0)])
    qdd = np.gradient(qd, dt, axis=0)
    time = np.arange(qd.shape[0], dtype=float) * dt
    return FrictionSweep(
        samples=TrajectorySamples(time=time, q=q, qd=qd, qdd=qdd), q_start=q0,
        speeds=np.array(speeds), direction=direction, cruise_s=np.array(cruises),
        duration_s=float(time[-1]))
