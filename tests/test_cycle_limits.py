"""The cycle limiter: feasible streams pass unchanged, any stream comes out within the limits
(finite differences over the cycle, as a J519 controller checks them), and it catches up."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.drivers.cycle_limits import CycleLimiter, CycleLimits
from leadthrough.errors import DriverError

T = 0.008
V, A, J = np.array([2.0, 3.0]), np.array([10.0, 20.0]), np.array([500.0, 1000.0])


def _differences(qs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v = np.diff(qs, axis=0) / T
    a = np.diff(v, axis=0) / T
    return v, a, np.diff(a, axis=0) / T


def _run(limiter: CycleLimiter, targets: np.ndarray, q0: np.ndarray) -> np.ndarray:
    limiter.reset(q0)
    # the controller's view: two cycles at rest at q0, then the limited targets
    return np.array([q0, q0] + [limiter.limit(q).copy() for q in targets])


@settings(max_examples=80, deadline=None)
@given(steps=st.lists(st.lists(st.floats(-0.05, 0.05), min_size=2, max_size=2),
                      min_size=5, max_size=120),
       jerk=st.booleans())
def test_any_stream_comes_out_within_the_limits(steps: list[list[float]], jerk: bool) -> None:
    limits = CycleLimits(V, A, J if jerk else None)
    limiter = CycleLimiter(limits, T, margin=0.95)
    targets = np.cumsum(np.array(steps) * 5, axis=0)  # wild: up to 30 rad/s asked for
    v, a, j = _differences(_run(limiter, targets, np.zeros(2)))
    slack = 1 + 1e-9
    assert np.all(np.abs(v) <= V * slack)
    assert np.all(np.abs(a) <= A * slack)
    if jerk:
        assert np.all(np.abs(j) <= J * slack)


def test_a_feasible_stream_passes_unchanged() -> None:
    limiter = CycleLimiter(CycleLimits(V, A, J), T)
    t = np.arange(1, 200) * T
    s = np.clip(t / 1.5, 0, 1)
    targets = np.outer(10 * s**3 - 15 * s**4 + 6 * s**5, [0.3, -0.5])  # min-jerk, slow
    out = _run(limiter, targets, np.zeros(2))[2:]
    assert np.array_equal(out, targets) and limiter.limited == 0


def test_a_jump_is_limited_then_caught_up() -> None:
    limiter = CycleLimiter(CycleLimits(V, A, J), T)
    targets = np.tile([0.5, -0.5], (300, 1))  # a step: infinitely fast
    out = _run(limiter, targets, np.zeros(2))[2:]
    assert limiter.limited > 10 and limiter.last_limited is False
    assert np.abs(out[-1] - targets[-1]).max() < 1e-12  # settled exactly on the target
    assert out[:, 0].max() <= 0.5 + 1e-12 and out[:, 1].min() >= -0.5 - 1e-12  # no overshoot
    v = np.diff(out, axis=0) / T
    assert np.abs(v).max() > 0.5 * V.min()  # it did not crawl


def test_bad_limits_name_the_field() -> None:
    with pytest.raises(DriverError) as err:
        CycleLimits(np.array([1.0, -1.0]))
    assert err.value.field == "limits.velocity"
    with pytest.raises(DriverError) as err:
        CycleLimits(V, np.array([1.0]))
    assert err.value.field == "limits.acceleration"
    with pytest.raises(DriverError):
        CycleLimiter(CycleLimits(V), 0.0)
