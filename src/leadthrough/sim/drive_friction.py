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
        thermal: Scale the friction by :attr:`static_scale` and :attr:`viscous_scale` (set by
            the joint temperatures, :mod:`leadthrough.sim.thermal`) and accumulate the
            friction losses in :attr:`heat`.
    """

    def __init__(self, truth: DriveTrainTruth, gear_ratio: Array, thermal: bool = False
                 ) -> None:
        self.truth = truth
        n = gear_ratio.size
        self._thermal = thermal
        self.static_scale = np.ones(n)
        self.viscous_scale = np.ones(n)
        self.heat = np.zeros(n)
        self._a_motor = gear_ratio / truth.stribeck_velocity_motor
        self._a_gear = 1.0 / truth.stribeck_velocity_gear
        self._a_damp = 1.0 / truth.bristle_damping_velocity
        self._coulomb = truth.coulomb_motor + truth.coulomb_gear + truth.bristle
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
        np.multiply(t1, tr.stribeck_motor, out=st)
        self._stribeck(qd, self._a_gear, tr.stribeck_exponent_gear, t1)
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
        if self._thermal:
            st *= self.static_scale
        self._bristles(qd, dt)
        if self._power_viscous:
            self._add_power_viscous(qd)
        if self._thermal:
            self._heat(qd, dt)

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
        t1, t2 = self._t1, self._t2
        np.abs(qd, out=t1)
        np.power(t1, self.truth.viscous_exponent, out=t1)
        t1 *= self.truth.viscous_power
        if self._thermal:
            t1 *= self.viscous_scale
        np.sign(qd, out=t2)
        t1 *= t2
        self.friction += t1

    def _heat(self, qd: Array, dt: float) -> None:
        """heat += (|F·q̇| + φ_v·c·q̇²)·dt, the step's friction loss [J]."""
        t1, t2 = self._t1, self._t2
        np.multiply(self.friction, qd, out=t1)
        np.abs(t1, out=t1)
        np.square(qd, out=t2)
        t2 *= self.truth.viscous
        t2 *= self.viscous_scale
        t1 += t2
        t1 *= dt
        self.heat += t1
