"""Closed-loop velocity control, the comparison baseline [14] of the paper's Fig. 4.

The commanded velocity follows the estimated force through a first-order lag with zero target
velocity, per axis:

    v̇_i = (K_i·F̂_i − v_i) / T

discretised exactly for a force held over the cycle: v⁺ = v + (1 − e^(−dt/T))·(K·F̂ − v). There is
no dead band, so any estimator noise or bias moves the robot: at rest with a noisy F̂ the
commanded velocity is not zero and the TCP drifts. That is the point of the comparison; this law
exists only to reproduce Fig. 4 and shares :class:`AdmittanceLaw` with the virtual-friction law so
that the guiding controller can swap them.

The gains are not given in the paper; the defaults (0.0025 m/(s·N), 0.0025 rad/(s·N·m),
T = 0.2 s) give 0.1 m/s for a steady 40 N push. :func:`velocity_baseline` is the law (compiled:
Numba, ``nopython``, cached on disk) that the guiding cycle runs with ``controller="velocity"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import ControlError, check_fields

__all__ = ["VelocityBaselineConfig", "velocity_baseline"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class VelocityBaselineConfig:
    """Gains of the velocity baseline, validated once.

    Attributes:
        gain: K_i per axis (x, y, z, ωx, ωy, ωz) [m/(s·N), rad/(s·N·m)], 6 values ≥ 0.
        time_constant: T of the first-order lag [s], > 0.
    """

    gain: tuple[float, ...] = (0.0025,) * 6
    time_constant: float = 0.2

    def __post_init__(self) -> None:
        check_fields("velocity_baseline", self, [
            ("gain", len(self.gain) == 6 and all(math.isfinite(g) and g >= 0 for g in self.gain),
             "6 finite values >= 0 [m/(s·N), rad/(s·N·m)]"),
            ("time_constant", math.isfinite(self.time_constant) and self.time_constant > 0,
             "finite and > 0 s"),
        ], ControlError)

    def alpha(self, dt: float) -> float:
        """1 − e^(−dt/T) for a cycle of ``dt`` [s]."""
        return 1.0 - math.exp(-dt / self.time_constant)


@njit(cache=True, nogil=True)
def velocity_baseline(twist: Array, wrench: Array, gain: Array, alpha: float,
                           out: Array) -> None:
    """The velocity baseline's first-order lag, v⁺ = v + α·(K·F̂ − v) per axis: the desired
    twist after one cycle.

    Args:
        twist: Twist of the last cycle, shape (6,).
        wrench: Estimated wrench, shape (6,).
        gain: K per axis, shape (6,).
        alpha: 1 − e^(−dt/T).
        out: Desired twist, shape (6,); must not alias an input.
    """
    for i in range(6):
        out[i] = (gain[i] * wrench[i] - twist[i]) * alpha + twist[i]
