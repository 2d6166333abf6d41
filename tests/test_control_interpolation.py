"""10 ms → 1 ms joint commands: cubic Hermite (C¹, exact at rest) and the optional Ruckig one."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from leadthrough.control import (
    HermiteInterpolator,
    InterpolatorStatus,
    JerkLimitConfig,
    JerkLimitedInterpolator,
)
from leadthrough.errors import ControlError
from leadthrough.robot import Robot

T, SUB = 0.01, 10
TS = T / SUB


def _setpoints(n_cycles: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Setpoints as the IK makes them: q_{k+1} = q_k + q̇_k·T, q̇ with bounded changes."""
    rng = np.random.default_rng(seed)
    qd = np.cumsum(rng.uniform(-0.05, 0.05, size=(n_cycles, 3)), axis=0)
    q = np.cumsum(qd * T, axis=0)
    return q, qd


def _interpolate(interp: HermiteInterpolator | JerkLimitedInterpolator, q: np.ndarray,
                 qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[InterpolatorStatus]]:
    cmd = interp.make_command()
    qs, qds, status = [], [], []
    for k in range(q.shape[0]):
        interp.set_target(q[k], qd[k])
        for _ in range(SUB):
            status.append(interp.update(cmd))
            qs.append(cmd.q.copy())
            qds.append(cmd.qd.copy())
    return np.array(qs), np.array(qds), status


def test_hermite_hits_the_setpoints_and_is_c1() -> None:
    q, qd = _setpoints(200, seed=0)
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(np.zeros(3))
    qs, qds, status = _interpolate(interp, q, qd)
    # every 10th command is the setpoint itself, bit for bit
    assert np.array_equal(qs[SUB - 1::SUB], q) and np.array_equal(qds[SUB - 1::SUB], qd)
    assert status[SUB - 1::SUB] == [InterpolatorStatus.FINISHED] * 200
    # the same curve as SciPy's cubic Hermite spline through the setpoints
    knots = T * np.arange(201)
    spline = CubicHermiteSpline(knots, np.vstack([np.zeros(3), q]),
                                np.vstack([np.zeros(3), qd]))
    t = TS * np.arange(1, 2001)
    np.testing.assert_allclose(qs, spline(t), rtol=0, atol=1e-14)
    np.testing.assert_allclose(qds, spline(t, 1), rtol=0, atol=1e-11)
    # no steps: consecutive commands differ by at most one servo period of the speed
    assert np.max(np.abs(np.diff(qs, axis=0))) <= np.max(np.abs(qds)) * TS * 1.01
    # C¹, no velocity steps: |q̈| ≤ 4·|v₀ − v₁|/T on a segment, so per servo period
    dv = np.abs(np.diff(np.vstack([np.zeros(3), qd]), axis=0)).max()
    assert np.max(np.abs(np.diff(qds, axis=0))) <= 4 * dv / T * TS * (1 + 1e-9)


def test_hermite_holds_exactly_at_rest() -> None:
    q0 = np.array([0.3, -1.2, 2.0])
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(q0)
    qs, qds, _ = _interpolate(interp, np.tile(q0, (50, 1)), np.zeros((50, 3)))
    assert np.all(qs == q0) and np.all(qds == 0.0)


def test_hermite_stays_within_the_bound_of_the_docstring() -> None:
    """Departure from the straight segment ≤ 4/27·T·|v₀ − v₁| (with v₁ the segment's mean
    velocity, as the IK makes them)."""
    q, qd = _setpoints(300, seed=1)
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(np.zeros(3))
    qs, _, _ = _interpolate(interp, q, qd)
    prev_q = np.vstack([np.zeros(3), q[:-1]])
    prev_v = np.vstack([np.zeros(3), qd[:-1]])
    s = (np.arange(1, SUB + 1) / SUB)[None, :, None]
    line = prev_q[:, None, :] + s * (q - prev_q)[:, None, :]
    dev = np.abs(qs.reshape(300, SUB, 3) - line)
    bound = 4 / 27 * T * np.abs(prev_v - qd)[:, None, :]
    assert np.all(dev <= bound + 1e-15)


def test_hermite_starved_holds_at_rest() -> None:
    interp = HermiteInterpolator(2, T, SUB)
    interp.reset(np.zeros(2))
    interp.set_target(np.array([0.001, 0.0]), np.array([0.1, 0.0]))
    cmd = interp.make_command()
    for _ in range(SUB):
        interp.update(cmd)
    assert interp.update(cmd) == InterpolatorStatus.STARVED
    assert np.array_equal(cmd.q, [0.001, 0.0]) and np.all(cmd.qd == 0.0)
    with pytest.raises(ControlError, match="substeps"):
        HermiteInterpolator(2, T, 0)


@pytest.mark.parametrize("bad", ["nan q", "inf qd", "short q"])
def test_hermite_ignores_a_bad_setpoint_like_a_missed_one(bad: str) -> None:
    """A non-finite or wrong-size setpoint never reaches the commands: the running segment
    ends at its own setpoint, then the end is held (STARVED), and a valid setpoint resumes."""
    interp = HermiteInterpolator(2, T, SUB)
    interp.reset(np.zeros(2))
    cmd = interp.make_command()
    interp.set_target(np.array([0.001, 0.0]), np.array([0.1, 0.0]))
    for _ in range(SUB // 2):
        interp.update(cmd)
    q, qd = np.array([0.002, 0.0]), np.array([0.1, 0.0])
    if bad == "nan q":
        q[1] = np.nan
    elif bad == "inf qd":
        qd[0] = np.inf
    else:
        q = q[:1]
    interp.set_target(q, qd)
    statuses = [interp.update(cmd) for _ in range(SUB)]
    assert statuses[SUB // 2 - 1] == InterpolatorStatus.FINISHED
    assert statuses[-1] == InterpolatorStatus.STARVED
    assert np.array_equal(cmd.q, [0.001, 0.0]) and np.all(cmd.qd == 0.0)
    interp.set_target(np.array([0.0015, 0.0]), np.zeros(2))
    assert interp.update(cmd) == InterpolatorStatus.WORKING and np.all(np.isfinite(cmd.q))


def test_jerk_limited_needs_ruckig_with_a_clear_error(er20: Robot,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ruckig", None)
    with pytest.raises(ControlError, match="pip install ruckig"):
        JerkLimitedInterpolator(er20)


def test_jerk_limited_tracks_within_jerk_limits(er20: Robot) -> None:
    # ruckig is a test dependency (the "jerk" extra): no skip, a missing ruckig fails here
    cfg = JerkLimitConfig(jerk_per_acceleration=20.0)
    interp = JerkLimitedInterpolator(er20, cfg)
    n = er20.n
    q0 = np.array([0.0, -0.6, 0.9, 0.0, 0.8, 0.0])
    interp.reset(q0)
    # setpoints of a joint move with bounded acceleration, then at rest
    k = np.arange(1, 151)
    profile = np.clip(k * T, 0, 1.0)               # ramp of q̇ up to 0.3 rad/s over 1 s
    qd_set = np.zeros((250, n))
    qd_set[:150, 0] = 0.3 * profile
    qd_set[150:200, 0] = 0.3 * np.linspace(1, 0, 50)
    q_set = q0 + np.cumsum(qd_set * T, axis=0)
    qs, qds, status = _interpolate(interp, q_set, qd_set)
    assert InterpolatorStatus.ERROR not in status
    acc = np.diff(qds, axis=0) / TS
    jerk = np.diff(acc, axis=0) / TS
    amax = er20.acceleration_limit
    assert np.all(np.abs(acc) <= amax * (1 + 1e-6))
    assert np.all(np.abs(jerk) <= 20.0 * amax * (1 + 1e-6))
    np.testing.assert_allclose(qs[-1], q_set[-1], atol=1e-12)     # settles on the last setpoint
    lag = np.abs(qs[SUB - 1::SUB, 0] - q_set[:, 0])
    assert lag.max() < 0.005                                       # a few mrad at most
    assert np.all(qs[:, 1:] == q0[1:])                             # other joints untouched
