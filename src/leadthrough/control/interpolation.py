"""From 10 ms joint setpoints to 1 ms position-mode commands (position and velocity, no steps).

The guiding controller produces, every controller cycle T (10 ms), the joint position q_k it
wants at the end of the cycle and the joint velocity q̇_k it moves with; the IK advances
q_k = q_{k−1} + T·q̇_k, so q̇_k is the cycle's *mean* velocity. The servo wants a command every
1 ms. :class:`HermiteInterpolator` commands the **uniform quadratic B-spline of the setpoints**:
it joins the setpoints' midpoints m_k = (q_{k−1} + q_k)/2 by cubic Hermite segments

    q(s) = p₀ + h₀₁(s)·(p₁ − p₀) + T·(h₁₀(s)·v₀ + h₁₁(s)·v₁),  s = (t − t_k)/T ∈ [0, 1]
    h₀₁ = 3s² − 2s³,  h₁₀ = s³ − 2s² + s,  h₁₁ = s³ − s²

from the last command (p₀, v₀) = (m_{k−1}, (q_{k−1} − q_{k−2})/T) to
(p₁, v₁) = (m_k, (q_k − q_{k−1})/T). The chord p₁ − p₀ = T·(v₀ + v₁)/2 is the mean of the end
velocities, for which the cubic is the quadratic of constant acceleration (v₁ − v₀)/T: **inside
each cycle the command accelerates at exactly the setpoints' per-cycle change**, so a stop at
the controller's acceleration limit is one at the servo period too, and the command stays in
the convex hull of three consecutive setpoints (never beyond a joint limit the setpoints
respect). The price is half a cycle of delay (the command reaches m_k, not q_k, at t_k + T).
Position and velocity are continuous at every 1 ms sample (C¹); a held setpoint gives, one
cycle later, exactly constant commands and exactly zero velocity.

(Segments ending at the setpoints themselves, with v₁ = q̇_k, were used before: their end
velocity is the segment's mean, which makes the cubic accelerate at 4(v₁ − v₀)/T at its start
and −2(v₁ − v₀)/T at its end, 4× and −2× a ramp's acceleration within each cycle.) The setpoint's
q̇ is checked (finite) but not used: the velocities come from the setpoints' differences, which
is what keeps every segment a constant-acceleration one whatever the caller's q̇.
(Uniform quadratic B-splines: de Boor, *A Practical Guide to Splines*, ch. IX; the midpoint form
is the Chaikin/Riesenfeld construction.)

:class:`leadthrough.control.jerk_limit.JerkLimitedInterpolator` has the same interface and adds
jerk limits (``ruckig``, optional). Both take the setpoint once per cycle (``set_target``) and
produce one command per ``update``. The segment lives in one record (:func:`interpolator_dtype`)
and both steps are compiled (Numba, ``nopython``, cached on disk: :func:`start_segment`,
:func:`next_command`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from functools import cache
from typing import Any, Protocol

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import ControlError, check_period
from leadthrough.state_records import new_record, view

__all__ = [
    "CommandBuffer",
    "HermiteInterpolator",
    "InterpolatedCommand",
    "InterpolatorStatus",
    "JointInterpolator",
    "interpolator_dtype",
    "next_command",
    "start_segment",
]

Array = NDArray[np.float64]


class InterpolatorStatus(IntEnum):
    """Result of one interpolator update."""

    #: A command inside the current segment.
    WORKING = 0
    #: The command is the segment's end point (the next setpoint is due).
    FINISHED = 1
    #: Called again after the end without a new setpoint: holds the end position, q̇ = 0.
    STARVED = -1
    #: The interpolator failed (jerk-limited version only): holds the last command, q̇ = 0.
    ERROR = -2


@dataclass
class InterpolatedCommand:
    """One servo command, filled in place by an interpolator.

    Attributes:
        q: Joint position command [rad], shape (n,).
        qd: Joint velocity feed-forward [rad/s], shape (n,).
    """

    q: Array
    qd: Array


class CommandBuffer(Protocol):
    """What ``update`` writes into: anything with preallocated ``q`` and ``qd`` arrays of shape
    (n,) (a :class:`InterpolatedCommand`, or a driver's own command object)."""

    q: Array
    qd: Array


class JointInterpolator(Protocol):
    """Interface of the 10 ms → 1 ms interpolators."""

    def make_command(self) -> InterpolatedCommand:
        """A preallocated command."""
        ...

    def reset(self, q: Array) -> None:
        """Hold ``q`` at rest (shape (n,) [rad])."""
        ...

    def set_target(self, q: Array, qd: Array) -> None:
        """Start a new segment toward setpoint (q, q̇), once per controller cycle."""
        ...

    def update(self, out: CommandBuffer) -> InterpolatorStatus:
        """Advance by one servo period and write the command into ``out.q``, ``out.qd``."""
        ...

    def warm_up(self) -> None:
        """Prepare whatever the first ``update`` would otherwise prepare (compiled code)."""
        ...


@cache
def interpolator_dtype(n: int, substeps: int) -> np.dtype[Any]:
    """The Hermite interpolator's record for ``n`` joints and ``substeps`` commands a segment."""
    f8 = np.float64
    return np.dtype([
        # per substep k (s = (k + 1)/substeps): the position basis h01(s), T·h10(s), T·h11(s)
        # and the velocity basis h01'(s)/T, h10'(s), h11'(s)
        ("h01", f8, (substeps,)), ("h10", f8, (substeps,)), ("h11", f8, (substeps,)),
        ("dh01", f8, (substeps,)), ("dh10", f8, (substeps,)), ("dh11", f8, (substeps,)),
        # the segment: start position and velocity (the last command), end position and
        # velocity (the midpoint of the last two setpoints, their difference / T), end − start
        # [rad, rad/s]
        ("p0", f8, (n,)), ("v0", f8, (n,)), ("p1", f8, (n,)), ("v1", f8, (n,)),
        ("dp", f8, (n,)),
        # the last setpoint [rad] and 1/T [1/s]
        ("setpoint", f8, (n,)), ("rate", f8),
        # the last command [rad, rad/s] and the next substep
        ("q", f8, (n,)), ("qd", f8, (n,)), ("k", np.int64),
    ])


@njit(cache=True, nogil=True)
def start_segment(segment: NDArray[np.void], q: Array, qd: Array) -> bool:
    """A new segment from the last command to the midpoint of the last setpoint and (q, q̇).

    Args:
        segment: The interpolator's record (:func:`interpolator_dtype`, one element), in
            place.
        q: Setpoint [rad], shape (n,).
        qd: Velocity at the setpoint [rad/s], shape (n,): only checked (finite); the segment's
            end velocity is (q − last setpoint)/T.

    Returns:
        False, with nothing changed, for a setpoint of the wrong size or not finite.
    """
    seg = segment[0]
    n = seg.q.size
    if q.size != n or qd.size != n:
        return False
    for j in range(n):
        if not (np.isfinite(q[j]) and np.isfinite(qd[j])):
            return False
    for j in range(n):
        seg.p0[j] = seg.q[j]
        seg.v0[j] = seg.qd[j]
        seg.p1[j] = 0.5 * (seg.setpoint[j] + q[j])
        seg.v1[j] = (q[j] - seg.setpoint[j]) * seg.rate
        seg.dp[j] = seg.p1[j] - seg.q[j]
        seg.setpoint[j] = q[j]
    seg.k = 0
    return True


@njit(cache=True, nogil=True)
def next_command(segment: NDArray[np.void], q_out: Array, qd_out: Array) -> int:
    """The segment's next command: q = p0 + h01·Δp + T·h10·v0 + T·h11·v1,
    q̇ = h01'/T·Δp + h10'·v0 + h11'·v1; the last one is the segment's end (p1, v1) itself;
    past it, the end position is held at rest.

    Args:
        segment: The interpolator's record (:func:`interpolator_dtype`, one element); the last
            command and the substep advance.
        q_out: Position command [rad], shape (n,).
        qd_out: Velocity command [rad/s], shape (n,).

    Returns:
        ``InterpolatorStatus``: WORKING inside the segment, FINISHED at its end, STARVED past
        it.
    """
    seg = segment[0]
    k = seg.k
    substeps = seg.h01.size
    if k < substeps:
        seg.k = k + 1
    status = InterpolatorStatus.WORKING
    for j in range(q_out.size):
        if k >= substeps:
            seg.qd[j] = 0.0
            status = InterpolatorStatus.STARVED
        elif k == substeps - 1:
            seg.q[j] = seg.p1[j]
            seg.qd[j] = seg.v1[j]
            status = InterpolatorStatus.FINISHED
        else:
            dp, v0, v1 = seg.dp[j], seg.v0[j], seg.v1[j]
            seg.q[j] = dp * seg.h01[k] + v0 * seg.h10[k] + v1 * seg.h11[k] + seg.p0[j]
            seg.qd[j] = dp * seg.dh01[k] + v0 * seg.dh10[k] + v1 * seg.dh11[k]
        q_out[j] = seg.q[j]
        qd_out[j] = seg.qd[j]
    return status.value      # an int: returning the member would box its class every call


class HermiteInterpolator:
    """The quadratic B-spline of the controller's setpoints, as C¹ Hermite segments between
    their midpoints (no steps; constant acceleration within a cycle; see the module doc).

    Args:
        n: Number of joints.
        period: Controller cycle T [s].
        substeps: Servo commands per controller cycle (10 for 10 ms → 1 ms).

    Attributes:
        record: The segment (:func:`interpolator_dtype`).

    Raises:
        ControlError: ``period`` not positive or ``substeps`` < 1.
    """

    def __init__(self, n: int, period: float = 0.01, substeps: int = 10) -> None:
        check_period("period", period, ControlError)
        if substeps < 1:
            raise ControlError("out of range", field="substeps", value=substeps,
                               expected=">= 1")
        self.n = n
        self.period = period
        self.substeps = substeps
        self.record = new_record(interpolator_dtype(n, substeps))
        seg = self._seg = view(self.record)
        s = np.arange(1, substeps + 1) / substeps
        seg.h01, seg.h10 = 3 * s**2 - 2 * s**3, period * (s**3 - 2 * s**2 + s)
        seg.h11, seg.dh01 = period * (s**3 - s**2), (6 * s - 6 * s**2) / period
        seg.dh10, seg.dh11 = 3 * s**2 - 4 * s + 1, 3 * s**2 - 2 * s
        seg.rate = 1.0 / period
        seg.k = substeps

    def make_command(self) -> InterpolatedCommand:
        """A preallocated command."""
        return InterpolatedCommand(q=np.zeros(self.n), qd=np.zeros(self.n))

    def reset(self, q: Array) -> None:
        """Hold ``q`` at rest (shape (n,) [rad])."""
        seg = self._seg
        for name in ("p0", "v0", "p1", "v1", "dp", "q", "qd"):
            getattr(seg, name)[:] = 0.0
        seg.q = q
        seg.p1 = q
        seg.setpoint = q
        seg.k = self.substeps

    def set_target(self, q: Array, qd: Array) -> None:
        """New segment from the last command toward setpoint (q, q̇) [rad, rad/s], shape (n,)
        each: to the midpoint of the last setpoint and q, reached one cycle later.

        A setpoint of the wrong size or not finite is ignored, like a missed one: the current
        segment runs to its end, then the end is held (``STARVED``); no command is ever NaN.
        """
        start_segment(self.record, q, qd)

    def update(self, out: CommandBuffer) -> InterpolatorStatus:
        """Advance one servo period and write the command into ``out.q``, ``out.qd``."""
        return _STATUS[next_command(self.record, out.q, out.qd)]

    def warm_up(self) -> None:
        """Load (or compile) the compiled steps on a copy of the segment (nothing changes)."""
        seg, cmd = self.record.copy(), self.make_command()
        start_segment(seg, seg["q"][0], seg["qd"][0])
        next_command(seg, cmd.q, cmd.qd)


#: The statuses by value (a dictionary lookup is cheaper than the enum's constructor).
_STATUS = {int(s): s for s in InterpolatorStatus}
