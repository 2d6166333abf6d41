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
T = 0.2 s) give 0.1 m/s for a steady 40 N push.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding_kernel import LAW_VELOCITY, velocity_baseline_step
from leadthrough.errors import ControlError, check_fields, check_period

__all__ = ["VelocityBaseline", "VelocityBaselineConfig"]

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


class VelocityBaseline:
    """First-order velocity law [14]; an :class:`AdmittanceLaw` (ignores the friction).

    Args:
        config: Gains and time constant.
        dt: Controller cycle [s].

    Raises:
        ControlError: ``dt`` not finite and positive.
    """

    def __init__(self, config: VelocityBaselineConfig | None = None, dt: float = 0.01) -> None:
        check_period("dt", dt, ControlError)
        self.config = cfg = config if config is not None else VelocityBaselineConfig()
        self.dt = dt
        self.law_id = LAW_VELOCITY
        #: K_i per axis.
        self.coefficients = np.asarray(cfg.gain, dtype=float)
        #: 1 − e^(−dt/T).
        self.alpha = 1.0 - math.exp(-dt / cfg.time_constant)

    def step(self, twist: Array, wrench: Array, friction: Array, stopping_friction: Array,
             out: Array) -> None:
        """Desired twist after one cycle: v⁺ = v + (1 − e^(−dt/T))·(K·F̂ − v).

        Args:
            twist: Commanded twist of the last cycle, shape (6,) [m/s, rad/s].
            wrench: Estimated operator wrench F̂, shape (6,) [N, N·m].
            friction: Ignored (no dead band in [14]).
            stopping_friction: Ignored.
            out: Desired twist, shape (6,), written in place; must not alias an input.
        """
        velocity_baseline_step(twist, wrench, self.coefficients, self.alpha, out)
