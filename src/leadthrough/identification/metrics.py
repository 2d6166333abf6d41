"""Residual statistics and the paper's objective J (eq. 26).

The residual τ_ω = τ_measured − τ_model (the noise term of eq. 21) is evaluated per joint over
the joint equations used for identification (near-standstill samples excluded)::

    J = Σ_i |mean(τ_ω,i)| + K_ω · Σ_i std(τ_ω,i)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ResidualStats", "residual_stats"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ResidualStats:
    """Per-joint residual figures and J.

    Attributes:
        mean: mean(τ_ω,i) [N·m], shape (n,).
        std: std(τ_ω,i) [N·m], shape (n,).
        std_pct_max: std as a percentage of each joint's max torque [%], shape (n,).
        rms: RMS residual [N·m], shape (n,).
        rel_error_pct: 100·‖τ_ω‖ / ‖τ_measured‖ over all used equations [%].
        J: Σ|mean| + K_ω·Σ std [N·m].
        k_omega: K_ω used.
        samples: Used equations per joint, shape (n,).
    """

    mean: Array
    std: Array
    std_pct_max: Array
    rms: Array
    rel_error_pct: float
    J: float
    k_omega: float
    samples: NDArray[np.int64]


def residual_stats(
    tau_measured: Array,
    tau_model: Array,
    used: NDArray[np.bool_],
    max_torque: Array,
    k_omega: float = 1.0,
) -> ResidualStats:
    """Residual statistics of a model on data.

    Args:
        tau_measured: Measured joint torque [N·m], shape (N, n).
        tau_model: Model joint torque [N·m], shape (N, n).
        used: Equations to include, shape (N, n).
        max_torque: Max joint torque per joint [N·m], shape (n,).
        k_omega: Weight K_ω of the std term.

    Returns:
        The statistics.
    """
    r = tau_measured - tau_model
    w = used.astype(float)
    cnt = np.maximum(w.sum(axis=0), 1.0)
    mean = (r * w).sum(axis=0) / cnt
    var = ((r - mean) ** 2 * w).sum(axis=0) / cnt
    std = np.sqrt(var)
    rms = np.sqrt((r**2 * w).sum(axis=0) / cnt)
    denom = float(np.sqrt((tau_measured**2 * w).sum()))
    rel = 100.0 * float(np.sqrt((r**2 * w).sum())) / denom if denom > 0 else float("nan")
    return ResidualStats(
        mean=mean, std=std, std_pct_max=100.0 * std / max_torque, rms=rms,
        rel_error_pct=rel, J=float(np.abs(mean).sum() + k_omega * std.sum()),
        k_omega=k_omega, samples=w.sum(axis=0).astype(np.int64),
    )
