"""A presliding test: small out-and-back excursions at rest, to measure each drive's presliding
length z₀.

At standstill the gear's friction is not eq. 15's function of velocity: it is a state that
turns over a displacement of a few z₀ (the presliding regime of a LuGre/Dahl model) and keeps its
value when the motion stops. How far a joint has to move for its friction to turn decides how
much of a push the drive's current sees at rest (:mod:`leadthrough.estimation.kernels`), and a
friction sweep cannot measure it: during a reversal, the servo's lag and the presliding damping
blur it (the sweep's reversals read z₀ 25 % short on the simulated er20).

This module designs a test that needs no link model. All joints move at once, from and back to
the same configuration ``q_start``. One *trial* of amplitude A and sign s is:

1. precondition: out by −s·P and back (P ≫ z₀), so every drive's friction is saturated in the
   direction +s; then rest;
2. excursion: out by −s·A against that direction and back; then rest.

Every rest is at the same configuration, so gravity and the drives' offset are equal in all of
them and the change of the joint torque between two consecutive rests is the change of the
friction alone. For a Dahl friction of level g, it is 2g·(1 − e^{−x₁})·e^{−x₂} after an excursion
(x₁, x₂ the outward and return displacements over z₀): zero for A ≪ z₀ (the drive springs
back), zero again for A ≫ z₀ (the friction turns over twice), largest near A ≈ z₀·ln 2. The
amplitudes span that range; :mod:`leadthrough.identification.presliding` fits z₀ and g to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import check_fields
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.start_pose import checked_start
from leadthrough.robot.description import Robot

__all__ = ["PreslidingTest", "PreslidingTestConfig", "design_presliding_test"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class PreslidingTestConfig:
    """How the test is laid out.

    Attributes:
        amplitudes: Excursion amplitudes A [rad, joint side], each run in both signs. They
            should span z₀/5 … 10·z₀ (gear presliding is of the order of the lost motion:
            ≲ 1 arcmin ≈ 3e-4 rad).
        precondition: P [rad]: the preconditioning move, several z₀ plus the servo's lag.
        move_s: Duration of each one-way move (cosine profile) [s]. Slow drives (a wrist
            stuck in static friction until its servo's integrator builds up) need the time.
        rest_s: Rest after each out-and-back move [s]: the servo settles and the torque is
            averaged over its last part.
        limit_margin: Distance kept from the joint limits [rad].
        rate_hz: Sample rate of the command [Hz].
    """

    amplitudes: tuple[float, ...] = (3e-5, 6e-5, 1e-4, 1.5e-4, 2e-4, 3e-4, 4.5e-4, 7e-4,
                                     1e-3, 1.5e-3)
    precondition: float = 2e-3
    move_s: float = 0.5
    rest_s: float = 1.0
    limit_margin: float = 0.05
    rate_hz: float = 1000.0

    def __post_init__(self) -> None:
        check_fields("presliding_test", self, [
            ("amplitudes", len(self.amplitudes) >= 2
             and all(math.isfinite(a) and 0 < a <= 0.05 for a in self.amplitudes),
             "at least 2 amplitudes in (0, 0.05] rad"),
            ("precondition", math.isfinite(self.precondition)
             and max(self.amplitudes, default=0.0) <= self.precondition <= 0.05,
             "the largest amplitude <= P <= 0.05 rad"),
            ("move_s", math.isfinite(self.move_s) and self.move_s > 0, "> 0 s"),
            ("rest_s", math.isfinite(self.rest_s) and self.rest_s > 0, "> 0 s"),
            ("limit_margin", math.isfinite(self.limit_margin) and self.limit_margin >= 0,
             ">= 0 rad"),
            ("rate_hz", math.isfinite(self.rate_hz) and self.rate_hz > 0, "> 0 Hz"),
        ])


@dataclass(frozen=True)
class PreslidingTest:
    """A designed test.

    Attributes:
        samples: The command at ``config.rate_hz``, starting and ending at rest at ``q_start``.
        q_start: The configuration of every rest [rad], shape (n,).
        amplitude: Amplitude A of each trial [rad], shape (T,).
        sign: Direction s of each trial (+1 or −1; the excursion goes toward −s), shape (T,).
        trial_start_s: Start time of each trial [s], shape (T,).
        duration_s: Total length [s].
    """

    samples: TrajectorySamples
    q_start: Array
    amplitude: Array
    sign: Array
    trial_start_s: Array
    duration_s: float


def design_presliding_test(robot: Robot, q_start: Array | None = None,
                           config: PreslidingTestConfig | None = None) -> PreslidingTest:
    """Design the presliding test of every joint at once (module docstring).

    Args:
        robot: The robot (joint limits).
        q_start: The test configuration [rad], shape (n,); default: the neutral pose.
        config: Layout.

    Returns:
        The test: an initial rest, then one trial per amplitude and sign (ascending amplitude,
        +1 then −1).

    Raises:
        DataError: ``q_start`` has the wrong size or is outside the limits less the margin and
            the preconditioning move.
    """
    cfg = config if config is not None else PreslidingTestConfig()
    n = robot.n
    q0 = checked_start(robot, q_start, cfg.limit_margin + cfg.precondition)
    dt = 1.0 / cfg.rate_hz
    k_move = max(2, round(cfg.move_s / dt))
    phase = np.pi * np.arange(1, k_move + 1) / k_move
    # one-way move of unit length: position, velocity (cosine profile, rest to rest)
    shape_q = 0.5 * (1.0 - np.cos(phase))
    shape_v = 0.5 * np.pi / (k_move * dt) * np.sin(phase)
    out_back_q = np.concatenate([shape_q, 1.0 - shape_q])
    out_back_v = np.concatenate([shape_v, -shape_v])
    rest = np.zeros(max(1, round(cfg.rest_s / dt)))
    one_q = np.concatenate([out_back_q, rest])
    one_v = np.concatenate([out_back_v, rest])
    offset: list[Array] = [rest]
    velocity: list[Array] = [rest]
    amplitude, sign, start = [], [], []
    t = rest.size
    for a in sorted(cfg.amplitudes):
        for s in (1.0, -1.0):
            start.append(t * dt)
            amplitude.append(a)
            sign.append(s)
            for length in (-s * cfg.precondition, -s * a):
                offset.append(length * one_q)
                velocity.append(length * one_v)
                t += one_q.size
    d = np.concatenate(offset)
    v = np.concatenate(velocity)
    q = q0[None, :] + d[:, None] * np.ones(n)[None, :]
    qd = v[:, None] * np.ones(n)[None, :]
    qdd = np.gradient(qd, dt, axis=0)
    time = np.arange(d.size, dtype=float) * dt
    return PreslidingTest(
        samples=TrajectorySamples(time=time, q=q, qd=qd, qdd=qdd), q_start=q0,
        amplitude=np.array(amplitude), sign=np.array(sign), trial_start_s=np.array(start),
        duration_s=float(time[-1]))
