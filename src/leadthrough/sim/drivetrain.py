"""The simulated robot's "true" drive train: richer than the identification model (eq. 15–16).

Per joint, all joint-side torques [N·m]:

* motor-side friction: Coulomb + Stribeck (exp(−(R·q̇/q̇sm)²), motor speed) + viscous;
* gear-side friction: Coulomb + Stribeck (exp(−(q̇/q̇sg)²), joint speed) + viscous;
* a load-dependent Coulomb part μ·|τ_transmitted| (gear tooth friction grows with load);
* a position-dependent ripple (gear meshing): the static friction is modulated by
  1 + ε·sin(k·R·q + ϕ), k mesh periods per motor revolution;
* rotor inertia R²·J_motor as MuJoCo armature.

All of the non-viscous friction (Coulomb + Stribeck + load + ripple, level g) acts through the
LuGre bristle model (Canudas de Wit et al. 1995), which gives presliding: below breakaway a
gear behaves like a stiff spring with memory, not like a rigid lock::

    ż = q̇ − |q̇|·z / z_ss(q̇),   z_ss = g / σ0,   F = σ0·z + σ1·e^{−(q̇/q̇_d)²}·ż

σ0 = g_static / presliding (the static level is reached after the presliding displacement), and
σ1 damps the presliding oscillation (a fraction of critical for the joint's inertia; it fades
out with speed, Olsson's modification, so it adds no viscous friction in sliding). This matters
in position mode: the servo's integrator holds the commanded position, so in steady state a
push changes the motor current by the full push even at standstill, and a stopped joint does
not hunt (a rigid Coulomb lock plus integral action gives a stick-slip limit cycle instead).

z is advanced with the exact exponential solution for constant q̇ over the step, which is
unconditionally stable; the bristle force is applied explicitly (its stiffness is far below the
1 kHz step's limit). Viscous friction is MuJoCo joint damping (implicit in the integrator).

Only f1 ≈ Coulomb_total + g_d, f2, q̇sm, f3, q̇sg and f4 ≈ viscous_total are representable by
eq. 15; the presliding dynamics, load dependence and ripple are deliberate model mismatch.

This is the ideal plant's drive train. The realistic plant (:mod:`leadthrough.sim.plant`) draws
more mismatch into the same parameters (:mod:`leadthrough.sim.drive_mismatch`): Stribeck
exponents δ other than 2 (exp(−|q̇/q̇ₛ|^δ)) and a nonlinear viscous part f_p·sgn(q̇)·|q̇|^α,
applied explicitly with the bristle force (the linear part stays MuJoCo damping).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.servo import mid_range_link_inertia

__all__ = ["DriveTrainConfig", "DriveTrainTruth", "sample_drive_truth"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DriveTrainConfig:
    """How the true drive train is drawn. Torques are fractions of each joint's max torque.

    Each value is multiplied per joint by a seeded random factor in [1 − spread, 1 + spread].

    Attributes:
        coulomb_motor: Motor-side Coulomb friction [-].
        coulomb_gear: Gear-side Coulomb friction [-].
        stribeck_motor: Motor-side Stribeck amplitude [-].
        stribeck_gear: Gear-side Stribeck amplitude [-].
        stribeck_velocity_motor: Motor-side Stribeck velocity [rad/s at the motor].
        stribeck_velocity_gear: Gear-side Stribeck velocity [rad/s at the joint].
        viscous: Total viscous friction at the joint's velocity limit [-].
        viscous_motor_share: Share of the viscous friction on the motor side [-].
        bristle: Extra velocity-independent friction g_d [-] (adds to Coulomb).
        bristle_presliding: Presliding displacement at the static level [rad at the joint].
        bristle_damping_ratio: σ1 as a fraction of critical damping of the presliding spring
            with the joint's nominal inertia [-].
        bristle_damping_velocity: Speed q̇_d above which σ1 fades out [rad/s at the joint].
        load_coefficient: μ, extra Coulomb friction per N·m transmitted [-].
        ripple: Relative amplitude ε of the mesh ripple of the static friction [-].
        ripple_periods_per_motor_rev: Mesh periods per motor revolution k [-].
        rotor_inertia_spread: Relative deviation of the true rotor inertia from the datasheet.
        spread: Per-joint random spread of all friction values [-].
    """

    coulomb_motor: float = 0.010
    coulomb_gear: float = 0.014
    stribeck_motor: float = 0.028
    stribeck_gear: float = 0.024
    stribeck_velocity_motor: float = 12.0
    stribeck_velocity_gear: float = 0.12
    viscous: float = 0.03
    viscous_motor_share: float = 0.5
    bristle: float = 0.003
    bristle_presliding: float = 2e-4
    bristle_damping_ratio: float = 0.7
    bristle_damping_velocity: float = 0.01
    load_coefficient: float = 0.01
    ripple: float = 0.05
    ripple_periods_per_motor_rev: float = 2.0
    rotor_inertia_spread: float = 0.1
    spread: float = 0.25

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (np.isfinite(v) and v >= 0.0):
                raise SimulationError("must be finite and >= 0", field=f"drive.{f.name}",
                                      value=v, expected="a finite number >= 0")
        for name in ("stribeck_velocity_motor", "stribeck_velocity_gear", "bristle_presliding",
                     "bristle_damping_velocity"):
            if getattr(self, name) <= 0.0:
                raise SimulationError("must be > 0", field=f"drive.{name}",
                                      value=getattr(self, name), expected="> 0")
        if self.spread >= 1.0 or self.rotor_inertia_spread >= 1.0:
            raise SimulationError("spread must be below 1", field="drive.spread",
                                  value=self.spread, expected="0 <= spread < 1")


@dataclass(frozen=True)
class DriveTrainTruth:
    """The drawn true drive-train parameters, joint side, each shape (n,).

    Attributes:
        armature: Rotor inertia R²·J_motor [kg·m²].
        coulomb_motor: [N·m]. coulomb_gear: [N·m].
        stribeck_motor: [N·m]. stribeck_gear: [N·m].
        stribeck_velocity_motor: [rad/s motor]. stribeck_velocity_gear: [rad/s joint].
        viscous: Total viscous friction [N·m·s/rad].
        bristle: g_d [N·m]. bristle_stiffness: σ0 [N·m/rad]. bristle_damping: σ1 [N·m·s/rad].
        bristle_presliding: Presliding displacement at the static level [rad].
        bristle_damping_velocity: q̇_d [rad/s].
        load_coefficient: μ [-]. ripple: ε [-]. ripple_frequency: k·R [periods/rad joint].
        ripple_phase: ϕ [rad].
        stribeck_exponent_motor: δ of exp(−|R·q̇/q̇sm|^δ) [-] (2 on the ideal plant).
        stribeck_exponent_gear: δ of exp(−|q̇/q̇sg|^δ) [-] (2 on the ideal plant).
        viscous_power: f_p of the nonlinear viscous part f_p·sgn(q̇)·|q̇|^α
            [N·m/(rad/s)^α] (0 on the ideal plant; :mod:`leadthrough.sim.drive_mismatch`).
        viscous_exponent: α [-].
        torque_constant_scale: True R·Kt over the drive file's [-] (1 on the ideal plant).
        cogging: Amplitude of the motor's cogging torque, joint side [N·m] (0 on the ideal
            plant). cogging_frequency: Its periods per rad of the joint [1/rad].
        cogging_phase: [rad].
    """

    armature: Array
    coulomb_motor: Array
    coulomb_gear: Array
    stribeck_motor: Array
    stribeck_gear: Array
    stribeck_velocity_motor: Array
    stribeck_velocity_gear: Array
    viscous: Array
    bristle: Array
    bristle_stiffness: Array
    bristle_damping: Array
    bristle_presliding: Array
    bristle_damping_velocity: Array
    load_coefficient: Array
    ripple: Array
    ripple_frequency: Array
    ripple_phase: Array
    stribeck_exponent_motor: Array
    stribeck_exponent_gear: Array
    viscous_power: Array
    viscous_exponent: Array
    torque_constant_scale: Array
    cogging: Array
    cogging_frequency: Array
    cogging_phase: Array

    def equivalent_eq15(self) -> dict[str, Array]:
        """The closest eq. 15 parameters (for tests and noise floors): f1..f4, q̇sm, q̇sg."""
        return {
            "f1": self.coulomb_motor + self.coulomb_gear + self.bristle,
            "f2": self.stribeck_motor,
            "qd_sm": self.stribeck_velocity_motor,
            "f3": self.stribeck_gear,
            "qd_sg": self.stribeck_velocity_gear,
            "f4": self.viscous,
        }


def sample_drive_truth(
    robot: Robot, config: DriveTrainConfig, rng: np.random.Generator
) -> DriveTrainTruth:
    """Draw the true drive train of a simulated robot.

    Args:
        robot: The robot (max torques, gear ratios, datasheet rotor inertias).
        config: Nominal fractions and spreads.
        rng: Random generator.

    Returns:
        The drawn parameters.
    """
    n = robot.n
    tmax = robot.max_torque

    def draw(value: float) -> Array:
        return value * (1.0 + config.spread * rng.uniform(-1.0, 1.0, n))

    bristle = draw(config.bristle) * tmax
    z_ss = draw(config.bristle_presliding)
    armature = robot.reflected_rotor_inertia * (
        1.0 + config.rotor_inertia_spread * rng.uniform(-1.0, 1.0, n))
    coulomb_motor = draw(config.coulomb_motor) * tmax
    coulomb_gear = draw(config.coulomb_gear) * tmax
    stribeck_motor = draw(config.stribeck_motor) * tmax
    stribeck_gear = draw(config.stribeck_gear) * tmax
    static = coulomb_motor + coulomb_gear + stribeck_motor + stribeck_gear + bristle
    sigma0 = static / z_ss
    inertia = mid_range_link_inertia(robot) + armature
    return DriveTrainTruth(
        armature=armature,
        coulomb_motor=coulomb_motor,
        coulomb_gear=coulomb_gear,
        stribeck_motor=stribeck_motor,
        stribeck_gear=stribeck_gear,
        stribeck_velocity_motor=draw(config.stribeck_velocity_motor),
        stribeck_velocity_gear=draw(config.stribeck_velocity_gear),
        viscous=draw(config.viscous) * tmax / robot.velocity_limit,
        bristle=bristle,
        bristle_stiffness=sigma0,
        bristle_damping=2.0 * config.bristle_damping_ratio * np.sqrt(sigma0 * inertia),
        bristle_presliding=z_ss,
        bristle_damping_velocity=np.full(n, config.bristle_damping_velocity),
        load_coefficient=draw(config.load_coefficient),
        ripple=draw(config.ripple),
        ripple_frequency=config.ripple_periods_per_motor_rev * robot.gear_ratio,
        ripple_phase=rng.uniform(0.0, 2.0 * np.pi, n),
        stribeck_exponent_motor=np.full(n, 2.0),
        stribeck_exponent_gear=np.full(n, 2.0),
        viscous_power=np.zeros(n),
        viscous_exponent=np.ones(n),
        torque_constant_scale=np.ones(n),
        cogging=np.zeros(n),
        cogging_frequency=np.zeros(n),
        cogging_phase=np.zeros(n),
    )
