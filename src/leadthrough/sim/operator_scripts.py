"""Scripted operators: the simulated hand of the guiding sessions, selectable by name.

:func:`make_operator` builds one of :data:`OPERATOR_NAMES`:

* ``rest``: nobody touches the robot (zero wrench) for 5 s.
* ``push-x``: +x (base frame) with 40 N from t = 1 s to t = 4 s, then released; 6 s session.
* ``diagonal``: along (1, 1, 0)/√2 with 40 N from t = 1 s to t = 4 s; marks P1 at 0.5 s (before
  the push) and P2 at 5.5 s (after the release); 6.5 s session.
* ``random``: 8 seeded pushes, random direction (uniform on the sphere), 20–60 N, 0.5–2 s long,
  0.5–1.5 s pauses, 50–100 ms raised-cosine onsets and releases; first push at 1 s.
* ``seam``: the hand pulls the TCP through a spring-damper toward a target that moves from the
  start position to P1, dwells (mark P1), follows the straight 0.3 m seam to P2, dwells (mark P2),
  then the hand lets go (see :class:`SeamOperator`).

Every time is simulation time [s], the ``t`` of :meth:`Operator.wrench` (= ``Feedback.t`` of the
step the wrench acts in). Every script has ``name``, ``duration_s`` (session length, with time
to come to rest after the release) and ``marks`` ("mark point" presses, :class:`Mark`).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leadthrough.errors import SimulationError
from leadthrough.sim.operator import Mark, ScriptedOperator, vector3
from leadthrough.sim.seam_operator import HandTarget, SeamOperator, SeamTiming

__all__ = [
    "OPERATOR_NAMES", "HandTarget", "PushScript", "ScriptedPush", "SeamOperator", "SeamTiming",
    "diagonal_push", "make_operator", "push_x", "random_pushes", "rest",
]

Array = NDArray[np.float64]

OPERATOR_NAMES: tuple[str, ...] = ("rest", "push-x", "diagonal", "random", "seam")
"""Names accepted by :func:`make_operator`."""

# The ``push-x`` and ``diagonal`` pushes: force [N], onset [s] (the loop settles before), length
# onset to release [s], raised-cosine onset and release ramps [s].
PUSH_FORCE_N, PUSH_START_S, PUSH_DURATION_S, PUSH_RAMP_S = 40.0, 1.0, 3.0, 0.05


# ------------------------------------------------------------------------------------ pushes
@dataclass(frozen=True)
class ScriptedPush:
    """One push of the hand, zero outside ``[t_start, t_end)``.

    Attributes:
        t_start: Time the force starts to rise from zero [s].
        t_end: Release: time the force is back to exactly zero [s].
        force_base: Full force (Fx, Fy, Fz), base frame [N]; no torque.
        ramp_s: Length of the raised-cosine onset and release [s]; full force during
            ``[t_start + ramp_s, t_end - ramp_s]``.
    """

    t_start: float
    t_end: float
    force_base: tuple[float, float, float]
    ramp_s: float = PUSH_RAMP_S

    def __post_init__(self) -> None:
        vector3(self.force_base, "force_base")
        if not (math.isfinite(self.t_start) and self.t_start >= 0.0
                and self.ramp_s >= 0.0 and self.t_end >= self.t_start + 2.0 * self.ramp_s
                and math.isfinite(self.t_end)):
            raise SimulationError("bad push timing", field="push",
                                  value=(self.t_start, self.t_end, self.ramp_s),
                                  expected="0 <= t_start, ramp_s >= 0, "
                                  "t_end >= t_start + 2·ramp_s, finite")

    @property
    def magnitude(self) -> float:
        """Full force magnitude [N]."""
        return float(np.linalg.norm(self.force_base))

    def scale(self, t: float) -> float:
        """Fraction of the full force at time ``t`` [s], in [0, 1]."""
        if t < self.t_start or t >= self.t_end:
            return 0.0
        rise = t - self.t_start
        fall = self.t_end - t
        edge = min(rise, fall)
        if edge >= self.ramp_s:
            return 1.0
        return 0.5 * (1.0 - math.cos(math.pi * edge / self.ramp_s))


@dataclass(frozen=True)
class PushScript:
    """A sequence of non-overlapping pushes (the ``rest``, ``push-x``, ``diagonal`` and
    ``random`` scripts). Does not react to the TCP position.

    Attributes:
        name: Script name.
        pushes: The pushes, in time order, not overlapping.
        duration_s: Session length [s], >= the last release.
        marks: "Mark point" button presses.
    """

    name: str
    pushes: tuple[ScriptedPush, ...]
    duration_s: float
    marks: tuple[Mark, ...] = ()
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for a, b in zip(self.pushes, self.pushes[1:], strict=False):
            if b.t_start < a.t_end:
                raise SimulationError("pushes overlap or are out of order", field="pushes",
                                      value=(a.t_end, b.t_start),
                                      expected="each push starting after the previous release")
        last = self.pushes[-1].t_end if self.pushes else 0.0
        if not (math.isfinite(self.duration_s) and self.duration_s >= last):
            raise SimulationError("session ends before the last release", field="duration_s",
                                  value=self.duration_s, expected=f">= {last:g} s")
        times = [m.t for m in self.marks]
        if times != sorted(times) or any(not (0.0 <= t <= self.duration_s) for t in times):
            raise SimulationError("marks out of order or outside the session", field="marks",
                                  value=times,
                                  expected=f"increasing times in [0, {self.duration_s:g}] s")
        object.__setattr__(self, "_starts", tuple(p.t_start for p in self.pushes))

    def force_at(self, t: float) -> Array:
        """Force of the hand at time ``t`` [s], base frame [N], shape (3,)."""
        i = bisect_right(self._starts, t) - 1
        if i < 0:
            return np.zeros(3)
        p = self.pushes[i]
        return p.scale(t) * np.asarray(p.force_base, dtype=float)

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """Wrench at the TCP, base frame [N, N·m], shape (6,) (a new array; torque zero).

        Args:
            t: Simulation time [s].
            tcp_position_base: TCP position, base frame [m], shape (3,) (unused).
        """
        w = np.zeros(6)
        w[:3] = self.force_at(t)
        return w


def rest(duration_s: float = 5.0) -> PushScript:
    """The ``rest`` script: nobody touches the robot for ``duration_s`` [s]."""
    return PushScript(name="rest", pushes=(), duration_s=duration_s)


def push_x(force_n: float = PUSH_FORCE_N, t_start: float = PUSH_START_S,
           push_s: float = PUSH_DURATION_S, after_s: float = 2.0) -> PushScript:
    """The ``push-x`` script: +x (base frame) with ``force_n`` [N] over ``[t_start, t_start +
    push_s)`` [s] (raised-cosine edges of :data:`PUSH_RAMP_S`), then ``after_s`` [s] without
    a hand."""
    p = ScriptedPush(t_start, t_start + push_s, (force_n, 0.0, 0.0))
    return PushScript(name="push-x", pushes=(p,), duration_s=p.t_end + after_s)


def diagonal_push(force_n: float = PUSH_FORCE_N, t_start: float = PUSH_START_S,
                  push_s: float = PUSH_DURATION_S, after_s: float = 2.5) -> PushScript:
    """The ``diagonal`` script: along (1, 1, 0)/√2 (base frame) with ``force_n`` [N] over
    ``[t_start, t_start + push_s)`` [s]; marks P1 half-way through the wait before the push and
    P2 1.5 s after the release (the robot at rest), then ``after_s`` [s] in all after release."""
    c = force_n / math.sqrt(2.0)
    p = ScriptedPush(t_start, t_start + push_s, (c, c, 0.0))
    marks = (Mark(0.5 * t_start, "P1"), Mark(p.t_end + 1.5, "P2"))
    return PushScript(name="diagonal", pushes=(p,), duration_s=p.t_end + after_s, marks=marks)


def random_pushes(seed: int, n_pushes: int = 8, *,
                  force_range_n: tuple[float, float] = (20.0, 60.0),
                  push_range_s: tuple[float, float] = (0.5, 2.0),
                  pause_range_s: tuple[float, float] = (0.5, 1.5),
                  ramp_range_s: tuple[float, float] = (0.05, 0.1),
                  t_first: float = PUSH_START_S, after_s: float = 2.0) -> PushScript:
    """The ``random`` script: ``n_pushes`` reproducible random pushes.

    Directions are uniform on the sphere (base frame); magnitude, length, pause before and
    onset/release ramp are uniform in their ranges. The same seed gives the same script.

    Args:
        seed: Random seed, >= 0.
        n_pushes: Number of pushes, >= 1.
        force_range_n: Force magnitude range [N].
        push_range_s, pause_range_s, ramp_range_s: Ranges of the push length (onset to release,
            low >= 2·ramp high), of the pause before the next onset and of the ramps [s].
        t_first: Onset of the first push [s].
        after_s: Time after the last release until the end of the session [s].

    Raises:
        SimulationError: Negative seed, no pushes, or inconsistent ranges.
    """
    if seed < 0 or n_pushes < 1:
        raise SimulationError("out of range", field="seed/n_pushes", value=(seed, n_pushes),
                              expected="seed >= 0 and n_pushes >= 1")
    ranges = (force_range_n, push_range_s, pause_range_s, ramp_range_s)
    if any(not (0.0 <= lo <= hi < math.inf) for lo, hi in ranges) \
            or push_range_s[0] < 2.0 * ramp_range_s[1]:
        raise SimulationError("bad ranges", field="random_pushes", value=ranges,
                              expected="0 <= low <= high, pushes at least twice the ramp")
    rng = np.random.default_rng([seed, 7])
    pushes: list[ScriptedPush] = []
    t = t_first
    for _ in range(n_pushes):
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        f = rng.uniform(*force_range_n) * d
        length = rng.uniform(*push_range_s)
        ramp = rng.uniform(*ramp_range_s)
        pushes.append(ScriptedPush(t, t + length, (float(f[0]), float(f[1]), float(f[2])), ramp))
        t += length + rng.uniform(*pause_range_s)
    return PushScript(name="random", pushes=tuple(pushes), duration_s=pushes[-1].t_end + after_s)


# ---------------------------------------------------------------------------------- registry
def make_operator(name: str, *, seed: int, tcp_start_base: ArrayLike) -> ScriptedOperator:
    """Build a scripted operator by name.

    Args:
        name: One of :data:`OPERATOR_NAMES`.
        seed: Random seed, >= 0 (used by ``random``).
        tcp_start_base: TCP position at the start, base frame [m], shape (3,) (used by
            ``seam``; checked for all).

    Returns:
        The operator, with ``name``, ``duration_s`` and ``marks``.

    Raises:
        SimulationError: Unknown name (the message lists the valid ones), negative seed, or a
            start position that is not 3 finite numbers.
    """
    if name not in OPERATOR_NAMES:
        raise SimulationError("unknown operator script", field="operator", value=name,
                              expected="one of " + ", ".join(OPERATOR_NAMES))
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise SimulationError("bad seed", field="seed", value=seed, expected="integer >= 0")
    start = vector3(tcp_start_base, "tcp_start_base")
    if name == "rest":
        return rest()
    if name == "push-x":
        return push_x()
    if name == "diagonal":
        return diagonal_push()
    if name == "random":
        return random_pushes(int(seed))
    return SeamOperator(start)
