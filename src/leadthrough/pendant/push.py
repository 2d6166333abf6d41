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

The simulated hand lives in the loop's process: the pendant's :class:`RemoteHand` sends
:class:`Push`, :class:`Hold` and :class:`Release` requests there
(:func:`apply_to_hand` applies them at a controller cycle's start) and reads the force back
from the snapshot.

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
from leadthrough.pendant.messages import (
    Request,
    RequestError,
    SimulatorRequest,
    check_finite,
    check_request,
    check_vector,
)

__all__ = ["MAX_HAND_FORCE_N", "MAX_REACH_M", "MAX_SPRING", "Hand", "Hold", "Push",
           "PushSpring", "Release", "RemoteHand", "apply_to_hand"]

Array = NDArray[np.float64]

#: The largest force a hand request may carry (a push, a spring's cap) [N]: the controller's
#: collision threshold (``SafetyConfig.max_force``).
MAX_HAND_FORCE_N = 150.0
#: The farthest a handle may be from the robot's base, per axis [m].
MAX_REACH_M = 10.0
#: The stiffest spring [N/m] and the strongest damper [N·s/m] a hold may carry.
MAX_SPRING = 1e5


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


@dataclass(frozen=True)
class Push(SimulatorRequest):
    """A constant force on the tool [N], base axes (x, y, z)."""

    force_base: tuple[float, float, float]

    def check(self) -> None:
        """Three finite numbers, their magnitude at most :data:`MAX_HAND_FORCE_N`."""
        f = check_vector(self.force_base, "force_base", 3, bound=MAX_HAND_FORCE_N)
        if math.hypot(*f) > MAX_HAND_FORCE_N:
            raise RequestError("push too strong", source="pendant", field="force_base",
                               value=f, expected=f"at most {MAX_HAND_FORCE_N:g} N")


@dataclass(frozen=True)
class Hold(SimulatorRequest):
    """Grip the tool through a spring and a damper on a handle (see :meth:`Hand.hold`)."""

    handle_base: tuple[float, float, float]
    stiffness: float
    damping: float
    max_force: float

    def check(self) -> None:
        """A finite handle within :data:`MAX_REACH_M`, a spring and damper within
        :data:`MAX_SPRING`, a cap in (0, :data:`MAX_HAND_FORCE_N`]."""
        check_vector(self.handle_base, "handle_base", 3, bound=MAX_REACH_M)
        check_finite(self.stiffness, "stiffness", low=0.0, high=MAX_SPRING)
        check_finite(self.damping, "damping", low=0.0, high=MAX_SPRING)
        check_finite(self.max_force, "max_force", low=0.0, high=MAX_HAND_FORCE_N,
                     low_open=True)


@dataclass(frozen=True)
class Release(SimulatorRequest):
    """Let go of the tool."""


def apply_to_hand(hand: Hand, request: object) -> bool:
    """Apply a hand request to ``hand`` (the loop's process); False if it is none."""
    if isinstance(request, Push):
        hand.push(request.force_base)
    elif isinstance(request, Hold):
        hand.hold(request.handle_base, request.stiffness, request.damping, request.max_force)
    elif isinstance(request, Release):
        hand.release()
    else:
        return False
    return True


class LoopLink(Protocol):
    """The pendant's link to the loop (:class:`~leadthrough.pendant.backend.LiveSession`)."""

    def send(self, request: Request) -> None:
        """Send a request to the loop."""
        ...

    def snapshot(self) -> object:
        """The latest snapshot (with ``push_base``), or None."""
        ...


class RemoteHand:
    """The simulated hand as the pendant's process sees it: requests out, force from the
    snapshot (the force the hand applied at the latest controller cycle)."""

    def __init__(self, link: LoopLink) -> None:
        self.link = link

    def push(self, force_base: ArrayLike) -> None:
        """A constant force [N], shape (3,), at the TCP from the next cycle on.

        Raises:
            RequestError: Not 3 finite numbers within :data:`MAX_HAND_FORCE_N` (nothing sent).
        """
        self._send(Push(_vec3(force_base, "force_base")))

    def hold(self, handle_base: ArrayLike, stiffness: float, damping: float,
             max_force: float) -> None:
        """Grip the tool through a spring on a handle (see :meth:`Hand.hold`).

        Raises:
            RequestError: A handle or spring out of range or not finite (nothing sent).
        """
        self._send(Hold(_vec3(handle_base, "handle_base"), stiffness, damping, max_force))

    def _send(self, request: Request) -> None:
        check_request(request)
        self.link.send(request)

    def release(self) -> None:
        """No force from the next cycle on."""
        self.link.send(Release())

    @property
    def force_base(self) -> Array:
        """The force the hand applied at the latest controller cycle [N], shape (3,)."""
        snap = self.link.snapshot()
        push = getattr(snap, "push_base", None)
        return np.zeros(3) if push is None else np.asarray(push, dtype=float)


def _vec3(v: ArrayLike, field: str) -> tuple[float, float, float]:
    try:
        a = np.asarray(v, dtype=float).reshape(3)
    except (TypeError, ValueError) as e:
        raise RequestError("not 3 numbers", source="pendant", field=field,
                           value=type(v).__name__, expected="3 finite numbers") from e
    return float(a[0]), float(a[1]), float(a[2])
