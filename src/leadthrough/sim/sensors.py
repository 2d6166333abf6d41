"""Sensors of the simulated robot at 1 kHz: motor encoders and motor-current measurement, when
they sample, and what a controller reports of them (:class:`Feedback`).

* Position: the true joint angle quantised to the motor encoder's resolution
  2π / (counts · R) [rad].
* Current: true current + per-joint bias + white noise + a slowly varying, motion-induced error
  (an Ornstein–Uhlenbeck process gated by the joint speed: torque fluctuations of gear meshing,
  lubrication and cogging under motion, which no rigid-body + friction model captures), quantised
  by an ADC with ``adc_bits`` over ±``adc_range`` × max current.

Defaults (fractions of each joint's max current): white noise σ = 0.2 %, slow error σ = 0.75 %
with a 50 ms correlation time at joint speeds ≥ 0.05 rad/s, fading linearly to zero at rest,
bias uniform within ±0.2 %, 12-bit ADC over ±1.25 × max current (LSB ≈ 0.06 %).

Timing (the realistic plant, :mod:`leadthrough.sim.plant`): a drive controller samples its
current loop and its encoder at different instants and hands them to the interface with
different delays. The realistic plant's current samples are those of a fixed lag behind the
positions, drawn per robot instance within ``current_lag_s`` (0–2 ms); a driver may also ask
for sample-time jitter (:meth:`leadthrough.sim.robot.SimRobot.set_sample_jitter`): each sample
is then taken a random time up to the jitter before the instant it is reported for. Both read
the true current at fractional delays from a short ring buffer (:class:`DelayLine`, linear
interpolation between 1 ms samples; :class:`SampleTiming` keeps the lag, the jitter and the
buffer).

Why this shape: real logs show far less current noise at rest than model residuals in motion.
The UR5 of ``../shared/data/ur5-ft`` at standstill has current-derived torque σ 0.08–0.19 N·m
unfiltered at 125 Hz (≈ 0.1 % of max torque), while calibration residuals in motion are
1–6 % (the paper's Table II: 1.6–5.7 %). The slow error is not removed by the calibration's
10 Hz low-pass, so with the drive train's deliberate model mismatch calibration residuals are
1–2 % of max torque, the order of Table II; at rest the force estimate is limited by the small
white noise, the bias and stiction instead.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from leadthrough.errors import SimulationError

__all__ = ["CurrentSensor", "DelayLine", "Feedback", "SampleTiming", "SensorConfig"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Feedback:
    """One sample as a real controller reports it.

    Attributes:
        t: Time [s].
        q: Encoder joint positions [rad], shape (n,).
        current: Measured motor currents [A], shape (n,).
        sequence: Sample counter.
    """

    t: float
    q: Array
    current: Array
    sequence: int


@dataclass(frozen=True)
class SensorConfig:
    """Sensor noise model, relative to each joint's max current.

    Attributes:
        current_noise: White-noise σ [-].
        current_drift: σ of the slowly varying (Ornstein–Uhlenbeck) error in motion [-].
        drift_time: Correlation time of the slow error [s].
        drift_full_speed: Joint speed from which the slow error has its full σ; below it, it
            fades linearly to zero at rest [rad/s].
        current_bias: Bias drawn uniformly within ± this [-].
        adc_bits: ADC resolution [bits].
        adc_range: ADC full scale as a multiple of max current [-].
        current_lag_s: Range of the realistic plant's lag of the current samples behind the
            positions [s] (drawn once per robot instance; the ideal plant has none).
    """

    current_noise: float = 0.002
    current_drift: float = 0.0075
    drift_time: float = 0.05
    drift_full_speed: float = 0.05
    current_bias: float = 0.002
    adc_bits: int = 12
    adc_range: float = 1.25
    current_lag_s: tuple[float, float] = (0.0, 0.002)

    def __post_init__(self) -> None:
        lo, hi = self.current_lag_s
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo <= hi <= MAX_LAG_S):
            raise SimulationError("bad range", field="sensors.current_lag_s",
                                  value=self.current_lag_s,
                                  expected=f"0 <= low <= high <= {MAX_LAG_S:g} s")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "current_lag_s":
                continue
            if not (np.isfinite(v) and v >= 0):
                raise SimulationError("must be finite and >= 0", field=f"sensors.{f.name}",
                                      value=v, expected="a finite number >= 0")
        for name in ("drift_time", "drift_full_speed"):
            if getattr(self, name) <= 0:
                raise SimulationError("must be > 0", field=f"sensors.{name}",
                                      value=getattr(self, name), expected="> 0")
        if not 4 <= self.adc_bits <= 32 or self.adc_range <= 0:
            raise SimulationError("bad ADC", field="sensors.adc_bits", value=self.adc_bits,
                                  expected="4..32 bits and adc_range > 0")


#: Longest current lag plus jitter the sensor's ring buffer holds [s].
MAX_LAG_S = 0.01


class DelayLine:
    """A signal a fractional number of steps ago, from a ring buffer (linear interpolation).

    Args:
        n: Signal size.
        max_delay_steps: Longest delay asked for [steps].
    """

    def __init__(self, n: int, max_delay_steps: float) -> None:
        self._size = int(np.ceil(max_delay_steps)) + 2
        self._buf = np.zeros((self._size, n))
        self._head = 0
        self._filled = False
        self.value = np.zeros(n)

    def clear(self) -> None:
        """Forget the past: the next sample pushed fills it."""
        self._filled = False

    def push(self, x: Array) -> None:
        """Store the newest sample (the first one also fills the past: a signal at rest)."""
        self._head = (self._head + 1) % self._size
        if not self._filled:
            self._buf[:] = x
            self._filled = True
        else:
            self._buf[self._head] = x

    def delayed(self, steps: float) -> Array:
        """The signal ``steps`` (>= 0, within the buffer) before the newest sample; returns
        :attr:`value` (an internal buffer)."""
        whole = int(steps)
        frac = steps - whole
        a = self._buf[(self._head - whole) % self._size]
        b = self._buf[(self._head - whole - 1) % self._size]
        np.multiply(a, 1.0 - frac, out=self.value)
        self.value += frac * b
        return self.value


class CurrentSensor:
    """Current measurement with preallocated noise blocks (fast per-step reads).

    Args:
        config: Noise model.
        max_current: Max current per joint [A], shape (n,).
        rng: Random generator of the noise (owned: draws are reproducible per seed).
        dt: Sample period [s].
        bias_rng: Random generator of the bias (a property of the drive, so of the robot
            instance, not of the recording); default ``rng``.
        block: Samples of noise drawn at once.
    """

    def __init__(self, config: SensorConfig, max_current: Array, rng: np.random.Generator,
                 dt: float, block: int = 4096,
                 bias_rng: np.random.Generator | None = None) -> None:
        imax = np.asarray(max_current, dtype=float)
        self.white_sigma = config.current_noise * imax
        self.drift_sigma = config.current_drift * imax
        self.sigma = np.sqrt(self.white_sigma**2 + self.drift_sigma**2)
        self._a = float(np.exp(-dt / config.drift_time))
        self._drift_state = self.drift_sigma * rng.standard_normal(imax.size)
        self._drift_noise = np.empty((block, imax.size))
        self.bias = (config.current_bias * imax
                     * (bias_rng or rng).uniform(-1.0, 1.0, imax.size))
        self.lsb = 2.0 * config.adc_range * imax / (2**config.adc_bits)
        self._inv_lsb = 1.0 / self.lsb
        self._full = config.adc_range * imax
        self._neg_full = -self._full
        self._rng = rng
        self._block = block
        self._noise = np.empty((block, imax.size))
        self._k = block
        self.value = np.zeros(imax.size)
        self._gate = np.zeros(imax.size)
        self._inv_full_speed = 1.0 / config.drift_full_speed

    def _refill(self) -> None:
        """Draw the next block: white noise + AR(1) slow error + bias."""
        self._rng.standard_normal(out=self._noise)
        self._noise *= self.white_sigma
        self._rng.standard_normal(out=self._drift_noise)
        self._drift_noise *= self.drift_sigma * np.sqrt(1.0 - self._a**2)
        zi = (self._a * self._drift_state)[None, :]
        drift, _ = scipy.signal.lfilter([1.0], [1.0, -self._a], self._drift_noise, axis=0,
                                        zi=zi)
        self._drift_state = drift[-1].copy()
        self._drift_noise[:] = drift
        self._noise += self.bias
        self._k = 0

    def read(self, current: Array, speed: Array) -> Array:
        """Measure a current [A], shape (n,); returns an internal buffer (copy to keep).

        Args:
            current: True current [A], shape (n,).
            speed: Joint speeds |q̇| [rad/s], shape (n,) (gates the slow error).
        """
        if self._k >= self._block:
            self._refill()
        v, g = self.value, self._gate
        np.multiply(speed, self._inv_full_speed, out=g)
        np.minimum(g, 1.0, out=g)
        g *= self._drift_noise[self._k]
        np.add(current, self._noise[self._k], out=v)
        v += g
        self._k += 1
        v *= self._inv_lsb
        np.rint(v, out=v)
        v *= self.lsb
        # clipped to the ADC's range (two ufuncs: np.clip's wrapper costs more on 6 values)
        np.maximum(v, self._neg_full, out=v)
        np.minimum(v, self._full, out=v)
        return v


class SampleTiming:
    """When the sensors sample (the module's "Timing"): the current a fixed lag behind the
    positions, and with a jitter both a random time up to the jitter before the instant they
    are reported for.

    Args:
        n: Joints.
        lag_s: The current's lag behind the positions [s], 0 to :data:`MAX_LAG_S`.
        timestep: The simulator's step [s].
        resolution: The encoders' resolution per joint [rad], shape (n,).
        rng: Random generator of the jitter (owned).
    """

    def __init__(self, n: int, lag_s: float, timestep: float, resolution: Array,
                 rng: np.random.Generator) -> None:
        self._n, self._dt = n, timestep
        self._res = resolution
        self._inv_res = 1.0 / resolution
        self._lag_steps = lag_s / timestep
        self._jitter_steps = 0.0
        self._rng = rng
        self._delay = None if lag_s == 0.0 else DelayLine(n, MAX_LAG_S / timestep)
        #: Encoder positions of the last jittered instant [rad], shape (n,) (with a jitter).
        self.q_jittered = np.zeros(n)
        #: True current at the instant the last late sample was taken [A], shape (n,).
        self.sampled_current = np.zeros(n)

    @property
    def late(self) -> bool:
        """Whether a sample is read from the past (a lag, or a jitter asked for)."""
        return self._delay is not None

    def reset(self, q: Array) -> None:
        """A restart at rest at the encoder positions ``q`` [rad], shape (n,)."""
        self.q_jittered[:] = q
        if self._delay is not None:
            self._delay.clear()

    def set_jitter(self, jitter_s: float) -> None:
        """Take each sample a random time within [0, ``jitter_s``] before its instant.

        Args:
            jitter_s: Largest timing error [s], from 0 (none) to one timestep.

        Raises:
            SimulationError: Out of range.
        """
        dt = self._dt
        if not (np.isfinite(jitter_s) and 0.0 <= jitter_s <= dt):
            raise SimulationError("out of range", field="sample_jitter_s", value=jitter_s,
                                  expected=f"0 <= jitter <= {dt:g} s (one timestep)")
        self._jitter_steps = jitter_s / dt
        if self._delay is None and jitter_s > 0.0:
            self._delay = DelayLine(self._n, MAX_LAG_S / dt)

    def read_late(self, sensor: CurrentSensor, current: Array, speed: Array, q: Array,
                  qd: Array) -> Array:
        """Measured current of a lagged (and jittered) instant; jittered positions into
        :attr:`q_jittered` (with a jitter). Only when :attr:`late`.

        Args:
            sensor: The current sensor.
            current: True current now [A], shape (n,).
            speed: Joint speeds |q̇| now [rad/s], shape (n,).
            q: True joint positions now [rad], shape (n,).
            qd: True joint velocities now [rad/s], shape (n,).

        Returns:
            The measured current [A], shape (n,) (the sensor's buffer).
        """
        assert self._delay is not None
        self._delay.push(current)
        early = self._jitter_steps * self._rng.uniform() if self._jitter_steps else 0.0
        self.sampled_current[:] = self._delay.delayed(self._lag_steps + early)
        measured = sensor.read(self.sampled_current, speed)
        if self._jitter_steps:
            qj = self.q_jittered
            np.multiply(qd, -early * self._dt, out=qj)
            qj += q
            qj *= self._inv_res
            np.rint(qj, out=qj)
            qj *= self._res
        return measured
