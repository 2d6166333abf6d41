"""The true drive-train friction of a simulated robot, step by step and in steady sliding.

:class:`DriveTrain` advances the friction of the parameters drawn in
:mod:`leadthrough.sim.drivetrain` (the model is described there) by one simulator step:
the level g (Coulomb, Stribeck, mesh ripple, load), the LuGre bristles that carry it, the
realistic plant's power-law viscous part and its temperature scaling
(:mod:`leadthrough.sim.thermal`). :func:`sliding_friction` is the same friction in steady
sliding, for the thermal model's production losses.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from leadthrough.sim.drivetrain import DriveTrainTruth

__all__ = ["DriveTrain", "sliding_friction"]

Array = NDArray[np.float64]


def sliding_friction(truth: DriveTrainTruth, gear_ratio: Array, speed: Array,
                     transmitted: Array) -> tuple[Array, Array]:
    """Steady sliding friction at a joint speed, mean over the mesh ripple, cold.

    Args:
        truth: Drive-train parameters.
        gear_ratio: R per joint, shape (n,).
        speed: Joint speeds |q̇| [rad/s], shape (n,).
        transmitted: Torque through the gears [N·m], shape (n,).

    Returns:
        The level g of the bristles (Coulomb, Stribeck, load) and the viscous friction
        (linear and power law) [N·m], each shape (n,).
    """
    v = np.abs(speed)
    level = (truth.coulomb_motor + truth.coulomb_gear + truth.bristle
             + truth.stribeck_motor * np.exp(-np.abs(gear_ratio * v
                                                     / truth.stribeck_velocity_motor)
                                             ** truth.stribeck_exponent_motor)
             + truth.stribeck_gear * np.exp(-np.abs(v / truth.stribeck_velocity_gear)
                                            ** truth.stribeck_exponent_gear)
             + truth.load_coefficient * np.abs(transmitted))
    return level, truth.viscous * v + truth.viscous_power * v**truth.viscous_exponent


class DriveTrain:
    """Per-step evaluation of the true friction, with preallocated buffers.

    Args:
        truth: Drive-train parameters.
        gear_ratio: R per joint, shape (n,).
        thermal: Scale the friction by the joint temperatures' factors
            (:meth:`set_temperature_scales`, :mod:`leadthrough.sim.thermal`) and accumulate
            the friction losses (:meth:`take_losses`).
    """

    def __init__(self, truth: DriveTrainTruth, gear_ratio: Array, thermal: bool = False
                 ) -> None:
        self.truth = truth
        n = gear_ratio.size
        self._thermal = thermal
        self.viscous_scale = np.ones(n)
        self._heat = np.zeros(n)          # Σ|F·q̇| over the steps since the last take [N·m·rad/s]
        self._speed_sq = np.zeros(n)      # Σq̇² likewise [rad²/s²]
        self._a_motor = gear_ratio / truth.stribeck_velocity_motor
        self._a_gear = 1.0 / truth.stribeck_velocity_gear
        self._a_damp = 1.0 / truth.bristle_damping_velocity
        # the friction levels now: the drawn (cold) ones, scaled by temperature if thermal
        self._cold_coulomb = truth.coulomb_motor + truth.coulomb_gear + truth.bristle
        self._coulomb = self._cold_coulomb.copy() if thermal else self._cold_coulomb
        self._stribeck_m = truth.stribeck_motor.copy() if thermal else truth.stribeck_motor
        self._stribeck_g = truth.stribeck_gear.copy() if thermal else truth.stribeck_gear
        self._load = truth.load_coefficient.copy() if thermal else truth.load_coefficient
        self._viscous_power = truth.viscous_power.copy()
        # no static friction at all (σ0 = 0): the bristle force is identically zero
        self._inv_sigma0 = np.divide(1.0, truth.bristle_stiffness,
                                     out=np.zeros(n), where=truth.bristle_stiffness > 0.0)
        # eq. 15's Gaussian Stribeck shape is squared (the ideal plant, bit for bit)
        self._gaussian = bool(np.all(truth.stribeck_exponent_motor == 2.0)
                              and np.all(truth.stribeck_exponent_gear == 2.0))
        self._power_viscous = bool(np.any(truth.viscous_power != 0.0))
        self.z = np.zeros(n)
        self.static = np.zeros(n)
        self.friction = np.zeros(n)
        self._t1 = np.zeros(n)
        self._t2 = np.zeros(n)
        self._z_old = np.zeros(n)

    def reset(self) -> None:
        """Zero the bristle state (no friction carried at rest)."""
        self.z[:] = 0.0
        self.friction[:] = 0.0

    def set_temperature_scales(self, static: Array, viscous: Array) -> None:
        """Scale the cold friction: Coulomb, Stribeck and load by ``static``, the power-law
        viscous part (and the linear one in :meth:`take_losses`) by ``viscous``, each (n,)."""
        tr = self.truth
        np.multiply(self._cold_coulomb, static, out=self._coulomb)
        np.multiply(tr.stribeck_motor, static, out=self._stribeck_m)
        np.multiply(tr.stribeck_gear, static, out=self._stribeck_g)
        np.multiply(tr.load_coefficient, static, out=self._load)
        np.multiply(tr.viscous_power, viscous, out=self._viscous_power)
        self.viscous_scale[:] = viscous

    def take_losses(self, dt: float) -> Array:
        """The friction energy since the last take [J], shape (n,): Σ(|F·q̇| + c·q̇²)·dt with
        c the linear viscous coefficient at the current temperature; restarts the sums."""
        energy = (self._heat + self.truth.viscous * self.viscous_scale * self._speed_sq) * dt
        self._heat[:] = 0.0
        self._speed_sq[:] = 0.0
        return energy

    def _stribeck(self, qd: Array, scale: Array, exponent: Array, out: Array) -> None:
        """out = exp(−|scale·q̇|^δ)."""
        np.multiply(qd, scale, out=out)
        if self._gaussian:
            np.square(out, out=out)
        else:
            np.abs(out, out=out)
            np.power(out, exponent, out=out)
        np.negative(out, out=out)
        np.exp(out, out=out)

    def update(self, q: Array, qd: Array, transmitted: Array, dt: float) -> None:
        """Advance one step: fills :attr:`static` (friction level g) and :attr:`friction`.

        Args:
            q: True joint positions [rad], shape (n,).
            qd: True joint velocities [rad/s], shape (n,).
            transmitted: Torque through the gear (motor torque) [N·m], shape (n,).
            dt: Step [s].
        """
        tr = self.truth
        t1, st = self._t1, self.static
        # Stribeck curve (motor and gear side) + Coulomb.
        self._stribeck(qd, self._a_motor, tr.stribeck_exponent_motor, t1)
        np.multiply(t1, self._stribeck_m, out=st)
        self._stribeck(qd, self._a_gear, tr.stribeck_exponent_gear, t1)
        np.multiply(t1, self._stribeck_g, out=t1)
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
        t1 *= self._load
        st += t1
        self._bristles(qd, dt)
        if self._power_viscous:
            self._add_power_viscous(qd)
        if self._thermal:
            self._add_losses(qd)

    def _bristles(self, qd: Array, dt: float) -> None:
        """LuGre bristles at level :attr:`static`: advances z, sets :attr:`friction`."""
        tr = self.truth
        t1, t2 = self._t1, self._t2
        # dz/dt = v - |v| z / z_ss with z_ss = g / σ0, exact for constant v.
        self._z_old[:] = self.z
        np.multiply(self.static, self._inv_sigma0, out=t2)  # z_ss(v) [rad]
        np.maximum(t2, 1e-15, out=t2)
        np.abs(qd, out=t1)
        t1 *= -dt
        t1 /= t2
        np.exp(t1, out=t1)                             # decay factor
        np.sign(qd, out=self.friction)
        t2 *= self.friction                            # steady state sgn(v)·z_ss
        self.z -= t2
        self.z *= t1
        self.z += t2
        # F = σ0·z + σ1·exp(-(v/v_d)²)·ż.
        np.multiply(qd, self._a_damp, out=t1)
        np.square(t1, out=t1)
        np.negative(t1, out=t1)
        np.exp(t1, out=t1)
        t1 *= tr.bristle_damping
        np.subtract(self.z, self._z_old, out=t2)
        t2 *= 1.0 / dt
        t2 *= t1
        np.multiply(self.z, tr.bristle_stiffness, out=self.friction)
        self.friction += t2

    def _add_power_viscous(self, qd: Array) -> None:
        """friction += f_p·sgn(q̇)·|q̇|^α (the realistic plant's degressive viscous part)."""
        t1 = self._t1
        np.abs(qd, out=t1)
        np.power(t1, self.truth.viscous_exponent, out=t1)
        t1 *= self._viscous_power
        np.copysign(t1, qd, out=t1)
        self.friction += t1

    def _add_losses(self, qd: Array) -> None:
        """Sum the step's |F·q̇| and q̇² (:meth:`take_losses`)."""
        t1 = self._t1
        np.multiply(self.friction, qd, out=t1)
        np.abs(t1, out=t1)
        self._heat += t1
        np.square(qd, out=t1)
        self._speed_sq += t1
