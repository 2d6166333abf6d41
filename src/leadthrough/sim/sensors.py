"""Sensors of the simulated robot at 1 kHz: motor encoders and motor-current measurement.

* Position: the true joint angle quantised to the motor encoder's resolution
  2π / (counts · R) [rad].
* Current: true current + per-joint bias + white noise, quantised by an ADC with
  ``adc_bits`` over ±``adc_range`` × max current.

Defaults (fractions of each joint's max current): noise σ = 1.5 %, bias uniform within ±0.2 %,
12-bit ADC over ±1.25 × max current (LSB ≈ 0.06 %). Together with the deliberate model mismatch
of the drive train this gives calibration residuals of a few percent of max torque, the order of
the paper's Table II (1.6–5.7 %).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError

__all__ = ["CurrentSensor", "SensorConfig"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SensorConfig:
    """Sensor noise model, relative to each joint's max current.

    Attributes:
        current_noise: White-noise σ [-].
        current_bias: Bias drawn uniformly within ± this [-].
        adc_bits: ADC resolution [bits].
        adc_range: ADC full scale as a multiple of max current [-].
    """

    current_noise: float = 0.015
    current_bias: float = 0.002
    adc_bits: int = 12
    adc_range: float = 1.25

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (np.isfinite(v) and v >= 0):
                raise SimulationError("must be finite and >= 0", field=f"sensors.{f.name}",
                                      value=v, expected="a finite number >= 0")
        if not 4 <= self.adc_bits <= 32 or self.adc_range <= 0:
            raise SimulationError("bad ADC", field="sensors.adc_bits", value=self.adc_bits,
                                  expected="4..32 bits and adc_range > 0")


class CurrentSensor:
    """Current measurement with preallocated noise blocks (fast per-step reads).

    Args:
        config: Noise model.
        max_current: Max current per joint [A], shape (n,).
        rng: Random generator (owned: draws are reproducible per seed).
        block: Samples of noise drawn at once.
    """

    def __init__(self, config: SensorConfig, max_current: Array, rng: np.random.Generator,
                 block: int = 4096) -> None:
        imax = np.asarray(max_current, dtype=float)
        self.sigma = config.current_noise * imax
        self.bias = config.current_bias * imax * rng.uniform(-1.0, 1.0, imax.size)
        self.lsb = 2.0 * config.adc_range * imax / (2**config.adc_bits)
        self._inv_lsb = 1.0 / self.lsb
        self._full = config.adc_range * imax
        self._rng = rng
        self._block = block
        self._noise = np.empty((block, imax.size))
        self._k = block
        self.value = np.zeros(imax.size)

    def read(self, current: Array) -> Array:
        """Measure a current [A], shape (n,); returns an internal buffer (copy to keep)."""
        if self._k >= self._block:
            self._rng.standard_normal(out=self._noise)
            self._noise *= self.sigma
            self._noise += self.bias
            self._k = 0
        v = self.value
        np.add(current, self._noise[self._k], out=v)
        self._k += 1
        v *= self._inv_lsb
        np.rint(v, out=v)
        v *= self.lsb
        np.clip(v, -self._full, self._full, out=v)
        return v
