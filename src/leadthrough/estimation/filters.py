"""Causal real-time filters (one sample per call, preallocated, no allocation in ``step``).

* :class:`StateVariableDifferentiator`: q̇ and q̈ from sampled q, the real-time counterpart of the
  offline differentiation used for calibration. A critically damped second-order low-pass with
  cut-off ω_c tracks q; its states give the filtered position and velocity and its input the
  acceleration. Discretised exactly (zero-order hold on q) for the step dt.
* :class:`FirstOrderLowPass`: y ← y + α·(x − y), α = 1 − exp(−2π·f_c·dt); used on τ_ext.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.estimation import kernels

__all__ = ["FirstOrderLowPass", "StateVariableDifferentiator"]

Array = NDArray[np.float64]


class StateVariableDifferentiator:
    """Causal estimate of velocity and acceleration from positions.

    The filter is x = [q_f, q̇_f] with q̈_f = ω²(q − q_f) − 2ω·q̇_f (critically damped); the
    acceleration output is the backward difference of q̇_f.

    Args:
        n: Number of channels.
        cutoff_hz: Cut-off frequency f_c [Hz] (ω = 2π·f_c).
        dt: Sample period [s].

    Raises:
        DataError: Cut-off not positive or above the Nyquist frequency.
    """

    def __init__(self, n: int, cutoff_hz: float, dt: float) -> None:
        if not (cutoff_hz > 0 and dt > 0 and cutoff_hz < 0.5 / dt):
            raise DataError("cut-off out of range", field="cutoff_hz", value=cutoff_hz,
                            expected=f"0 < f_c < {0.5 / dt:g} Hz (Nyquist)")
        w = 2.0 * np.pi * cutoff_hz
        A = np.array([[0.0, 1.0], [-w * w, -2.0 * w]])
        B = np.array([[0.0], [w * w]])
        M = np.zeros((3, 3))
        M[:2, :2] = A * dt
        M[:2, 2:] = B * dt
        E = scipy.linalg.expm(M)
        self.coef = np.array([E[0, 0], E[0, 1], E[1, 0], E[1, 1], E[0, 2], E[1, 2], 1.0 / dt])
        self.position = np.zeros(n)
        self.velocity = np.zeros(n)
        self.acceleration = np.zeros(n)

    def reset(self, q: Array) -> None:
        """Start at rest at ``q``."""
        self.position[:] = q
        self.velocity[:] = 0.0
        self.acceleration[:] = 0.0

    def step(self, q: Array) -> None:
        """Advance one sample with the measured positions ``q`` (n,).

        Exact discrete update of [p, v] (v' = a21·p + a22·v + b2·q, p' = a11·p + a12·v + b1·q);
        the acceleration is the backward difference of the filtered velocity, consistent with
        the discrete update (the continuous ω²(q − p) − 2ω·v is off by ≈ ω²·dt·q̇).
        """
        kernels.svf_step(self.coef, q, self.position, self.velocity, self.acceleration)


class FirstOrderLowPass:
    """First-order low-pass, y ← y + α·(x − y).

    Args:
        n: Number of channels.
        cutoff_hz: Cut-off frequency [Hz].
        dt: Sample period [s].
    """

    def __init__(self, n: int, cutoff_hz: float, dt: float) -> None:
        if not (cutoff_hz > 0 and dt > 0):
            raise DataError("cut-off out of range", field="cutoff_hz", value=cutoff_hz,
                            expected="> 0 Hz")
        self.alpha = 1.0 - float(np.exp(-2.0 * np.pi * cutoff_hz * dt))
        self.value = np.zeros(n)

    def reset(self, x: Array) -> None:
        """Set the output to ``x``."""
        self.value[:] = x

    def step(self, x: Array) -> Array:
        """Filter one sample; returns the (internal) output buffer."""
        kernels.low_pass_step(self.alpha, x, self.value)
        return self.value
