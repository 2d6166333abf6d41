"""Pushing the simulated robot with the mouse: a spring from the tool to a handle.

The pendant shows a handle (a translation gizmo) at the tool. Dragging it away stretches a
spring between the handle and the TCP: the force on the tool is ``k·(p_handle − p_tcp)``,
``k`` in N per cm, its magnitude capped. As the arm follows, the TCP closes on the handle and the
force falls, until the virtual friction holds (eq. 33: δ/k short of the handle, 1.5 cm with
15 N and 10 N/cm), the way a hand pulling on a tool would feel. The force goes into the
simulated plant at the TCP (:class:`~leadthrough.sim.operator.HandPush`); the estimator sees it
only through the motor currents.

The cap (80 N by default) stays below the controller's collision threshold (150 N,
``SafetyConfig.max_force``), so that a hard drag is a push, not a crash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leadthrough.errors import ControlError, check_fields

__all__ = ["Hand", "PushSpring"]

Array = NDArray[np.float64]


class Hand(Protocol):
    """What pushes the simulated tool (:class:`leadthrough.sim.operator.HandPush`)."""

    def push(self, force_base: ArrayLike) -> None:
        """Apply ``force_base`` [N], shape (3,), at the TCP from the next step on."""
        ...

    def release(self) -> None:
        """No force from the next step on."""
        ...

    @property
    def force_base(self) -> Array:
        """The force applied now [N], shape (3,)."""
        ...


@dataclass(frozen=True)
class PushSpring:
    """The spring between the mouse's handle and the tool.

    Attributes:
        newton_per_cm: Stiffness k [N/cm].
        max_force_n: Cap on the force's magnitude [N].
    """

    newton_per_cm: float = 10.0
    max_force_n: float = 80.0

    def __post_init__(self) -> None:
        check_fields("push", self, [
            ("newton_per_cm", math.isfinite(self.newton_per_cm) and self.newton_per_cm > 0,
             "finite and > 0 N/cm"),
            ("max_force_n", math.isfinite(self.max_force_n) and self.max_force_n > 0,
             "finite and > 0 N"),
        ], ControlError)

    def force(self, handle_m: ArrayLike, tcp_m: ArrayLike) -> Array:
        """The force on the tool [N], shape (3,), base frame.

        Args:
            handle_m: Handle position [m], shape (3,).
            tcp_m: TCP position [m], shape (3,).
        """
        f = 100.0 * self.newton_per_cm * (np.asarray(handle_m, float) - np.asarray(tcp_m, float))
        norm = float(np.linalg.norm(f))
        if not math.isfinite(norm):
            return np.zeros(3)
        return f * (self.max_force_n / norm) if norm > self.max_force_n else f
