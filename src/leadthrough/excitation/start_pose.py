"""The start configuration of a friction experiment, checked once against the joint limits."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.robot.description import Robot

__all__ = ["checked_start"]

Array = NDArray[np.float64]


def checked_start(robot: Robot, q_start: Array | None, margin: float) -> Array:
    """The start configuration, finite and within the joint limits less ``margin``.

    Args:
        robot: The robot.
        q_start: Start configuration [rad], shape (n,); None: the neutral pose.
        margin: Distance to keep from each joint limit [rad].

    Returns:
        The configuration as a float array [rad], shape (n,).

    Raises:
        DataError: Wrong size, not finite, or outside the limits less the margin (naming the
            joint, its value and the allowed interval).
    """
    n = robot.n
    q0 = robot.neutral() if q_start is None else np.asarray(q_start, dtype=float)
    if q0.shape != (n,) or not np.all(np.isfinite(q0)):
        raise DataError("wrong start configuration", field="q_start", value=np.ravel(q0).tolist(),
                        expected=f"{n} finite joint positions [rad]")
    lo = robot.lower_limits + margin
    hi = robot.upper_limits - margin
    if np.any(q0 < lo) or np.any(q0 > hi):
        j = int(np.argmax((q0 < lo) | (q0 > hi)))
        raise DataError("start outside the joint limits (with margin)",
                        field=f"q_start[{robot.joint_names[j]}]", value=float(q0[j]),
                        expected=f"within [{lo[j]:.3f}, {hi[j]:.3f}] rad")
    return q0
