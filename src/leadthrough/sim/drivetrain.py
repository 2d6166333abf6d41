"""The simulated robot's "true" drive train: richer than the identification model (eq. 15–16).

Per joint, all joint-side torques [N·m]:

* motor-side friction: Coulomb + Stribeck (exp(−(R·q̇/q̇sm)²), motor speed) + viscous;
* gear-side friction: Coulomb + Stribeck (exp(−(q̇/q̇sg)²), joint speed) + viscous;
* a dynamic, LuGre-type bristle component (presliding hysteresis and frictional lag):
  ż = q̇ − |q̇|·z/z_ss,  F = σ0·z + σ1·ż with σ0 = g_d / z_ss;
* a load-dependent Coulomb part μ·|τ_transmitted| (gear tooth friction grows with load);
* a position-dependent ripple (gear meshing): the static friction is modulated by
  1 + ε·sin(k·R·q + ϕ), k mesh periods per motor revolution;
* rotor inertia R²·J_motor as MuJoCo armature.

The static (Coulomb + Stribeck + load + ripple) part is applied as MuJoCo ``dof_frictionloss``,
updated every step, so sticking is solved implicitly by MuJoCo's constraint solver; viscous
friction is MuJoCo joint damping (implicit in the integrator); the bristle force is applied
explicitly with an exact exponential update of z, which is unconditionally stable.

Only f1 ≈ Coulomb_total + g_d, f2, q̇sm, f3, q̇sg and f4 ≈ viscous_total are representable by
eq. 15; the bristle dynamics, load dependence and ripple are deliberate model mismatch.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot

__all__ = ["DriveTrain", "DriveTrainConfig", "DriveTrainTruth", "sample_drive_truth"]

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
        bristle: Steady-state bristle (LuGre) friction g_d [-].
        bristle_presliding: Presliding displacement z_ss [rad at the joint].
        bristle_damping_ratio: σ1 as a multiple of σ0·(z_ss per rad/s) [-]; small.
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
    bristle_damping_ratio: float = 0.02
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
        for name in ("stribeck_velocity_motor", "stribeck_velocity_gear", "bristle_presliding"):
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
        bristle_presliding: z_ss [rad].
        load_coefficient: μ [-]. ripple: ε [-]. ripple_frequency: k·R [periods/rad joint].
        ripple_phase: ϕ [rad].
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
    load_coefficient: Array
    ripple: Array
    ripple_frequency: Array
    ripple_phase: Array

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
    sigma0 = bristle / z_ss
    return DriveTrainTruth(
        armature=robot.reflected_rotor_inertia
        * (1.0 + config.rotor_inertia_spread * rng.uniform(-1.0, 1.0, n)),
        coulomb_motor=draw(config.coulomb_motor) * tmax,
        coulomb_gear=draw(config.coulomb_gear) * tmax,
        stribeck_motor=draw(config.stribeck_motor) * tmax,
        stribeck_gear=draw(config.stribeck_gear) * tmax,
        stribeck_velocity_motor=draw(config.stribeck_velocity_motor),
        stribeck_velocity_gear=draw(config.stribeck_velocity_gear),
        viscous=draw(config.viscous) * tmax / robot.velocity_limit,
        bristle=bristle,
        bristle_stiffness=sigma0,
        bristle_damping=config.bristle_damping_ratio * sigma0 * z_ss,
        bristle_presliding=z_ss,
        load_coefficient=draw(config.load_coefficient),
        ripple=draw(config.ripple),
        ripple_frequency=config.ripple_periods_per_motor_rev * robot.gear_ratio,
        ripple_phase=rng.uniform(0.0, 2.0 * np.pi, n),
    )


class DriveTrain:
    """Per-step evaluation of the true friction, with preallocated buffers.

    Args:
        truth: Drive-train parameters.
        gear_ratio: R per joint, shape (n,).
    """

    def __init__(self, truth: DriveTrainTruth, gear_ratio: Array) -> None:
        self.truth = truth
        n = gear_ratio.size
        self._a_motor = gear_ratio / truth.stribeck_velocity_motor
        self._a_gear = 1.0 / truth.stribeck_velocity_gear
        self._coulomb = truth.coulomb_motor + truth.coulomb_gear
        self._inv_zss = 1.0 / truth.bristle_presliding
        self.z = np.zeros(n)
        self.static = np.zeros(n)
        self.bristle_force = np.zeros(n)
        self._t1 = np.zeros(n)
        self._t2 = np.zeros(n)
        self._z_old = np.zeros(n)

    def reset(self) -> None:
        """Zero the bristle state."""
        self.z[:] = 0.0
        self.bristle_force[:] = 0.0

    def update(self, q: Array, qd: Array, transmitted: Array, dt: float) -> None:
        """Advance one step: fills :attr:`static` (friction-loss level) and :attr:`bristle_force`.

        Args:
            q: True joint positions [rad], shape (n,).
            qd: True joint velocities [rad/s], shape (n,).
            transmitted: Torque through the gear (motor torque) [N·m], shape (n,).
            dt: Step [s].
        """
        tr = self.truth
        t1, t2, st = self._t1, self._t2, self.static
        # Stribeck curve (motor and gear side) + Coulomb.
        np.multiply(qd, self._a_motor, out=t1)
        np.square(t1, out=t1)
        np.negative(t1, out=t1)
        np.exp(t1, out=t1)
        np.multiply(t1, tr.stribeck_motor, out=st)
        np.multiply(qd, self._a_gear, out=t1)
        np.square(t1, out=t1)
        np.negative(t1, out=t1)
        np.exp(t1, out=t1)
        np.multiply(t1, tr.stribeck_gear, out=t1)
        st += t1
        st += self._coulomb
        # Mesh ripple modulation.
        np.multiply(q, tr.ripple_frequency, out=t1)
        t1 += tr.ripple_phase
        np.sin(t1, out=t1)
        t1 *= tr.ripple
        t1 += 1.0
        st *= t1
        # Load-dependent part.
        np.abs(transmitted, out=t1)
        t1 *= tr.load_coefficient
        st += t1
        # Bristle: dz/dt = v - |v| z / z_ss, exact for constant v over the step.
        self._z_old[:] = self.z
        np.abs(qd, out=t1)
        t1 *= self._inv_zss
        np.multiply(t1, -dt, out=t2)
        np.exp(t2, out=t2)                   # decay factor
        np.sign(qd, out=t1)
        np.divide(t1, self._inv_zss, out=t1)  # steady state z = sgn(v)·z_ss
        self.z -= t1
        self.z *= t2
        self.z += t1
        # Bristle force σ0·z + σ1·ż.
        np.subtract(self.z, self._z_old, out=t2)
        t2 *= tr.bristle_damping / dt
        np.multiply(self.z, tr.bristle_stiffness, out=self.bristle_force)
        self.bristle_force += t2
