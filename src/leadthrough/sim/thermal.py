"""Joint temperatures of the realistic plant, and how they change its friction.

Gear friction falls as a joint warms up: the lubricant's viscosity drops, and with it the
viscous and the low-speed (mixed-lubrication) friction. Studies on industrial arms find the
friction of a cold robot tens of per cent above the warm one's, with time constants of tens of
minutes (Bittencourt, Wernholt, Sander-Tavallaey, Brogårdh, "An extended friction model to
capture load and temperature effects in robot joints", IROS 2010, ABB; Simoni, Beschi, Legnani,
Visioli, "Modelling the temperature in joint friction of industrial manipulators", Robotica 37,
2019, which also estimates the joint temperature from the dissipated power with a first-order
model; Nevmerzhitskiy, Notkin, Vara, Zmeu, "Friction model of industrial robot joint with
temperature correction by example of KUKA KR10", J. Robotics 2019).

Per joint, a first-order thermal state heated by the friction losses P and cooled to ambient::

    τ_th·dT/dt = T_a + R_th·P − T

and the friction scaled by

    φ_s(T) = exp(−β_s·(T − T_a))   (Coulomb, Stribeck, bristles, load dependence)
    φ_v(T) = exp(−β_v·(T − T_a))   (viscous, linear and power law)

The drive-train configuration's friction values are those of the cold robot (T = T_a).
Per robot instance and joint are drawn: τ_th, the steady temperature rise ΔT of production-like
motion at cold friction (which sets R_th = ΔT / P_production), and the cold/warm friction ratios
r_s, r_v between T_a and T_a + ΔT (β = ln r / ΔT). A robot that runs production-like motion
long enough settles below T_a + ΔT, because its warming friction dissipates less.

Production-like motion (:meth:`JointTemperatures.warm_up`, the fast-forward): every joint moves
a share ``production_duty`` of the time at ``production_speed`` × its velocity limit, carrying
``production_load`` × its max torque. The loss is the sliding friction there, evaluated with
the current temperature; the state is advanced exactly (constant loss) in steps of
``warm_up_step_s``, so an hour costs a few hundred small array operations.

In the simulation the loss is the drive train's actual friction power |F·q̇| plus the linear
viscous part's c·q̇², accumulated every step and applied every ``update_period_s``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot
from leadthrough.sim.drive_friction import sliding_friction
from leadthrough.sim.drivetrain import DriveTrainTruth
from leadthrough.sim.plant import check_draw_ranges

__all__ = ["JointTemperatures", "ThermalConfig", "ThermalTruth", "draw_thermal_truth"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ThermalConfig:
    """How the joints' thermal behaviour is drawn (ranges sampled uniformly per joint).

    Attributes:
        ambient_c: Ambient temperature, the cold robot's [°C].
        time_constant_min: Range of the thermal time constant τ_th [min].
        production_rise_k: Range of the steady temperature rise ΔT under production-like
            motion at cold friction [K].
        static_ratio: Range of the cold/warm ratio r_s of the Coulomb, Stribeck and load
            friction between T_a and T_a + ΔT [-].
        viscous_ratio: Range of the cold/warm ratio r_v of the viscous friction [-].
        production_speed: Joint speed of production-like motion, fraction of the limit [-].
        production_duty: Share of the time production-like motion moves a joint [-].
        production_load: Torque a joint carries in production, fraction of its max [-].
        update_period_s: How often the simulation applies the accumulated losses [s].
        warm_up_step_s: Step of the warm-up fast-forward [s].
    """

    ambient_c: float = 20.0
    time_constant_min: tuple[float, float] = (20.0, 40.0)
    production_rise_k: tuple[float, float] = (20.0, 35.0)
    static_ratio: tuple[float, float] = (1.3, 1.8)
    viscous_ratio: tuple[float, float] = (1.5, 2.2)
    production_speed: float = 0.25
    production_duty: float = 0.7
    production_load: float = 0.2
    update_period_s: float = 0.1
    warm_up_step_s: float = 10.0

    def __post_init__(self) -> None:
        check_draw_ranges("thermal", self, skip=("ambient_c",))
        if not np.isfinite(self.ambient_c):
            raise SimulationError("not finite", field="thermal.ambient_c", value=self.ambient_c,
                                  expected="a temperature [°C]")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "ambient_c" and min(value if isinstance(value, tuple) else (value,)) <= 0:
                raise SimulationError("must be > 0", field=f"thermal.{f.name}", value=value,
                                      expected="> 0")
        if self.static_ratio[0] < 1.0 or self.viscous_ratio[0] < 1.0:
            raise SimulationError("friction must not rise with temperature",
                                  field="thermal.static_ratio/viscous_ratio",
                                  value=(self.static_ratio, self.viscous_ratio),
                                  expected="cold/warm ratios >= 1")
        if self.production_duty > 1.0 or self.production_speed > 1.0:
            raise SimulationError("out of range", field="thermal.production_duty/speed",
                                  value=(self.production_duty, self.production_speed),
                                  expected="fractions <= 1")


@dataclass(frozen=True)
class ThermalTruth:
    """A robot instance's drawn thermal parameters, each shape (n,) but ``ambient_c``.

    Attributes:
        ambient_c: Ambient temperature [°C].
        time_constant_s: τ_th [s].
        resistance: R_th [K/W].
        beta_static: β_s [1/K].
        beta_viscous: β_v [1/K].
    """

    ambient_c: float
    time_constant_s: Array
    resistance: Array
    beta_static: Array
    beta_viscous: Array


def production_loss(drive: DriveTrainTruth, robot: Robot, config: ThermalConfig,
                    static_scale: Array, viscous_scale: Array) -> Array:
    """Mean friction loss of production-like motion at the given friction scales [W], (n,)."""
    speed = config.production_speed * robot.velocity_limit
    level, viscous = sliding_friction(drive, robot.gear_ratio, speed,
                                      config.production_load * robot.max_torque)
    return config.production_duty * speed * (static_scale * level + viscous_scale * viscous)


def draw_thermal_truth(drive: DriveTrainTruth, robot: Robot, config: ThermalConfig,
                       rng: np.random.Generator) -> ThermalTruth:
    """Draw a robot instance's thermal parameters (see the module doc).

    Args:
        drive: The instance's (cold) drive train.
        robot: The robot.
        config: Ranges.
        rng: Random generator of the instance's thermal draw.
    """
    n = robot.n

    def draw(bounds: tuple[float, float]) -> Array:
        return rng.uniform(bounds[0], bounds[1], n)

    tau = 60.0 * draw(config.time_constant_min)
    rise = draw(config.production_rise_k)
    ones = np.ones(n)
    loss = production_loss(drive, robot, config, ones, ones)
    return ThermalTruth(ambient_c=config.ambient_c, time_constant_s=tau,
                        resistance=rise / np.maximum(loss, 1e-12),
                        beta_static=np.log(draw(config.static_ratio)) / rise,
                        beta_viscous=np.log(draw(config.viscous_ratio)) / rise)


class JointTemperatures:
    """The joints' temperatures and the friction scales they give.

    Args:
        truth: Thermal parameters.
        temperature_c: Start temperatures [°C], shape (n,); default ambient (a cold robot).
    """

    def __init__(self, truth: ThermalTruth, temperature_c: Array | None = None) -> None:
        self.truth = truth
        n = truth.time_constant_s.size
        self.temperature_c = (np.full(n, truth.ambient_c) if temperature_c is None
                              else np.array(temperature_c, dtype=float))
        self.static_scale = np.ones(n)
        self.viscous_scale = np.ones(n)
        self._update_scales()

    def _update_scales(self) -> None:
        rise = self.temperature_c - self.truth.ambient_c
        np.exp(-self.truth.beta_static * rise, out=self.static_scale)
        np.exp(-self.truth.beta_viscous * rise, out=self.viscous_scale)

    def set(self, temperature_c: Array) -> None:
        """Set the temperatures [°C], shape (n,)."""
        t = np.asarray(temperature_c, dtype=float)
        if t.shape != self.temperature_c.shape or not np.all(np.isfinite(t)):
            raise SimulationError("bad temperatures", field="temperature_c",
                                  value=np.asarray(temperature_c).tolist(),
                                  expected=f"{self.temperature_c.size} finite values [°C]")
        self.temperature_c[:] = t
        self._update_scales()

    def advance(self, loss: Array, duration: float) -> None:
        """Advance by ``duration`` [s] with a constant friction loss [W], shape (n,)."""
        tr = self.truth
        steady = tr.ambient_c + tr.resistance * loss
        decay = np.exp(-duration / tr.time_constant_s)
        self.temperature_c[:] = steady + (self.temperature_c - steady) * decay
        self._update_scales()

    def warm_up(self, duration_s: float, drive: DriveTrainTruth, robot: Robot,
                config: ThermalConfig) -> None:
        """Fast-forward ``duration_s`` of production-like motion (see the module doc).

        Raises:
            SimulationError: A negative or non-finite duration.
        """
        if not (np.isfinite(duration_s) and duration_s >= 0.0):
            raise SimulationError("out of range", field="warm_up_s", value=duration_s,
                                  expected="a finite duration >= 0 s")
        left = float(duration_s)
        while left > 0.0:
            h = min(config.warm_up_step_s, left)
            self.advance(production_loss(drive, robot, config, self.static_scale,
                                         self.viscous_scale), h)
            left -= h
