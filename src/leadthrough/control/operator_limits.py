"""What an operator may change of the guiding law at the robot, and within which bounds.

A pendant lets the person at the robot switch the frame and the enabled axes and tune the
virtual mass and friction (eq. 31–33). The integrator who commissions the cell sets the bounds
here, in the controller's configuration (:attr:`GuidingConfig.operator_limits
<leadthrough.control.guiding_types.GuidingConfig.operator_limits>`); a value asked outside them is
clamped to the nearest bound, never refused silently and never applied as asked
(:meth:`GuidingController.adjust <leadthrough.control.guiding.GuidingController.adjust>` reports
what it applied).

Why bounds at all: the speed and acceleration limits (Table IV) bound the motion whatever the
mass, but

* the **friction** δ is what holds the robot still against the estimator's error (eq. 33: no
  motion below δ). Below the error of the force estimate the arm creeps by itself: on the
  simulated er20 that error is about 1 N at rest after the tare and 9 N RMS under 20–100 N
  pushes (README, "External force and payload"), so the default floor is 10 N (3 N·m), and
  the ceiling, 60 N, keeps a push possible by hand below the collision threshold (150 N);
* the **mass** M sets the response to a push: (F − δ)/M. A very light mass turns the
  estimator's noise into jerky motion that the acceleration limit then clips; a very heavy one
  makes the robot feel stuck, which an operator answers by pushing harder, towards the
  collision threshold.

The defaults are choices for the simulated er20 (Table IV's 1000 kg and 15 N lie inside), not
values from the paper.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from leadthrough.errors import ControlError, check_fields

if TYPE_CHECKING:
    from leadthrough.control.guiding_types import GuidingConfig

__all__ = ["OperatorLimits", "adjusted_config"]


def _range(bounds: tuple[float, float], positive: bool) -> bool:
    lo, hi = bounds
    return (len(bounds) == 2 and math.isfinite(lo) and math.isfinite(hi) and lo <= hi
            and (lo > 0 if positive else lo >= 0))


@dataclass(frozen=True)
class OperatorLimits:
    """Bounds of the settings an operator may change at the robot, validated once.

    Attributes:
        linear_mass: (min, max) translational virtual mass, x, y and z alike [kg].
        angular_mass: (min, max) rotational virtual inertia, ωx, ωy and ωz alike [kg·m²].
        linear_friction: (min, max) virtual friction δ of x, y and z [N].
        angular_friction: (min, max) virtual friction δ of ωx, ωy and ωz [N·m].
    """

    linear_mass: tuple[float, float] = (50.0, 2000.0)
    angular_mass: tuple[float, float] = (5.0, 2000.0)
    linear_friction: tuple[float, float] = (10.0, 60.0)
    angular_friction: tuple[float, float] = (3.0, 60.0)

    def __post_init__(self) -> None:
        check_fields("operator_limits", self, [
            ("linear_mass", _range(self.linear_mass, True), "(min, max), 0 < min <= max [kg]"),
            ("angular_mass", _range(self.angular_mass, True),
             "(min, max), 0 < min <= max [kg·m²]"),
            ("linear_friction", _range(self.linear_friction, False),
             "(min, max), 0 <= min <= max [N]"),
            ("angular_friction", _range(self.angular_friction, False),
             "(min, max), 0 <= min <= max [N·m]"),
        ], ControlError)

    def clamp_mass(self, linear: float, angular: float) -> tuple[float, float]:
        """The virtual mass and inertia asked, clamped to the bounds [kg, kg·m²].

        Raises:
            ControlError: A value that is not a finite number.
        """
        return (_clamp("mass.linear", linear, self.linear_mass),
                _clamp("mass.angular", angular, self.angular_mass))

    def clamp_friction(self, linear: float, angular: float) -> tuple[float, float]:
        """The virtual friction asked, clamped to the bounds [N, N·m].

        Raises:
            ControlError: A value that is not a finite number.
        """
        return (_clamp("friction.linear", linear, self.linear_friction),
                _clamp("friction.angular", angular, self.angular_friction))


def _clamp(name: str, value: float, bounds: tuple[float, float]) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as e:
        raise ControlError("not a number", field=name, value=value,
                           expected=f"a number in [{bounds[0]:g}, {bounds[1]:g}]") from e
    if not math.isfinite(v):
        raise ControlError("not finite", field=name, value=value,
                           expected=f"a number in [{bounds[0]:g}, {bounds[1]:g}]")
    return min(max(v, bounds[0]), bounds[1])


def adjusted_config(config: GuidingConfig, commissioned: GuidingConfig, *,
                    frame: str | None = None, axes_enabled: Sequence[bool] | None = None,
                    mass: tuple[float, float] | None = None,
                    friction: tuple[float, float] | None = None) -> GuidingConfig:
    """The controller's settings with an operator's change, mass and friction clamped to
    ``config.operator_limits``.

    Args:
        config: The settings in force.
        commissioned: The settings the controller was built with: the stopping friction δ_s
            stays theirs, raised to δ if the operator's δ exceeds it.
        frame: ``"base"`` or ``"tool"``; None: unchanged.
        axes_enabled: 6 booleans (x, y, z, ωx, ωy, ωz); None: unchanged.
        mass: (translational [kg], rotational [kg·m²]) virtual mass; None: unchanged.
        friction: (translational [N], rotational [N·m]) virtual friction δ; None: unchanged.

    Raises:
        ControlError: An unknown frame, not 6 booleans, a mass with the velocity law, a
            friction with the automatic friction (eq. 36 sets it), or a value that is not a
            finite number.
    """
    vf = config.virtual_friction
    changes: dict[str, object] = {}
    if frame is not None:
        changes["frame"] = frame
    if axes_enabled is not None:
        axes = tuple(axes_enabled)
        if len(axes) != 6 or not all(isinstance(a, bool) for a in axes):
            raise ControlError("not 6 booleans", field="axes_enabled", value=axes,
                               expected="6 booleans (x, y, z, ωx, ωy, ωz)")
        changes["axes_enabled"] = axes
    if mass is not None:
        if config.controller != "virtual-friction":
            raise ControlError("the velocity law has no virtual mass", field="mass",
                               value=mass, expected="the 'virtual-friction' controller")
        m, inertia = config.operator_limits.clamp_mass(*mass)
        vf = replace(vf, mass=(m,) * 3 + (inertia,) * 3)
    if friction is not None:
        if config.friction_mode != "fixed":
            raise ControlError("the friction is automatic (eq. 36)", field="friction",
                               value=friction, expected="friction_mode 'fixed'")
        f, t = config.operator_limits.clamp_friction(*friction)
        delta = (f,) * 3 + (t,) * 3
        stop = tuple(max(s, d) for s, d in zip(commissioned.virtual_friction.stopping_friction,
                                               delta, strict=True))
        vf = replace(vf, friction=delta, stopping_friction=stop)
    return replace(config, virtual_friction=vf, **changes)  # type: ignore[arg-type]
