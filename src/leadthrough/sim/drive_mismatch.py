"""What the realistic plant's drive trains have beyond the identification model (eq. 15–16).

The ideal plant's sliding friction has exactly eq. 15's shape. The realistic plant
(:mod:`leadthrough.sim.plant`) draws, per joint and robot instance:

* **Stribeck shape** exp(−|q̇/q̇ₛ|^δ) on the motor and the gear side, δ drawn from
  ``stribeck_exponent`` (eq. 15 has δ = 2). The generalised exponent and its span come from
  the friction survey of Armstrong-Hélouvry, Dupont and Canudas de Wit (Automatica 30(7), 1994:
  δ = 2 in Armstrong's Gaussian model, 0.5–1 in Bo and Pavelescu's fits); Bittencourt,
  Wernholt, Sander-Tavallaey and Brogårdh identify such an exponent on an industrial robot's
  joint ("An extended friction model to capture load and temperature effects in robot joints",
  IROS 2010).
* **Viscous friction with a mild nonlinearity**: of the viscous friction at the joint's velocity
  limit (the drive-train configuration's ``viscous``), a share ``viscous_power_share`` follows a
  degressive power law f_p·sgn(q̇)·|q̇|^α with α drawn from ``viscous_exponent`` (< 1), the rest
  stays linear::

      F_v(q̇) = f_v·q̇ + f_p·sgn(q̇)·|q̇|^α,   f_v·v_max + f_p·v_max^α = viscous·τ_max

  Gear meshes and pre-loaded bearings under elastohydrodynamic lubrication show such a
  degressive viscous curve (Waiboer, Aarts, Jonker, "Velocity dependence of joint friction in
  robotic manipulators with gear transmissions", Multibody Dynamics 2005). At a tenth of the
  velocity limit the default makes the viscous friction 8–65 % larger than the linear law's
  through the same value at the limit.
* **Load-dependent Coulomb friction** μ·|τ_transmitted| with μ drawn per joint from
  ``load_coefficient`` (the ideal plant: 1 % ± 25 %). Gear tooth and bearing friction grows
  with the transmitted torque: Bittencourt et al. (IROS 2010, an ABB arm) and Hamon, Gautier and
  Garrec ("Dynamic identification of robots with a dry friction model depending on load and
  velocity", IROS 2010, a Stäubli TX40) identify it as a Coulomb level growing linearly with
  the load torque, and on an industrial arm it is as large as the velocity effects at low
  speed. A precision gear's efficiency at rated torque (80–90 % for cycloid / RV and
  strain-wave gears) bounds the load-proportional loss from above; the default 3–10 % of the
  transmitted torque is within it. The simulator keeps μ constant over speed (the studies find
  it largest at low speed, where guiding happens).
* **Torque constant**: the true R·Kt differs from the drive file's by a factor drawn within
  ±``torque_constant_error`` per joint (motor Kt tolerances of a few per cent, its temperature
  dependence and the gear's efficiency at the operating point make the datasheet value an
  estimate). The servo and every model convert with the drive file's value.
* **Cogging**: a position-periodic motor torque A·sin(k·R·q + ϕ) at the joint, amplitude drawn
  within ``cogging`` × the joint's max torque and ``cogging_periods_per_motor_rev`` periods per
  motor revolution (the cogging and torque ripple of a permanent-magnet servo motor, of the
  order of 1 % of its rated torque; higher harmonics are filtered by the arm's inertia).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.drivetrain import DriveTrainTruth
from leadthrough.sim.plant import check_draw_ranges

__all__ = ["DriveMismatchConfig", "with_drive_mismatch"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DriveMismatchConfig:
    """How the realistic plant's drive trains are drawn (ranges sampled uniformly per joint).

    Attributes:
        stribeck_exponent: Range of the Stribeck shape exponent δ (eq. 15: 2) [-].
        viscous_power_share: Share of the viscous friction at the velocity limit that follows
            the power law [-].
        viscous_exponent: Range of the power law's exponent α [-].
        load_coefficient: Range of μ, Coulomb friction per N·m transmitted [-].
        torque_constant_error: Relative deviation of the true R·Kt, drawn within ± this [-].
        cogging: Range of the cogging amplitude, fraction of the joint's max torque [-].
        cogging_periods_per_motor_rev: Cogging periods per motor revolution k [-].
    """

    stribeck_exponent: tuple[float, float] = (0.5, 2.0)
    viscous_power_share: float = 0.3
    viscous_exponent: tuple[float, float] = (0.5, 0.9)
    load_coefficient: tuple[float, float] = (0.03, 0.10)
    torque_constant_error: float = 0.04
    cogging: tuple[float, float] = (0.001, 0.004)
    cogging_periods_per_motor_rev: float = 12.0

    def __post_init__(self) -> None:
        check_draw_ranges("drive_mismatch", self)
        if self.stribeck_exponent[0] <= 0.0 or self.viscous_exponent[0] <= 0.0:
            raise SimulationError("exponents must be > 0",
                                  field="drive_mismatch.stribeck_exponent/viscous_exponent",
                                  value=(self.stribeck_exponent, self.viscous_exponent),
                                  expected="exponents > 0")
        if self.torque_constant_error >= 0.5:
            raise SimulationError("out of range", field="drive_mismatch.torque_constant_error",
                                  value=self.torque_constant_error, expected="0 <= error < 0.5")
        if self.viscous_power_share > 1.0:
            raise SimulationError("out of range", field="drive_mismatch.viscous_power_share",
                                  value=self.viscous_power_share, expected="0 <= share <= 1")


def with_drive_mismatch(truth: DriveTrainTruth, robot: Robot, config: DriveMismatchConfig,
                        rng: np.random.Generator) -> DriveTrainTruth:
    """The ideal plant's drive train of an instance, with the realistic plant's mismatch.

    Args:
        truth: The instance's drive train as the ideal plant draws it.
        robot: The robot (velocity limits).
        config: The mismatch's ranges.
        rng: Random generator of the mismatch (not that of ``truth``).

    Returns:
        The realistic drive train: same friction levels, other shapes, larger load
        dependence, torque-constant errors and cogging.
    """
    n = robot.n

    def draw(bounds: tuple[float, float]) -> Array:
        return rng.uniform(bounds[0], bounds[1], n)

    vmax = robot.velocity_limit
    viscous_at_limit = truth.viscous * vmax          # N·m at the velocity limit
    alpha = draw(config.viscous_exponent)
    share = config.viscous_power_share
    return replace(
        truth,
        stribeck_exponent_motor=draw(config.stribeck_exponent),
        stribeck_exponent_gear=draw(config.stribeck_exponent),
        viscous=(1.0 - share) * truth.viscous,
        viscous_power=share * viscous_at_limit / vmax**alpha,
        viscous_exponent=alpha,
        load_coefficient=draw(config.load_coefficient),
        torque_constant_scale=1.0 + draw((-config.torque_constant_error,
                                          config.torque_constant_error)),
        cogging=draw(config.cogging) * robot.max_torque,
        cogging_frequency=config.cogging_periods_per_motor_rev * robot.gear_ratio,
        cogging_phase=draw((0.0, 2.0 * np.pi)),
    )
