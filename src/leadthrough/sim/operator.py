"""Pluggable "operator": who pushes on the simulated robot's TCP.

An operator returns the wrench it applies at the TCP, in the base frame, as
``[Fx, Fy, Fz, Tx, Ty, Tz]`` [N, N·m]. The simulator calls it once per physics step with the
simulation time and the TCP position, so it may react to the motion (a hand impedance, say).

A :class:`ScriptedOperator` also has a name, a session length and the times (:class:`Mark`) at
which the operator presses the "mark point" button; the scripts are in
:mod:`leadthrough.sim.operator_scripts`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leadthrough.errors import SimulationError
from leadthrough.session.record import Mark

__all__ = ["ConstantWrench", "Mark", "NoOperator", "Operator", "ScriptedOperator", "vector3"]

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
