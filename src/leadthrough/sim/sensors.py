"""Sensors of the simulated robot at 1 kHz: motor encoders and motor-current measurement.

* Position: the true joint angle quantised to the motor encoder's resolution
  2π / (counts · R) [rad].
* Current: true current + per-joint bias + white noise + a slowly varying error (an
  Ornstein–Uhlenbeck process: offset drift of the sensing amplifiers, interference), quantised
  by an ADC with ``adc_bits`` over ±``adc_range`` × max current.

Defaults (fractions of each joint's max current): white noise σ = 1.5 %, slow error σ = 0.75 %
with a 50 ms correlation time, bias uniform within ±0.2 %, 12-bit ADC over ±1.25 × max current
(LSB ≈ 0.06 %). The white part is mostly removed by the calibration's 10 Hz low-pass; the slow
part is not, so the measurement alone leaves a residual of about 0.8 % of max torque, and with
the drive train's deliberate model mismatch calibration residuals are 1–2 %, the order of the
paper's Table II (1.6–5.7 %).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from leadthrough.errors import SimulationError

__all__ = ["CurrentSensor", "SensorConfig"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SensorConfig:
    """Sensor noise model, relative to each joint's max current.

    Attributes:
        current_noise: White-noise σ [-].
        current_drift: σ of the slowly varying (Ornstein–Uhlenbeck) error [-].
        drift_time: Correlation time of the slow error [s].
        current_bias: Bias drawn uniformly within ± this [-].
        adc_bits: ADC resolution [bits].
        adc_range: ADC full scale as a multiple of max current [-].
    """

    current_noise: float = 0.015
    current_drift: float = 0.0075
    drift_time: float = 0.05
    current_bias: float = 0.002
    adc_bits: int = 12
    adc_range: float = 1.25

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (np.isfinite(v) and v >= 0):
                raise SimulationError("must be finite and >= 0", field=f"sensors.{f.name}",
                                      value=v, expected="a finite number >= 0")
        if self.drift_time <= 0:
            raise SimulationError("must be > 0", field="sensors.drift_time",
                                  value=self.drift_time, expected="> 0 s")
        if not 4 <= self.adc_bits <= 32 or self.adc_range <= 0:
            raise SimulationError("bad ADC", field="sensors.adc_bits", value=self.adc_bits,
                                  expected="4..32 bits and adc_range > 0")


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
        self._rng = rng
        self._block = block
        self._noise = np.empty((block, imax.size))
        self._k = block
        self.value = np.zeros(imax.size)

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
        self._noise += drift
        self._noise += self.bias
        self._k = 0

    def read(self, current: Array) -> Array:
        """Measure a current [A], shape (n,); returns an internal buffer (copy to keep)."""
        if self._k >= self._block:
            self._refill()
        v = self.value
        np.add(current, self._noise[self._k], out=v)
        self._k += 1
        v *= self._inv_lsb
        np.rint(v, out=v)
        v *= self.lsb
        np.clip(v, -self._full, self._full, out=v)
        return v
