"""Joint targets streamed once per controller cycle, kept within the controller's limits.

A controller that takes a joint target every cycle ``T`` (FANUC J519, a UR ``servoj`` program,
KUKA RSI) judges consecutive targets by their finite differences

    v_k = (q_k - q_{k-1}) / T,   a_k = (v_k - v_{k-1}) / T,   j_k = (a_k - a_{k-1}) / T

and refuses a target beyond its velocity, acceleration or jerk limit: J519 raises an alarm and
stops, a UR controller makes a protective stop on a ``servoj`` jump, a KUKA robot's speed
monitoring stops it. :class:`CycleLimiter` is the driver's last line before the wire: a target
within the limits (scaled by ``margin``) passes unchanged; any other is replaced by a target
that approaches it as fast as the limits allow. The acceleration asked for then is the one
that brings the velocity to the stream's own velocity plus a braking-limited approach,
``v_stream + sign(e) min(|e| / T, sqrt(A |e| / 2))`` for a position error ``e`` (the speed
from which a quarter of the acceleration limit stops the joint within ``|e|``: room is left for
the jerk limit, so the output does not overshoot), clipped to the accelerations that keep

* the jerk limit: ``|a - a_{k-1}| <= J T``;
* the acceleration limit: ``|a| <= A``;
* the velocity limit with room to brake: with the jerk limit, an acceleration ``a > 0`` can
  only be brought back to zero over ``a / J`` seconds, during which the velocity still grows by
  about ``a² / (2 J) + a T / 2`` (the discrete ramp), so ``v_{k-1} + a T + a² / (2 J) +
  a T / 2 <= V`` (and symmetrically below). Without a jerk limit this is ``v_{k-1} + a T <= V``.

When the bounds conflict (only possible if the previous state was already outside them) the
jerk limit wins. A limited target falls behind the stream; once the stream's next target is
again within reach of the limits the output is back on it exactly. Positions are not limited
here (the guiding controller keeps the joint limits; the controller checks them too).

The velocity bound with braking follows the jerk-limited stopping distance used by online
trajectory generators (Kröger, "On-Line Trajectory Generation in Robotic Systems", Springer
2010, ch. 4; ruckig's velocity interface); the finite-difference checks are those FANUC's J519
documentation describes for its velocity, acceleration and jerk limit tables (see
:mod:`leadthrough.drivers.fanuc_j519.limits`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DriverError

__all__ = ["CycleLimiter", "CycleLimits"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CycleLimits:
    """Per-joint limits a controller enforces on consecutive cycle targets.

    Attributes:
        velocity: [rad/s], shape (n,), > 0.
        acceleration: [rad/s²], shape (n,), > 0; None: not checked.
        jerk: [rad/s³], shape (n,), > 0; None: not checked.
    """

    velocity: Array
    acceleration: Array | None = None
    jerk: Array | None = None

    def __post_init__(self) -> None:
        n = self.velocity.shape
        for name in ("velocity", "acceleration", "jerk"):
            value = getattr(self, name)
            if value is None:
                continue
            if value.shape != n or not np.all(np.isfinite(value)) or np.any(value <= 0):
                raise DriverError("limits must be finite and > 0, one per joint",
                                  field=f"limits.{name}", value=np.asarray(value).tolist(),
                                  expected=f"shape {n}, finite, > 0")

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.velocity.shape[0])

    def scaled(self, factor: float) -> CycleLimits:
        """Every limit times ``factor``."""
        return CycleLimits(self.velocity * factor,
                           None if self.acceleration is None else self.acceleration * factor,
                           None if self.jerk is None else self.jerk * factor)


class CycleLimiter:
    """Keeps a stream of cycle targets within :class:`CycleLimits` (see the module doc).

    Args:
        limits: The controller's limits.
        cycle: Controller cycle T [s].
        margin: Fraction of each limit the output keeps (rounding of the wire format, e.g.
            float32 degrees, must not push a target over), 0 < margin <= 1.
    """

    def __init__(self, limits: CycleLimits, cycle: float, margin: float = 0.95) -> None:
        if not (math.isfinite(cycle) and cycle > 0):
            raise DriverError("out of range", field="cycle", value=cycle, expected="> 0 s")
        if not 0 < margin <= 1:
            raise DriverError("out of range", field="margin", value=margin,
                              expected="0 < margin <= 1")
        self.limits, self.cycle, self.margin = limits, cycle, margin
        self._lim = limits.scaled(margin)
        n = limits.n
        self._target = np.zeros(n)  # the stream's previous target
        self._q = np.zeros(n)
        self._v = np.zeros(n)
        self._a = np.zeros(n)
        self._out = np.zeros(n)
        self._before = np.zeros((3, n))  # q, v, a before the last target
        self.limited = 0     # targets changed so far
        self.last_limited = False

    @property
    def position(self) -> Array:
        """The last target sent [rad] (copy)."""
        return self._q.copy()

    def reset(self, q: Array) -> None:
        """Start from rest at ``q`` [rad] (the controller's current target)."""
        self._q[:] = q
        self._target[:] = q
        self._v[:] = 0.0
        self._a[:] = 0.0
        self._before[0], self._before[1], self._before[2] = q, 0.0, 0.0

    def _bounds(self) -> tuple[Array, Array]:
        """The acceleration interval of this cycle, velocity and acceleration bounds first,
        then intersected with the jerk bounds (jerk wins a conflict)."""
        lim, T, v = self._lim, self.cycle, self._v
        V, J = lim.velocity, lim.jerk
        if J is None:
            hi, lo = (V - v) / T, (-V - v) / T
        else:
            hi, lo = _braking_bound(V - v, J, T), -_braking_bound(V + v, J, T)
        if lim.acceleration is not None:
            hi = np.minimum(hi, lim.acceleration)
            lo = np.maximum(lo, -lim.acceleration)
        if J is not None:
            lo_j, hi_j = self._a - J * T, self._a + J * T
            lo, hi = np.clip(lo, lo_j, hi_j), np.clip(hi, lo_j, hi_j)
        return lo, hi

    def skip(self, cycles: int, extrapolate: bool = False) -> None:
        """Cycles the controller ran without a new target from us (lost or late packets).

        Most controllers hold the last target then (a UR program's ``servoj`` repeats it, RSI
        keeps the last correction with ``HOLDON``); with ``extrapolate`` the target moves on
        at the last velocity (the J519 emulator's documented assumption, until its watchdog).
        The limiter's state follows, so the next target is judged against what the
        controller did.

        Args:
            cycles: Cycles without a target (0: none).
            extrapolate: Whether the controller went on at the last velocity.
        """
        if cycles <= 0:
            return
        if extrapolate:
            self._q += self._v * (self.cycle * cycles)
            self._a[:] = 0.0
        elif cycles == 1:
            self._a[:] = -self._v / self.cycle
            self._v[:] = 0.0
        else:  # two held cycles or more: at rest
            self._v[:] = 0.0
            self._a[:] = 0.0

    def retract(self, extrapolate: bool = False) -> None:
        """The controller did not take the last target (it came too late): back to the state
        before it, then one cycle without a target (see :meth:`skip`)."""
        self._q[:], self._v[:], self._a[:] = self._before
        self.skip(1, extrapolate)

    def limit(self, q: Array) -> Array:
        """The target to send for ``q`` [rad], shape (n,) (finite: the caller checks).

        Returns:
            The target [rad]: ``q`` itself if it is within the limits, else the limited
            target (an internal array, valid until the next call).
        """
        T = self.cycle
        self._before[0], self._before[1], self._before[2] = self._q, self._v, self._a
        v = (q - self._q) / T
        a = (v - self._v) / T
        lo, hi = self._bounds()
        inside = bool(np.all((a >= lo) & (a <= hi)))
        if inside:
            self._out[:] = q
        else:
            a = np.clip(self._approach(q), lo, hi)
            v = self._v + a * T
            self._out[:] = self._q + v * T
            self.limited += 1
        self.last_limited = not inside
        self._a[:] = a
        self._v[:] = v
        self._q[:] = self._out
        self._target[:] = q
        return self._out

    def _approach(self, q: Array) -> Array:
        """The acceleration that closes the error to ``q`` without overshoot (module doc)."""
        T, lim = self.cycle, self._lim
        e = q - self._q
        v_stream = (q - self._target) / T
        brake = 0.5 * lim.acceleration if lim.acceleration is not None else lim.velocity / T
        # sqrt(brake |e|) = sqrt(2 (A/4) |e|): the speed a deceleration of A/4 stops in |e|
        v_goal = v_stream + np.sign(e) * np.minimum(np.abs(e) / T, np.sqrt(brake * np.abs(e)))
        return np.asarray((v_goal - self._v) / T)


def _braking_bound(room: Array, jerk: Array, T: float) -> Array:
    """Largest acceleration a with ``a T + a² / (2 J) + a T / 2 <= room`` (room = V - v);
    when there is no room left, the velocity bound ``room / T`` (a deceleration)."""
    root = jerk * (-1.5 * T + np.sqrt(np.maximum(2.25 * T * T + 2.0 * room / jerk, 0.0)))
    return np.where(room > 0, np.minimum(root, room / T), room / T)
