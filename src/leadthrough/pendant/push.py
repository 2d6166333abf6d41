"""Pushing the simulated robot with the mouse: a hand holding the tool through a spring.

The pendant shows a handle (a translation gizmo) at the tool. Dragging it away stretches a
spring and a damper between the handle and the TCP: the force on the tool is
``k·(p_handle − p_tcp) − c·ṗ_tcp``, ``k`` in N per cm, its magnitude capped. The simulated hand
(:class:`~leadthrough.sim.operator.HandPush`) evaluates it every physics step (1 kHz); the page
only moves the handle. As the arm follows, the TCP closes on the handle and the force falls
until the virtual friction holds (eq. 33: δ/k short of the handle, 1.5 cm with 15 N and
10 N/cm), the way a hand pulling on a tool feels. The damper is set for a damping ratio ζ with
the virtual mass in force, ``c = 2ζ·√(k·M)``: a spring on a mass alone would carry the arm past
the handle and back. The force goes into the simulated plant at the TCP; the estimator sees it
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
        """A constant force [N], shape (3,), at the TCP from the next step on."""
        ...

    def hold(self, handle_base: ArrayLike, stiffness: float, damping: float,
             max_force: float) -> None:
        """Grip the tool through a spring (k [N/m]) and a damper (c [N·s/m]) on a handle
        [m], the force capped [N]."""
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
    """The spring and damper between the mouse's handle and the tool.

    Attributes:
        newton_per_cm: Stiffness k [N/cm].
        max_force_n: Cap on the force's magnitude [N].
        damping_ratio: ζ of the spring on the virtual mass.
    """

    newton_per_cm: float = 10.0
    max_force_n: float = 80.0
    damping_ratio: float = 0.7

    def __post_init__(self) -> None:
        check_fields("push", self, [
            ("newton_per_cm", math.isfinite(self.newton_per_cm) and self.newton_per_cm > 0,
             "finite and > 0 N/cm"),
            ("max_force_n", math.isfinite(self.max_force_n) and self.max_force_n > 0,
             "finite and > 0 N"),
            ("damping_ratio", math.isfinite(self.damping_ratio) and self.damping_ratio >= 0,
             "finite and >= 0"),
        ], ControlError)

    @property
    def stiffness(self) -> float:
        """k [N/m]."""
        return 100.0 * self.newton_per_cm

    def damping(self, mass_kg: float) -> float:
        """c = 2ζ·√(k·M) for the virtual mass ``mass_kg`` [kg] [N·s/m]."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * max(mass_kg, 0.0))

    def hold(self, hand: Hand, handle_m: ArrayLike, mass_kg: float) -> None:
        """Grip ``hand`` on the handle at ``handle_m`` [m] with this spring."""
        hand.hold(np.asarray(handle_m, dtype=float), self.stiffness, self.damping(mass_kg),
                  self.max_force_n)
