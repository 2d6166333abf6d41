"""The KR300's hydraulic weight counterbalance on axis 2 (Weigand et al., facts.toml).

Not part of the paper's model (eq. 21): a nitrogen spring adds a nonlinear torque on joint 2.
We subtract the authors' model of it from the measured joint-2 torque before identification and
validation, and say so. Its parameters are approximations of the authors' (piston diameter,
maximum operating temperature).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leadthrough.data.recording import Recording


def counterbalance_torque(q2: NDArray[np.float64], facts: dict) -> NDArray[np.float64]:
    """Hydraulic torque on joint 2 [N·m] for model angles q2 [rad] (formula of facts.toml)."""
    h = facts["hydraulic_counterbalance"]
    delta = q2 + np.deg2rad(95.0)
    base = h["D"] - h["k"]
    area = np.pi * (h["diameter_piston"] ** 2 - h["diameter_rod"] ** 2) / 4.0
    dl = np.sqrt(h["D"] ** 2 + h["k"] ** 2 - 2 * h["D"] * h["k"] * np.cos(delta)) - base
    lever = np.sin(delta) * h["D"] * h["k"] / (dl + base)
    pressure = (h["Z"] * h["R_specific"] * h["temperature"] * h["mass_nitrogen"]
                / (h["v_max"] - dl * area))
    return np.asarray(lever * pressure * area)


def without_counterbalance(rec: Recording, facts_path: Path) -> Recording:
    """The recording with the counterbalance torque removed from joint 2's torque."""
    facts = tomllib.loads(facts_path.read_text())
    assert rec.torque is not None
    torque = rec.torque.copy()
    torque[:, 1] -= counterbalance_torque(rec.q[:, 1], facts)
    return Recording(time=rec.time, q=rec.q, torque=torque, robot=rec.robot,
                     source=f"{rec.source} (hydraulic counterbalance removed)")
