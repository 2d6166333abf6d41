"""Finite Fourier series excitation trajectories (Swevers et al.), starting and ending at rest.

Per joint j, with ω_k = 2π·f0·k, k = 1..H::

    q_j(t)  = q0_j + Σ_k [ a_jk/ω_k·sin(ω_k t) − b_jk/ω_k·cos(ω_k t) ]
    q̇_j(t)  = Σ_k [ a_jk·cos(ω_k t) + b_jk·sin(ω_k t) ]
    q̈_j(t)  = Σ_k [ −a_jk·ω_k·sin(ω_k t) + b_jk·ω_k·cos(ω_k t) ]

The series is periodic with T = 1/f0. Velocity and acceleration are zero at t = 0 (hence at every
multiple of T) when Σ_k a_jk = 0 and Σ_k k·b_jk = 0; :class:`FourierTrajectory` enforces this by
construction, taking a_j1 and b_j1 as the dependent coefficients. Positions are linear in the
free coefficients, so joint position, velocity and acceleration limits are linear constraints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError

__all__ = ["FourierTrajectory", "TrajectorySamples"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TrajectorySamples:
    """Joint trajectory samples.

    Attributes:
        time: [s], shape (N,).
        q: Positions [rad], shape (N, n).
        qd: Velocities [rad/s], shape (N, n).
        qdd: Accelerations [rad/s²], shape (N, n).
    """

    time: Array
    q: Array
    qd: Array
    qdd: Array


@dataclass(frozen=True)
class FourierTrajectory:
    """A rest-to-rest periodic Fourier trajectory.

    Attributes:
        base_frequency: f0 [Hz]; the period is 1/f0.
        q0: Position offsets [rad], shape (n,).
        a: Free sine-velocity coefficients for k = 2..H [rad/s], shape (n, H−1).
        b: Free cosine-velocity coefficients for k = 2..H [rad/s], shape (n, H−1).
    """

    base_frequency: float
    q0: Array
    a: Array
    b: Array

    def __post_init__(self) -> None:
        if not (np.isfinite(self.base_frequency) and self.base_frequency > 0):
            raise DataError("base frequency must be positive", field="base_frequency",
                            value=self.base_frequency, expected="> 0 Hz")
        if self.a.shape != self.b.shape or self.a.shape[0] != self.q0.shape[0]:
            raise DataError("coefficient shapes do not match", field="a, b, q0",
                            value=(self.a.shape, self.b.shape, self.q0.shape),
                            expected="a, b of shape (n, H-1) and q0 of shape (n,)")

    @property
    def harmonics(self) -> int:
        """Number of harmonics H."""
        return int(self.a.shape[1]) + 1

    @property
    def period(self) -> float:
        """Period T = 1/f0 [s]."""
        return 1.0 / self.base_frequency

    def full_coefficients(self) -> tuple[Array, Array]:
        """All coefficients a, b of shape (n, H), including the dependent k = 1 terms."""
        k = np.arange(2, self.harmonics + 1)
        a1 = -self.a.sum(axis=1, keepdims=True)
        b1 = -(self.b * k).sum(axis=1, keepdims=True)
        return np.hstack([a1, self.a]), np.hstack([b1, self.b])

    @staticmethod
    def basis(time: Array, base_frequency: float, harmonics: int) -> tuple[Array, Array, Array]:
        """Matrices mapping the free coefficients [a_2..a_H, b_2..b_H] of one joint to q − q0,
        q̇ and q̈ at ``time``.

        Args:
            time: [s], shape (N,).
            base_frequency: f0 [Hz].
            harmonics: H.

        Returns:
            Bq, Bqd, Bqdd, each shape (N, 2·(H−1)).
        """
        t = np.asarray(time, dtype=float)[:, None]
        k = np.arange(1, harmonics + 1)[None, :]
        w = 2.0 * np.pi * base_frequency * k
        s, c = np.sin(w * t), np.cos(w * t)
        # Full-coefficient bases (N, H) for a and b.
        qa, qb = s / w, -c / w
        va, vb = c, s
        aa, ab = -s * w, c * w
        kk = np.arange(2, harmonics + 1)

        def reduce(fa: Array, fb: Array) -> Array:
            # a1 = −Σ a_k, b1 = −Σ k·b_k
            return np.hstack([fa[:, 1:] - fa[:, :1], fb[:, 1:] - fb[:, :1] * kk[None, :]])

        return reduce(qa, qb), reduce(va, vb), reduce(aa, ab)

    def sample(self, time: Array) -> TrajectorySamples:
        """Evaluate the trajectory.

        Args:
            time: Sample times [s], shape (N,).

        Returns:
            Positions, velocities and accelerations.
        """
        Bq, Bv, Ba = self.basis(time, self.base_frequency, self.harmonics)
        x = np.hstack([self.a, self.b])  # (n, 2(H−1))
        return TrajectorySamples(
            time=np.asarray(time, dtype=float),
            q=self.q0 + Bq @ x.T,
            qd=Bv @ x.T,
            qdd=Ba @ x.T,
        )

    def position_offset_at_start(self) -> Array:
        """q(0) − q0 [rad], shape (n,)."""
        Bq, _, _ = self.basis(np.zeros(1), self.base_frequency, self.harmonics)
        return (Bq @ np.hstack([self.a, self.b]).T)[0]

    def at_rate(self, duration: float, rate_hz: float) -> TrajectorySamples:
        """Sample from 0 to ``duration`` at ``rate_hz`` (inclusive of 0, exclusive of the end).

        Args:
            duration: [s], a multiple of the period to end at rest.
            rate_hz: Sample rate [Hz].
        """
        steps = round(duration * rate_hz)
        return self.sample(np.arange(steps) / rate_hz)
