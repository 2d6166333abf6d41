"""The ``seam`` operator script: a hand leading the TCP along a straight welding seam P1 → P2
through a force-saturated spring-damper (see :class:`SeamOperator`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leadthrough.errors import SimulationError, check_fields
from leadthrough.sim.operator import Mark, vector3

__all__ = ["HandTarget", "SeamOperator", "SeamTiming"]

Array = NDArray[np.float64]


# -------------------------------------------------------------------------------------- seam
class HandTarget(NamedTuple):
    """Where the hand wants the TCP.

    Attributes:
        position_base: Target position, base frame [m], shape (3,).
        velocity_base: Target velocity, base frame [m/s], shape (3,).
    """

    position_base: Array
    velocity_base: Array


@dataclass(frozen=True)
class SeamTiming:
    """Phases of the ``seam`` script [s].

    Attributes:
        t_leave_start: Target starts moving from the start position toward P1.
        t_at_p1: Target reaches P1 (dwell starts).
        t_leave_p1: Target leaves P1 along the seam.
        t_at_p2: Target reaches P2 (dwell starts).
        t_release: The hand lets go (wrench exactly zero from here on).
    """

    t_leave_start: float
    t_at_p1: float
    t_leave_p1: float
    t_at_p2: float
    t_release: float


def _smooth_move(t: float, origin: Array, unit: Array, length: float, speed: float,
                 accel_s: float) -> HandTarget:
    """Straight move from ``origin`` along ``unit`` over ``length`` [m], cruising at ``speed``
    [m/s] with raised-cosine accelerations of ``accel_s`` [s], at ``t`` [s] from its start (ends
    at ``length/speed + accel_s``; needs ``length >= speed·accel_s``)."""
    total = length / speed + accel_s
    tau = min(max(t, 0.0), total)
    edge = min(tau, total - tau)  # time from the nearer end of the move
    if edge <= accel_s:
        s = 0.5 * speed * (edge - accel_s / math.pi * math.sin(math.pi * edge / accel_s))
        v = 0.5 * speed * (1.0 - math.cos(math.pi * edge / accel_s))
        if tau > 0.5 * total:
            s = length - s
    else:
        s, v = 0.5 * speed * accel_s + speed * (tau - accel_s), speed
    return HandTarget(origin + s * unit, v * unit)


class SeamOperator:
    """The ``seam`` script: the hand leads the TCP along a straight welding seam P1 → P2.

    The hand is a spring-damper to a moving target, ``F = k·(p_t − p) + c·(v_t − v) + L``, its
    magnitude saturated at ``max_force``. ``L`` is the operator's lean: while the target rests
    (at the start, P1 and P2) the operator sees the tool short of the point and pushes harder,
    ``L̇ = k_i·(p_t − p)`` (integrated only while |F| is below the saturation); while the target
    moves the lean relaxes with the time constant ``accel_s``. Without it the tool stops where the
    spring force falls below the robot's virtual friction, δ/k short of each point.

    The TCP velocity ``v`` is the finite difference of successive TCP positions over their
    times, low-passed with ``velocity_filter_s``; a call at the same ``t`` as the previous one
    leaves that estimate (and the lean) unchanged, and a call at an earlier ``t`` (a restarted
    simulation) resets both to zero. Forces only, no torque.

    The target rests at the start position until ``t_first``, moves to P1, dwells ``dwell_s``, moves
    along the seam to P2, dwells, and the hand lets go. Moves cruise at ``speed`` with
    raised-cosine accelerations of ``accel_s`` (a leg shorter than ``speed·accel_s`` peaks lower,
    so the target never exceeds ``speed``). Marks P1 and P2 are pressed ``mark_after_s`` into
    each dwell, when the TCP has settled.

    Args:
        tcp_start_base: TCP position at the start, base frame [m], shape (3,).
        p1_offset_base: P1 relative to the start position, base frame [m], shape (3,).
        seam_base: P2 − P1, base frame [m], shape (3,) (default a 0.3 m horizontal line along
            (0.6, 0.8, 0)).
        stiffness: Hand stiffness k [N/m] (a firm grip for fine positioning).
        damping: Hand damping c [N·s/m] (with k, ζ ≈ 0.3 against a 100 kg virtual mass).
        lean_gain: k_i of the lean [N/(m·s)] (0: a pure spring-damper).
        max_force: Saturation of |F| [N].
        speed: Cruise speed of the target [m/s].
        accel_s: Acceleration and deceleration time of each move [s].
        t_first: Time the target starts moving [s].
        dwell_s: Dwell at P1 and at P2 [s].
        mark_after_s: Time into each dwell of the mark [s], < dwell_s.
        after_s: Time after the release until the end of the session [s].
        velocity_filter_s: Time constant of the TCP velocity low-pass [s] (0: raw difference).

    Raises:
        SimulationError: A setting is out of range.
    """

    name = "seam"

    def __init__(self, tcp_start_base: ArrayLike, *,
                 p1_offset_base: ArrayLike = (-0.05, -0.10, -0.05),
                 seam_base: ArrayLike = (0.18, 0.24, 0.0),
                 stiffness: float = 3000.0, damping: float = 300.0, lean_gain: float = 1000.0,
                 max_force: float = 60.0, speed: float = 0.05, accel_s: float = 0.5,
                 t_first: float = 1.0, dwell_s: float = 3.0, mark_after_s: float = 2.5,
                 after_s: float = 1.0,
                 velocity_filter_s: float = 0.01) -> None:
        self.start_base = vector3(tcp_start_base, "tcp_start_base")
        self.p1_base = self.start_base + vector3(p1_offset_base, "p1_offset_base")
        self.p2_base = self.p1_base + vector3(seam_base, "seam_base")
        self.stiffness, self.damping, self.max_force = float(stiffness), float(damping), \
            float(max_force)
        self.lean_gain = float(lean_gain)
        self.speed, self.accel_s, self.t_first = float(speed), float(accel_s), float(t_first)
        self.dwell_s, self.mark_after_s = float(dwell_s), float(mark_after_s)
        self.after_s, self.velocity_filter_s = float(after_s), float(velocity_filter_s)
        pos, nonneg = "positive finite", "finite and >= 0"
        check_fields("seam", self, [
            ("stiffness", 0.0 < self.stiffness < math.inf, pos),
            ("damping", 0.0 <= self.damping < math.inf, nonneg),
            ("lean_gain", 0.0 <= self.lean_gain < math.inf, nonneg),
            ("max_force", 0.0 < self.max_force < math.inf, pos),
            ("speed", 0.0 < self.speed < math.inf, pos),
            ("accel_s", 0.0 < self.accel_s < math.inf, pos),
            ("t_first", 0.0 <= self.t_first < math.inf, nonneg),
            ("mark_after_s", 0.0 <= self.mark_after_s < self.dwell_s < math.inf,
             "0 <= mark_after_s < dwell_s"),
            ("after_s", 0.0 <= self.after_s < math.inf, nonneg),
            ("velocity_filter_s", 0.0 <= self.velocity_filter_s < math.inf, nonneg),
        ], SimulationError)
        self._legs = ((self.start_base, self.p1_base - self.start_base),
                      (self.p1_base, self.p2_base - self.p1_base))
        self._lengths = tuple(float(np.linalg.norm(d)) for _, d in self._legs)
        self._units = tuple(d / length if length > 0.0 else d
                            for (_, d), length in zip(self._legs, self._lengths, strict=True))
        # a leg too short to reach the cruise speed peaks at length / accel_s instead
        self._speeds = tuple(min(self.speed, length / self.accel_s) for length in self._lengths)
        t_p1 = self.t_first + self._move_time(0)
        t_leave = t_p1 + self.dwell_s
        t_p2 = t_leave + self._move_time(1)
        self.timing = SeamTiming(t_leave_start=self.t_first, t_at_p1=t_p1, t_leave_p1=t_leave,
                                 t_at_p2=t_p2, t_release=t_p2 + self.dwell_s)
        self.duration_s = self.timing.t_release + self.after_s
        self.marks = (Mark(t_p1 + self.mark_after_s, "P1"), Mark(t_p2 + self.mark_after_s, "P2"))
        self._t_prev = math.nan
        self._p_prev = np.zeros(3)
        self._v_est = np.zeros(3)
        self._lean = np.zeros(3)

    def _move_time(self, leg: int) -> float:
        length = self._lengths[leg]
        return length / self._speeds[leg] + self.accel_s if length > 0.0 else 0.0

    def reset(self) -> None:
        """Forget the TCP history (velocity estimate and lean back to zero)."""
        self._t_prev = math.nan
        self._v_est[:] = 0.0
        self._lean[:] = 0.0

    def target(self, t: float) -> HandTarget:
        """Where the hand wants the TCP at time ``t`` [s] (rests at P2 after the release)."""
        tm = self.timing
        leg, t0 = (0, tm.t_leave_start) if t < tm.t_at_p1 else (1, tm.t_leave_p1)
        origin = self._legs[leg][0]
        if self._lengths[leg] == 0.0 or t <= t0:
            return HandTarget(origin.copy(), np.zeros(3))
        return _smooth_move(t - t0, origin, self._units[leg], self._lengths[leg],
                            self._speeds[leg], self.accel_s)

    def _advance(self, t: float, p: Array) -> float:
        """Update the velocity estimate; returns the time step [s] (0 if none)."""
        dt = 0.0
        if not t >= self._t_prev:  # first call (nan) or time went back: restart
            self._v_est[:] = 0.0
            self._lean[:] = 0.0
        elif t > self._t_prev:
            dt = t - self._t_prev
            alpha = dt / (self.velocity_filter_s + dt)
            self._v_est += alpha * ((p - self._p_prev) / dt - self._v_est)
        else:  # same t again: keep the estimate
            return 0.0
        self._t_prev = t
        self._p_prev[:] = p
        return dt

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """Wrench of the hand at the TCP, base frame [N, N·m], shape (6,) (a new array).

        Args:
            t: Simulation time [s].
            tcp_position_base: TCP position, base frame [m], shape (3,).
        """
        p = np.asarray(tcp_position_base, dtype=float)
        dt = self._advance(t, p)
        w = np.zeros(6)
        if t >= self.timing.t_release:
            return w
        target = self.target(t)
        error = target.position_base - p
        f = self.stiffness * error + self.damping * (target.velocity_base - self._v_est)
        if dt > 0.0:
            if target.velocity_base.any():
                self._lean *= math.exp(-dt / self.accel_s)
            else:
                leaning = f + self._lean
                if math.sqrt(float(leaning @ leaning)) < self.max_force:
                    self._lean += (self.lean_gain * dt) * error
        f += self._lean
        norm = math.sqrt(float(f @ f))
        if norm > self.max_force:
            f *= self.max_force / norm
        w[:3] = f
        return w
