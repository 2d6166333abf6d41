"""Pluggable "operator": who pushes on the simulated robot's TCP.

An operator returns the wrench it applies at the TCP, in the base frame, as
``[Fx, Fy, Fz, Tx, Ty, Tz]`` [N, N·m]. The simulator calls it once per physics step with the
simulation time and the TCP position, so it may react to the motion (a hand impedance, say).

A :class:`ScriptedOperator` also has a name, a session length and the times (:class:`Mark`) at
which the operator presses the "mark point" button; the scripts are in
:mod:`leadthrough.sim.operator_scripts`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leadthrough.errors import SimulationError
from leadthrough.session_format import Mark

__all__ = ["ConstantWrench", "HandPush", "Mark", "NoOperator", "Operator", "ScriptedOperator",
           "vector3"]

Array = NDArray[np.float64]


@runtime_checkable
class Operator(Protocol):
    """Something that applies a wrench at the TCP."""

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """Wrench at the TCP in the base frame [N, N·m], shape (6,).

        Args:
            t: Simulation time [s].
            tcp_position_base: TCP position in the base frame [m], shape (3,).
        """
        ...


@runtime_checkable
class ScriptedOperator(Operator, Protocol):
    """An :class:`Operator` with a script: name, session length and button presses."""

    @property
    def name(self) -> str:
        """Script name."""
        ...

    @property
    def duration_s(self) -> float:
        """Sensible session length [s], including time to come to rest after the release."""
        ...

    @property
    def marks(self) -> tuple[Mark, ...]:
        """Times the "mark point" button is pressed, in time order."""
        ...


@dataclass(frozen=True)
class NoOperator:
    """Nobody touches the robot."""

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """Always zero."""
        return np.zeros(6)


@dataclass(frozen=True)
class ConstantWrench:
    """A constant wrench applied between two times.

    Attributes:
        wrench_base: [Fx, Fy, Fz, Tx, Ty, Tz] in the base frame [N, N·m].
        t_start: Start time [s].
        t_end: End time [s] (inf: never released).
    """

    wrench_base: tuple[float, ...]
    t_start: float = 0.0
    t_end: float = float("inf")
    _w: Array = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        w = np.asarray(self.wrench_base, dtype=float)
        if w.shape != (6,) or not np.all(np.isfinite(w)):
            raise SimulationError("wrench must be 6 finite numbers", field="wrench_base",
                                  value=self.wrench_base, expected="[Fx, Fy, Fz, Tx, Ty, Tz]")
        object.__setattr__(self, "_w", w)

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """The wrench while t_start <= t < t_end, else zero."""
        return self._w if self.t_start <= t < self.t_end else np.zeros(6)


class HandPush:
    """A hand on the tool that changes while the simulation runs: a person pushing with the
    mouse on a pendant (:mod:`leadthrough.pendant`).

    Either a constant force (:meth:`push`) or a grip through a spring and a damper on a
    handle the person moves (:meth:`hold`): ``F = k·(handle − p_tcp) − c·ṗ_tcp``, its magnitude
    capped, evaluated every physics step from the TCP the simulator passes (the velocity by
    differences of those positions), like a hand that follows the tool.

    :meth:`push`, :meth:`hold` and :meth:`release` may be called from any thread: each swaps
    in a new immutable grip, which the simulator reads once per step (a reference assignment
    is atomic in CPython): no step sees half a change, and the simulation never waits.
    """

    def __init__(self) -> None:
        self._grip: tuple[Array, float, float, float] | Array | None = None
        self._w: Array = np.zeros(6)
        self._last: tuple[float, Array] | None = None

    def push(self, force_base: ArrayLike) -> None:
        """A constant force at the TCP from the next physics step on.

        Args:
            force_base: [Fx, Fy, Fz] in the base frame [N].

        Raises:
            SimulationError: Not 3 finite numbers.
        """
        self._grip = vector3(force_base, "force_base")

    def hold(self, handle_base: ArrayLike, stiffness: float, damping: float,
             max_force: float) -> None:
        """Grip the tool through a spring and a damper on a handle at ``handle_base``.

        Args:
            handle_base: The handle's position, base frame [m], shape (3,).
            stiffness: k [N/m], ≥ 0.
            damping: c [N·s/m], ≥ 0.
            max_force: Cap on ‖F‖ [N], > 0.

        Raises:
            SimulationError: A value out of range.
        """
        handle = vector3(handle_base, "handle_base")
        if not (math.isfinite(stiffness) and stiffness >= 0 and math.isfinite(damping)
                and damping >= 0 and math.isfinite(max_force) and max_force > 0):
            raise SimulationError("bad grip", field="stiffness/damping/max_force",
                                  value=(stiffness, damping, max_force),
                                  expected="k >= 0 N/m, c >= 0 N·s/m, cap > 0 N, finite")
        self._grip = (handle, float(stiffness), float(damping), float(max_force))

    def release(self) -> None:
        """Let go: no force from the next step on."""
        self._grip = None

    @property
    def force_base(self) -> Array:
        """The force applied at the last physics step [N], shape (3,) (a copy)."""
        return self._w[:3].copy()

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """The hand's wrench at the TCP, base frame [N, N·m], shape (6,)."""
        grip, last = self._grip, self._last
        self._last = (t, tcp_position_base.copy())
        w = np.zeros(6)
        if isinstance(grip, tuple):
            handle, k, c, cap = grip
            f = k * (handle - tcp_position_base)
            if last is not None and t > last[0]:
                f -= c * (tcp_position_base - last[1]) / (t - last[0])
            norm = float(np.linalg.norm(f))
            w[:3] = f * (cap / norm) if norm > cap else f
        elif grip is not None:
            w[:3] = grip
        self._w = w
        return w


def vector3(value: ArrayLike, name: str) -> Array:
    """``value`` as a finite 3-vector, or a SimulationError naming ``name``."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SimulationError("must be 3 finite numbers", field=name, value=value,
                              expected="(x, y, z) in metres or newtons, base frame")
    return v
