"""10 ms → 1 ms joint commands: the setpoints' quadratic B-spline (C¹, the setpoints'
acceleration within each cycle, exact at rest) and the optional Ruckig one."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.interpolate import BSpline

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


def _bspline(q0: np.ndarray, q: np.ndarray) -> BSpline:
    """SciPy's uniform quadratic B-spline with the setpoints as control points (the reset
    position twice first), timed so that it passes m_k = (q_{k-1} + q_k)/2 at t = k·T."""
    c = np.vstack([q0, q0, q])
    knots = T * (np.arange(c.shape[0] + 3) - 2.0)
    return BSpline(knots, c, 2)


def test_the_command_is_the_quadratic_bspline_of_the_setpoints() -> None:
    q, qd = _setpoints(200, seed=0)
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(np.zeros(3))
    qs, qds, status = _interpolate(interp, q, qd)
    assert status[SUB - 1::SUB] == [InterpolatorStatus.FINISHED] * 200
    # every 10th command is the midpoint of the last two setpoints, moving at their difference
    prev = np.vstack([np.zeros(3), q[:-1]])
    np.testing.assert_allclose(qs[SUB - 1::SUB], (prev + q) / 2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(qds[SUB - 1::SUB], qd, rtol=0, atol=1e-12)
    # the same curve as SciPy's B-spline
    spline = _bspline(np.zeros(3), q)
    t = TS * np.arange(1, 2001)
    np.testing.assert_allclose(qs, spline(t), rtol=0, atol=1e-14)
    np.testing.assert_allclose(qds, spline(t, 1), rtol=0, atol=1e-11)


def test_inside_a_cycle_the_command_accelerates_at_the_setpoints_rate() -> None:
    """The point of the midpoint spline: the command's acceleration at the servo period is the
    setpoints' per-cycle change of velocity, not 4× and −2× of it (cubics ending at the
    setpoints with their mean velocity)."""
    q, qd = _setpoints(300, seed=1)
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(np.zeros(3))
    qs, qds, _ = _interpolate(interp, q, qd)
    acc_set = np.diff(np.vstack([np.zeros(3), qd]), axis=0) / T        # per cycle, (300, 3)
    # second difference of positions inside each cycle (both neighbours in the same segment)
    seg = np.vstack([np.zeros(3), qs]).reshape(-1, 3)
    acc = (seg[2:] - 2 * seg[1:-1] + seg[:-2]) / TS**2                # centred at 1..2999
    k = np.arange(1, seg.shape[0] - 1)
    inside = (k % SUB) != 0                                           # not at a knot
    cycle = (k - 1) // SUB
    np.testing.assert_allclose(acc[inside], acc_set[cycle[inside]], rtol=0, atol=1e-6)
    # the velocity is continuous: changes by one servo period of that acceleration
    np.testing.assert_allclose(np.diff(np.vstack([np.zeros(3), qds]), axis=0),
                               np.repeat(acc_set, SUB, axis=0) * TS, rtol=0, atol=1e-12)


def test_the_command_stays_in_the_hull_of_three_setpoints() -> None:
    q, qd = _setpoints(300, seed=2)
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(np.zeros(3))
    qs, _, _ = _interpolate(interp, q, qd)
    c = np.vstack([np.zeros(3), np.zeros(3), q])
    window = np.stack([c[:-2], c[1:-1], c[2:]])                       # (3, 300, 3)
    lo, hi = window.min(axis=0), window.max(axis=0)
    cmd = qs.reshape(300, SUB, 3)
    assert np.all(cmd >= lo[:, None, :] - 1e-15) and np.all(cmd <= hi[:, None, :] + 1e-15)


def test_a_stop_at_the_limit_is_at_the_limit_every_servo_period() -> None:
    """Setpoints braking from 0.5 rad/s at a = 2 rad/s² to rest: the command never exceeds a,
    and rests exactly on the last setpoint one cycle after the setpoints stop."""
    a = 2.0
    v = np.concatenate([np.full(20, 0.5), np.maximum(0.5 - a * T * np.arange(1, 40), 0.0),
                        np.zeros(20)])
    qd = np.column_stack([v, -v])
    q = np.cumsum(qd * T, axis=0)
    interp = HermiteInterpolator(2, T, SUB)
    interp.reset(np.zeros(2))
    qs, qds, _ = _interpolate(interp, q, qd)
    acc = np.diff(np.vstack([np.zeros(2), qds]), axis=0)[20 * SUB:] / TS
    assert np.max(np.abs(acc)) <= a * (1 + 1e-9)
    last_move = int(np.flatnonzero(v > 0)[-1])
    rest = (last_move + 2) * SUB - 1                 # end of the cycle after the last change
    assert np.all(qs[rest:] == q[-1]) and np.all(qds[rest:] == 0.0)
    assert np.any(qs[rest - 1] != q[-1])


def test_hermite_holds_exactly_at_rest() -> None:
    q0 = np.array([0.3, -1.2, 2.0])
    interp = HermiteInterpolator(3, T, SUB)
    interp.reset(q0)
    qs, qds, _ = _interpolate(interp, np.tile(q0, (50, 1)), np.zeros((50, 3)))
    assert np.all(qs == q0) and np.all(qds == 0.0)


def test_hermite_starved_holds_at_rest() -> None:
    interp = HermiteInterpolator(2, T, SUB)
    interp.reset(np.zeros(2))
    interp.set_target(np.array([0.001, 0.0]), np.array([0.1, 0.0]))
    cmd = interp.make_command()
    for _ in range(SUB):
        interp.update(cmd)
    assert np.array_equal(cmd.q, [0.0005, 0.0]) and np.array_equal(cmd.qd, [0.1, 0.0])
    assert interp.update(cmd) == InterpolatorStatus.STARVED
    assert np.array_equal(cmd.q, [0.0005, 0.0]) and np.all(cmd.qd == 0.0)
    with pytest.raises(ControlError, match="substeps"):
        HermiteInterpolator(2, T, 0)


@pytest.mark.parametrize("bad", ["nan q", "inf qd", "short q"])
def test_hermite_ignores_a_bad_setpoint_like_a_missed_one(bad: str) -> None:
    """A non-finite or wrong-size setpoint never reaches the commands: the running segment
    ends at its own end point, then the end is held (STARVED), and a valid setpoint resumes
    from there."""
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
    assert np.array_equal(cmd.q, [0.0005, 0.0]) and np.all(cmd.qd == 0.0)
    interp.set_target(np.array([0.0015, 0.0]), np.zeros(2))
    assert interp.update(cmd) == InterpolatorStatus.WORKING and np.all(np.isfinite(cmd.q))
    for _ in range(SUB - 1):
        interp.update(cmd)
    assert np.array_equal(cmd.q, [0.00125, 0.0])     # midpoint of 0.001 and 0.0015


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
