"""Virtual friction set automatically from the identified noise (paper eq. 36).

    eq. 36:  δ_i = r·|J^(−T)·τ̄_ω|_i

τ̄_ω is the identified noise per joint (params file ``[noise]``), J the TCP Jacobian in the
controller's frame at the current pose, so the threshold follows the pose: the wrench that the
model's residual torque would fake at the TCP never starts a motion. The paper uses r ≥ 1 for the
guiding friction δ and r ≥ 3 for the stopping friction δ_s.

J^(−T) is the damped pseudo-inverse A = (J Jᵀ + λ²·1)⁻¹·J (equal to J^(−T) for a square,
regular J; for a redundant arm the least-norm wrench), λ growing below a manipulability
threshold as in the estimator, so the threshold stays finite near a singularity.

Choice of the noise statistic (``basis``):

* ``"mean"`` (default, the paper): |A·τ̄_ω| with τ̄_ω the mean residual.
* ``"std"``: the standard deviation of the TCP wrench that independent joint noise of standard
  deviation σ_j produces, √(Σ_j A_ij²·σ_j²).
* ``"mean+std"``: the sum of both.

A good identification (ours: ``proposed``, ``consistent``) leaves a mean residual of almost zero,
and then the paper's choice gives almost no dead band: use ``"std"`` or ``"mean+std"``, or a floor
(``min_friction``), in that case. The floor applies to every basis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.damped_least_squares import damping_of
from leadthrough.errors import ControlError, check_fields

__all__ = ["AutoFriction", "AutoFrictionConfig"]

Array = NDArray[np.float64]

_BASES = ("mean", "std", "mean+std")


def _six_nonneg(values: tuple[float, ...]) -> bool:
    return len(values) == 6 and all(math.isfinite(v) and v >= 0 for v in values)


@dataclass(frozen=True)
class AutoFrictionConfig:
    """Settings of eq. 36, validated once.

    Attributes:
        basis: ``"mean"`` (paper), ``"std"`` or ``"mean+std"`` (see the module docstring).
        guiding_ratio: r for the guiding friction δ, ≥ 1.
        stopping_ratio: r for the stopping friction δ_s, ≥ 3 and ≥ ``guiding_ratio``.
        min_friction: Floor of δ per axis [N, N·m], 6 values ≥ 0.
        min_stopping_friction: Floor of δ_s per axis [N, N·m], 6 values ≥ ``min_friction``.
        manipulability_threshold: μ₀ below which the pseudo-inverse is damped.
        max_damping: λ_max.
    """

    basis: str = "mean"
    guiding_ratio: float = 1.0
    stopping_ratio: float = 3.0
    min_friction: tuple[float, ...] = (0.0,) * 6
    min_stopping_friction: tuple[float, ...] = (0.0,) * 6
    manipulability_threshold: float = 0.02
    max_damping: float = 0.05

    def __post_init__(self) -> None:
        check_fields("auto_friction", self, [
            ("basis", self.basis in _BASES, " or ".join(repr(b) for b in _BASES)),
            ("guiding_ratio", math.isfinite(self.guiding_ratio) and self.guiding_ratio >= 1,
             "r >= 1 (paper)"),
            ("stopping_ratio", math.isfinite(self.stopping_ratio) and self.stopping_ratio >= 3
             and self.stopping_ratio >= self.guiding_ratio, "r >= 3 and >= guiding_ratio"),
            ("min_friction", _six_nonneg(self.min_friction), "6 finite values >= 0 [N, N·m]"),
            ("min_stopping_friction", _six_nonneg(self.min_stopping_friction) and all(
                s >= f for s, f in zip(self.min_stopping_friction, self.min_friction,
                                       strict=True)),
             "6 finite values >= min_friction [N, N·m]"),
            ("manipulability_threshold", self.manipulability_threshold > 0,
             "> 0 (keeps J Jᵀ + λ² invertible)"),
            ("max_damping", self.max_damping > 0, "> 0 (keeps J Jᵀ + λ² invertible)"),
        ], ControlError)


class AutoFriction:
    """Friction thresholds from the identified noise, per pose (eq. 36).

    Args:
        noise_mean: τ̄_ω per joint [N·m], shape (n,) (params file ``[noise] mean``).
        noise_std: σ of τ_ω per joint [N·m], shape (n,) (``[noise] std``); required for the
            ``"std"`` and ``"mean+std"`` bases.
        config: Settings.

    Raises:
        ControlError: Wrong shape, non-finite or negative values, or σ missing.
    """

    def __init__(self, noise_mean: Array, noise_std: Array | None = None,
                 config: AutoFrictionConfig | None = None) -> None:
        self.config = cfg = config if config is not None else AutoFrictionConfig()
        mean = np.asarray(noise_mean, dtype=float)
        if mean.ndim != 1 or mean.size == 0 or not np.isfinite(mean).all():
            raise ControlError("not a finite vector", field="noise_mean",
                               value=np.asarray(noise_mean).tolist(),
                               expected="one finite value per joint [N·m]")
        n = mean.size
        std = np.zeros(n)
        if cfg.basis != "mean":
            if noise_std is None:
                raise ControlError("needed for this basis", field="noise_std",
                                   expected=f"σ per joint for basis {cfg.basis!r}")
            std = np.asarray(noise_std, dtype=float)
            if std.shape != (n,) or not (np.isfinite(std).all() and (std >= 0).all()):
                raise ControlError("wrong size, non-finite or negative", field="noise_std",
                                   value=std.tolist(), expected=f"{n} finite values >= 0 [N·m]")
        self.n = n
        self._mean = mean.copy()
        self._var = std * std
        self._use_mean = cfg.basis in ("mean", "mean+std")
        self._use_std = cfg.basis in ("std", "mean+std")
        self._min = np.asarray(cfg.min_friction, dtype=float)
        self._min_stop = np.asarray(cfg.min_stopping_friction, dtype=float)
        self._gram = np.zeros((6, 6))
        self._jacobian_noise = np.zeros(6)
        self._inverse_squared = np.zeros((6, n))
        self._noise = np.zeros(6)
        self._std_noise = np.zeros(6)

    def noise_wrench(self, jacobian: Array, manipulability: float, out: Array) -> None:
        """The noise statistic seen at the TCP, before the ratio r and the floor.

        Args:
            jacobian: TCP Jacobian in the controller's frame, shape (6, n) (Jᵀ·w = τ).
            manipulability: μ = √det(J Jᵀ) at the same pose (sets the damping).
            out: |A·τ̄_ω|, √(A²·σ²) or their sum per axis [N, N·m], shape (6,).
        """
        cfg = self.config
        lam = damping_of(manipulability, cfg.manipulability_threshold, cfg.max_damping)
        np.matmul(jacobian, jacobian.T, out=self._gram)
        self._gram.flat[::7] += lam * lam
        out[:] = 0.0
        if self._use_mean:
            np.matmul(jacobian, self._mean, out=self._jacobian_noise)
            np.abs(np.linalg.solve(self._gram, self._jacobian_noise), out=out)
        if self._use_std:
            np.square(np.linalg.solve(self._gram, jacobian), out=self._inverse_squared)
            np.matmul(self._inverse_squared, self._var, out=self._std_noise)
            np.sqrt(self._std_noise, out=self._std_noise)
            out += self._std_noise

    def update(self, jacobian: Array, manipulability: float, friction: Array,
               stopping_friction: Array) -> None:
        """δ and δ_s at the current pose (eq. 36).

        Args:
            jacobian: TCP Jacobian in the controller's frame, shape (6, n).
            manipulability: μ at the same pose.
            friction: δ = max(r·noise, floor) [N, N·m], shape (6,), written in place.
            stopping_friction: δ_s = max(r_s·noise, floor_s), shape (6,), written in place.
        """
        self.noise_wrench(jacobian, manipulability, self._noise)
        np.multiply(self._noise, self.config.guiding_ratio, out=friction)
        np.maximum(friction, self._min, out=friction)
        np.multiply(self._noise, self.config.stopping_ratio, out=stopping_friction)
        np.maximum(stopping_friction, self._min_stop, out=stopping_friction)
