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
from dataclasses import dataclass

from leadthrough.errors import ControlError, check_fields

__all__ = ["OperatorLimits"]


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
