"""Causal real-time filters of the force estimate (one sample per call, nothing allocated).

* The state-variable differentiator: q̇ and q̈ from sampled q, the real-time counterpart of the
  offline differentiation used for calibration. A critically damped second-order low-pass with
  cut-off ω_c tracks q; its states give the filtered position and velocity and its input the
  acceleration. Discretised exactly (zero-order hold on q) for the step dt
  (:func:`differentiator_coefficients`, :func:`differentiate`), with missed samples bridged
  (:func:`bridge_gap`).
* The first-order low-pass y ← y + α·(x − y), α = 1 − exp(−2π·f_c·dt), on τ_ext
  (:func:`low_pass_alpha`; the estimator applies it in
  :mod:`~leadthrough.estimation.external_torque`).

The per-sample steps are compiled (Numba, ``nopython``, cached on disk).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.state_records import new_record, view

__all__ = [
    "DIFFERENTIATOR_DTYPE",
    "MAX_GAP_SAMPLES",
    "bridge_gap",
    "differentiate",
    "differentiator_coefficients",
    "low_pass_alpha",
    "restart_differentiator",
]

Array = NDArray[np.float64]

#: The exact discrete update of the differentiator's state [p, v] for one step dt:
#: v' = a21·p + a22·v + b2·q, p' = a11·p + a12·v + b1·q; ``inverse_dt`` = 1/dt for q̈.
DIFFERENTIATOR_DTYPE = np.dtype([
    ("a11", np.float64), ("a12", np.float64), ("a21", np.float64), ("a22", np.float64),
    ("b1", np.float64), ("b2", np.float64), ("inverse_dt", np.float64)])

#: Most missed samples the differentiator steps through (a longer gap: its last ones, from a
#: restart with the gap's mean velocity).
MAX_GAP_SAMPLES = 100


def differentiator_coefficients(cutoff_hz: float, dt: float) -> NDArray[np.void]:
    """The differentiator's discrete update (:data:`DIFFERENTIATOR_DTYPE`) for a cut-off and a
    sample period: q̈_f = ω²(q − q_f) − 2ω·q̇_f, ω = 2π·f_c, exact for q held over dt.

    Args:
        cutoff_hz: f_c [Hz].
        dt: Sample period [s].

    Raises:
        DataError: Cut-off not positive or above the Nyquist frequency.
    """
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
    coef = new_record(DIFFERENTIATOR_DTYPE)
    c = view(coef)
    c.a11, c.a12, c.a21, c.a22 = E[0, 0], E[0, 1], E[1, 0], E[1, 1]
    c.b1, c.b2, c.inverse_dt = E[0, 2], E[1, 2], 1.0 / dt
    return coef


def low_pass_alpha(cutoff_hz: float, dt: float) -> float:
    """α = 1 − exp(−2π·f_c·dt) of the first-order low-pass y ← y + α·(x − y).

    Raises:
        DataError: Cut-off or period not positive.
    """
    if not (cutoff_hz > 0 and dt > 0):
        raise DataError("cut-off out of range", field="cutoff_hz", value=cutoff_hz,
                        expected="> 0 Hz")
    return 1.0 - float(np.exp(-2.0 * np.pi * cutoff_hz * dt))


@njit(cache=True, nogil=True)
def differentiate(c: Any, q: Array, position: Array, velocity: Array,
                  acceleration: Array) -> None:
    """One exact-discretised step of the state-variable differentiator (in place).

    The acceleration is the backward difference of the filtered velocity, consistent with the
    discrete update (the continuous ω²(q − p) − 2ω·v is off by ≈ ω²·dt·q̇).

    Args:
        c: The discrete update (a record of :data:`DIFFERENTIATOR_DTYPE`).
        q: Measured positions, shape (n,).
        position: Filtered positions (state), shape (n,).
        velocity: Filtered velocities (state), shape (n,).
        acceleration: Output: backward difference of the filtered velocity, shape (n,).
    """
    for j in range(q.size):
        v_new = c.a21 * position[j] + c.a22 * velocity[j] + c.b2 * q[j]
        position[j] = c.a11 * position[j] + c.a12 * velocity[j] + c.b1 * q[j]
        acceleration[j] = (v_new - velocity[j]) * c.inverse_dt
        velocity[j] = v_new


@njit(cache=True, nogil=True)
def restart_differentiator(q: Array, position: Array, velocity: Array,
                           acceleration: Array) -> None:
    """The differentiator at rest at ``q``."""
    for j in range(q.size):
        position[j] = q[j]
        velocity[j] = 0.0
        acceleration[j] = 0.0


@njit(cache=True, nogil=True)
def bridge_gap(c: Any, dt: float, q: Array, t: float, last_q: Array, last_t: float,
               gap_q: Array, position: Array, velocity: Array, acceleration: Array) -> None:
    """Samples missed since the last one (t advanced by k ≥ 2 periods): step the
    differentiator through q interpolated linearly between the two samples, so that the jump
    of q over the gap is not differentiated as one period's motion. Of a gap longer than
    :data:`MAX_GAP_SAMPLES` only the last that many are stepped, from a restart at the
    interpolated position with the gap's mean velocity (the work per sample stays bounded). A
    t that repeats or goes back is treated as one period.

    Args:
        c: The discrete update (:data:`DIFFERENTIATOR_DTYPE`).
        dt: Sample period [s].
        q: This sample's positions, shape (n,).
        t: Its time [s].
        last_q: The last sample's positions, shape (n,).
        last_t: Its time [s].
        gap_q: Work space, shape (n,).
        position: Filtered positions (state), shape (n,).
        velocity: Filtered velocities (state), shape (n,).
        acceleration: Its output, shape (n,).
    """
    elapsed = t - last_t
    periods = elapsed / dt
    if periods < 1.5:
        return
    missed = int(min(periods, 1e9) + 0.5) - 1
    first = max(1, missed - MAX_GAP_SAMPLES + 1)
    if first > 1:
        w = (first - 1) / (missed + 1.0)
        for j in range(q.size):
            position[j] = last_q[j] + w * (q[j] - last_q[j])
            velocity[j] = (q[j] - last_q[j]) / elapsed
            acceleration[j] = 0.0
    for m in range(first, missed + 1):
        w = m / (missed + 1.0)
        for j in range(q.size):
            gap_q[j] = last_q[j] + w * (q[j] - last_q[j])
        differentiate(c, gap_q, position, velocity, acceleration)
