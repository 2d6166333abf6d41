"""Pre-processing: zero-phase filtering, offline differentiation, standstill, resampling."""

from __future__ import annotations

import numpy as np
import pytest

from leadthrough.data.preprocess import PreprocessConfig, preprocess
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError
from leadthrough.robot import Robot


def _sine(er20: Robot, rate: float = 1000.0, seconds: float = 10.0, jitter: float = 0.0
          ) -> Recording:
    rng = np.random.default_rng(1)
    t = np.arange(0.0, seconds, 1.0 / rate)
    if jitter:
        t = t + rng.uniform(-jitter, jitter, t.size) / rate
    w = 2 * np.pi * 0.5
    q = 0.3 * np.sin(w * t)[:, None] * np.ones(6)
    q[:, 5] = 0.0  # joint 6 at rest
    cur = np.cos(w * t)[:, None] * np.ones(6) + rng.normal(0, 0.05, (t.size, 6))
    return Recording(time=t, q=q, current=cur, robot="er20")


def test_derivatives_and_zero_phase(er20: Robot) -> None:
    data = preprocess(_sine(er20), er20, PreprocessConfig(decimate_to_hz=None))
    w = 2 * np.pi * 0.5
    t = data.time
    inner = (t > 1.0) & (t < 9.0)  # away from the filter's edge transients (padding)
    np.testing.assert_allclose(data.qd[inner, 0], 0.3 * w * np.cos(w * t[inner]), atol=2e-3)
    np.testing.assert_allclose(data.qdd[inner, 0], -0.3 * w**2 * np.sin(w * t[inner]), atol=2e-2)
    # zero phase: the filtered current is not delayed, and the noise is reduced
    expected = er20.current_to_torque(np.cos(w * data.time)[:, None] * np.ones(6))
    err = data.torque - expected
    # per joint: the largest error stays below one σ of the raw current noise (0.05 A) in
    # that joint's own torque units
    assert np.all(np.abs(err).max(axis=0) < 0.05 * er20.torque_per_amp)


def test_standstill_and_decimation(er20: Robot) -> None:
    data = preprocess(_sine(er20), er20, PreprocessConfig(decimate_to_hz=100.0))
    assert data.rate_hz == pytest.approx(100.0)
    assert not data.moving[:, 5].any()            # the resting joint is excluded
    frac = data.moving[:, 0].mean()
    assert 0.9 < frac < 1.0                       # zero crossings of q̇ are dropped


def test_jittered_time_is_resampled(er20: Robot) -> None:
    data = preprocess(_sine(er20, rate=100.0, jitter=0.3), er20,
                      PreprocessConfig(decimate_to_hz=None))
    assert np.allclose(np.diff(data.time), np.diff(data.time)[0])
    w = 2 * np.pi * 0.5
    np.testing.assert_allclose(data.qd[:, 0], 0.3 * w * np.cos(w * data.time), atol=0.02)


def test_too_few_samples(er20: Robot) -> None:
    with pytest.raises(DataError, match="too few samples") as e:
        preprocess(_sine(er20, seconds=0.02), er20)
    assert e.value.field == "samples"


def test_cutoff_above_nyquist(er20: Robot) -> None:
    with pytest.raises(DataError, match="Nyquist") as e:
        preprocess(_sine(er20, rate=100.0), er20, PreprocessConfig(position_cutoff_hz=60.0))
    assert e.value.field == "preprocess.position_cutoff_hz"
