"""Poses to start from: a comfortable, non-singular configuration for hand guiding."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.robot.description import Robot

__all__ = ["guide_start_pose"]

Array = NDArray[np.float64]


def guide_start_pose(robot: Robot) -> Array:
    """A comfortable, non-singular start pose for a 6R arm [rad], shape (n,): the elbow bent by
    0.9 rad and the wrist by −1.2 rad from the neutral pose (clipped into the limits). For the
    er20 the TCP is then 0.87 m out and 0.81 m up with the tool pointing forward, about half way
    to the edge of the workspace, so a push of half a metre in any direction stays clear of the
    stretched-arm singularity."""
    q = robot.neutral()
    if robot.n >= 5:
        q[2] += 0.9
        q[4] -= 1.2
    return np.clip(q, robot.lower_limits + 0.05, robot.upper_limits - 0.05)
