"""Control laws: virtual friction (eq. 31–33), velocity baseline [14], Cartesian limits."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import pytest

from leadthrough.control import CartesianLimits, VelocityBaselineConfig, VirtualFrictionConfig
from leadthrough.control.limits import (
    braking_distance,
    decelerate_twist,
    limit_twist,
)
from leadthrough.control.release import (
    RELEASE_DROP,
    RELEASE_HOLD,
    RELEASE_SMOOTHING_S,
    RELEASE_WINDOW_S,
    release_step,
)
from leadthrough.control.velocity_baseline import velocity_baseline
from leadthrough.control.virtual_friction import virtual_friction
from leadthrough.errors import ControlError

DT = 0.01
DELTA = np.full(6, 15.0)
DELTA_S = np.full(6, 50.0)


Law = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


def vf_law(cfg: VirtualFrictionConfig | None = None) -> Law:
    """Eq. 31–33 as the guiding cycle runs it: (twist, wrench, δ, δ_s, out)."""
    dt_over_mass = (cfg or VirtualFrictionConfig()).dt_over_mass(DT)
    return lambda v, w, d, ds, out: virtual_friction(v, w, d, ds, dt_over_mass, out)


def vb_law(cfg: VelocityBaselineConfig | None = None) -> Law:
    """[14] as the guiding cycle runs it (ignores the friction)."""
    cfg = cfg or VelocityBaselineConfig()
    gain, alpha = np.asarray(cfg.gain, dtype=float), cfg.alpha(DT)
    return lambda v, w, d, ds, out: velocity_baseline(v, w, gain, alpha, out)


def _run(law: Law, wrenches: np.ndarray, delta: np.ndarray = DELTA,
         delta_s: np.ndarray = DELTA_S) -> np.ndarray:
    """Twists after each cycle for a (k, 6) wrench sequence (no limits)."""
    v, new = np.zeros(6), np.zeros(6)
    out = np.empty_like(wrenches)
    for k, w in enumerate(wrenches):
        law(v, w, delta, delta_s, new)
        v[:] = new
        out[k] = v
    return out


def test_table_iv_defaults() -> None:
    cfg = VirtualFrictionConfig()
    assert cfg.mass == (1000.0,) * 6
    assert cfg.friction == (15.0,) * 6
    assert cfg.stopping_friction == (50.0,) * 6
    lim = CartesianLimits()
    assert (lim.max_linear_speed, lim.max_angular_speed) == (0.2, 0.2)
    assert (lim.max_linear_acceleration, lim.max_angular_acceleration) == (0.4, 0.4)


def test_no_motion_below_friction_is_exactly_zero() -> None:
    """eq. 33: |F̂| < δ never starts a motion; the velocity is 0.0 exactly, not small."""
    rng = np.random.default_rng(0)
    w = rng.uniform(-14.999, 14.999, size=(5000, 6))
    v = _run(vf_law(), w)
    assert np.all(v == 0.0)


def test_breakaway_acceleration_is_force_minus_friction_over_mass() -> None:
    """eq. 31 + 33: above δ the axis accelerates with (|F̂| − δ)/M, in the force's direction."""
    w = np.zeros((100, 6))
    w[:, 0], w[:, 4] = 40.0, -20.0
    v = _run(vf_law(), w)
    np.testing.assert_allclose(v[:, 0], (40.0 - 15.0) / 1000.0 * DT * np.arange(1, 101),
                               rtol=1e-12)
    np.testing.assert_allclose(v[:, 4], -(20.0 - 15.0) / 1000.0 * DT * np.arange(1, 101),
                               rtol=1e-12)
    assert np.all(v[:, [1, 2, 3, 5]] == 0.0)


def test_moving_friction_opposes_velocity() -> None:
    """eq. 32: while moving with F̂ ≥ δ the friction is δ·sgn(v) (decelerating a push back)."""
    law = vf_law()
    v, out = np.zeros(6), np.zeros(6)
    v[1] = 0.1
    w = np.zeros(6)
    w[1] = 30.0                                   # same direction: a = (30 − 15)/M
    law(v, w, DELTA, DELTA_S, out)
    assert out[1] == pytest.approx(0.1 + DT * 15.0 / 1000.0, rel=1e-12)
    w[1] = -30.0                                  # pushing back: a = (−30 − 15)/M
    law(v, w, DELTA, DELTA_S, out)
    assert out[1] == pytest.approx(0.1 - DT * 45.0 / 1000.0, rel=1e-12)


def test_stopping_friction_after_release_stops_exactly_without_reversal() -> None:
    law = vf_law()
    w = np.zeros((1000, 6))
    w[:400, 2] = 60.0
    w[400:, 2] = 10.0                             # "released": a residual 10 N below δ
    v = _run(law, w)[:, 2]
    peak = v[399]
    assert peak == pytest.approx(400 * DT * 45.0 / 1000.0, rel=1e-12)
    decel = -np.diff(v[400:])
    moving = v[401:] > 0
    # δ_s applies once the force is below δ: a = (10 − 50)/M
    np.testing.assert_allclose(decel[moving], 40.0 / 1000.0 * DT, rtol=1e-9)
    assert np.all(v >= 0.0)                       # never reverses
    stop = 400 + int(np.argmax(v[400:] == 0.0))
    assert np.all(v[stop:] == 0.0)                # and stays exactly at rest
    assert (stop - 400) * DT == pytest.approx(peak * 1000.0 / 40.0, abs=DT)


def test_config_validation_names_the_field() -> None:
    with pytest.raises(ControlError, match=r"virtual_friction.stopping_friction"):
        VirtualFrictionConfig(stopping_friction=(10.0,) * 6)
    with pytest.raises(ControlError, match=r"virtual_friction.mass"):
        VirtualFrictionConfig(mass=(1000.0,) * 5)
    with pytest.raises(ControlError, match=r"velocity_baseline.time_constant"):
        VelocityBaselineConfig(time_constant=0.0)
    with pytest.raises(ControlError, match=r"limits.max_linear_speed"):
        CartesianLimits(max_linear_speed=math.nan)


def test_velocity_baseline_is_a_first_order_lag() -> None:
    """[14]: v̇ = (K·F − v)/T; exact discretisation, zero target velocity."""
    cfg = VelocityBaselineConfig(gain=(0.0025,) * 6, time_constant=0.2)
    w = np.zeros((300, 6))
    w[:150, 0] = 40.0
    v = _run(vb_law(cfg), w)[:, 0]
    t = DT * np.arange(1, 151)
    np.testing.assert_allclose(v[:150], 0.1 * (1 - np.exp(-t / 0.2)), rtol=1e-9)
    np.testing.assert_allclose(v[150:], v[149] * np.exp(-t / 0.2), rtol=1e-9)


def test_velocity_baseline_drifts_on_noise_that_virtual_friction_ignores() -> None:
    rng = np.random.default_rng(1)
    w = rng.normal(2.0, 3.0, size=(1000, 6))     # a biased, noisy estimate far below δ
    vf = _run(vf_law(), w)
    vb = _run(vb_law(), w)
    assert np.all(vf == 0.0)
    drift = np.sum(vb[:, :3], axis=0) * DT        # TCP displacement over 10 s [m]
    assert np.all(drift > 0.03)


def test_limiter_caps_speed_and_acceleration_by_norm() -> None:
    lim = CartesianLimits()
    speed, step = lim.max_speed, lim.max_step(DT)
    prev, out = np.zeros(6), np.zeros(6)
    desired = np.array([1.0, 1.0, 0.0, 0.0, 0.0, 5.0])
    speeds, accs = [], []
    for _ in range(200):
        limit_twist(prev, desired, speed, step, 1.0, out)
        accs.append(np.linalg.norm(out[:3] - prev[:3]) / DT)
        prev[:] = out
        speeds.append(np.linalg.norm(out[:3]))
    assert max(speeds) <= 0.2 * (1 + 1e-12)
    assert max(accs) <= 0.4 * (1 + 1e-12)
    np.testing.assert_allclose(out[:3], 0.2 / math.sqrt(2) * np.array([1, 1, 0]), rtol=1e-12)
    assert out[5] == pytest.approx(0.2, rel=1e-12)
    # a lowered speed scale is reached by decelerating, not by a jump
    before = out.copy()
    limit_twist(before, desired, speed, step, 0.1, out)
    assert np.linalg.norm(out[:3] - before[:3]) / DT == pytest.approx(0.4, rel=1e-12)


def test_decelerate_reaches_exact_zero_at_the_limit() -> None:
    step = CartesianLimits().max_step(DT)
    v = np.array([0.12, -0.16, 0.0, 0.05, 0.0, 0.0])
    direction = v[:3] / np.linalg.norm(v[:3])
    cycles = 0
    while v.any() and cycles < 100:
        cycles += 1
        before = v.copy()
        decelerate_twist(before, step, 0.0, v)
        assert np.linalg.norm(v[:3] - before[:3]) <= 0.4 * DT * (1 + 1e-12)
        assert np.linalg.norm(v[3:] - before[3:]) <= 0.4 * DT * (1 + 1e-12)
        if np.linalg.norm(v[:3]) > 0:             # straight line in velocity space
            np.testing.assert_allclose(v[:3] / np.linalg.norm(v[:3]), direction, rtol=1e-12)
        # proportional: the angular part (0.05 rad/s) ends with the linear one
        assert np.count_nonzero(v) in (0, 3)
    assert not v.any() and cycles == 50          # 0.2 m/s at 0.4 m/s²: 50 cycles
    assert braking_distance(0.2, 0.4, 0.0) == pytest.approx(0.05)


def test_decelerate_takes_the_joints_stop_when_longer() -> None:
    step = CartesianLimits().max_step(DT)
    v = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])  # 25 cycles at the Cartesian limit
    path, cycles = 0.0, 0
    while v.any() and cycles < 100:
        cycles += 1
        before = v[0]
        # the joints, whose speeds scale with the twist, need 40 cycles from the start
        decelerate_twist(v, step, 40.0 * before / 0.1, v)
        assert before - v[0] == pytest.approx(0.1 / 40.0, rel=1e-9)
        path += v[0] * DT
    assert cycles == 40
    # the braking distance given that stop time bounds the discrete stop's path
    bound = braking_distance(0.1, 0.4, 40 * DT)
    assert bound == pytest.approx(0.1 * 0.4 / 2)
    assert path <= bound and path == pytest.approx(bound, rel=0.03)
    assert braking_distance(0.1, 0.4, 0.01) == pytest.approx(0.1 ** 2 / 0.8)


def test_release_is_a_fall_back_from_the_peak_not_noise() -> None:
    """A release: the smoothed force falls back from its peak by half of δ (toward zero or past
    it); estimator noise below δ (±10 N per cycle, white) and a steady or rising push are not."""
    alpha = DT / (RELEASE_SMOOTHING_S + DT)
    forget = np.exp(-DT / RELEASE_WINDOW_S)
    friction = np.full(6, 15.0)
    smooth, peak = np.zeros(6), np.zeros(6)
    rng = np.random.default_rng(3)
    noise = rng.uniform(-10.0, 10.0, size=(2000, 6))
    step = partial(release_step, friction=friction, drop=RELEASE_DROP, hold=RELEASE_HOLD,
                   alpha=alpha, forget=forget, smooth=smooth, peak=peak)
    assert not any(step(w, moving=False) for w in noise)
    smooth[:], peak[:] = 0.0, 0.0
    w = np.zeros(6)
    for k in range(100):                   # rising, then steady at 12 N (below δ)
        w[1] = min(12.0, 0.5 * k)
        assert not step(w, moving=False)
    assert peak[1] == pytest.approx(12.0, rel=1e-6)
    w[1] = -5.0                            # let go (the estimate overshoots past zero)
    seen = [step(w, moving=False) for _ in range(10)]
    first = seen.index(True)
    assert first <= 3 and not any(seen[first + 1:])   # once, within 40 ms
    # in motion the peak follows the smoothed force: letting go is not a release at rest
    smooth[:], peak[:] = 0.0, 0.0
    w[1] = 30.0
    for _ in range(20):
        step(w, moving=True)
    w[1] = 0.0
    assert not any(step(w, moving=True) for _ in range(20))
    np.testing.assert_array_equal(peak, smooth)


def test_a_small_hold_that_swings_back_through_zero_is_a_release() -> None:
    """At rest the estimate reads less than a hand holds (the gears' static friction carries
    the rest), and after letting go it swings the other way: a hold read at 0.4 δ that falls
    back by half of δ (so through zero) is a release while the force's magnitude stays under
    δ/2 (the hand's force gone); a smaller fall is not (an operator easing off), nor a swing
    from a peak below RELEASE_HOLD·δ (the estimate's noise at rest), nor a rise from zero, nor
    a push against the small hold that adds force on another axis (a new push)."""
    alpha = DT / (RELEASE_SMOOTHING_S + DT)
    forget = float(np.exp(-DT / RELEASE_WINDOW_S))
    friction = np.full(6, 15.0)

    def released(held: float, after: float, other: float = 0.0) -> bool:
        smooth, peak, w = np.zeros(6), np.zeros(6), np.zeros(6)
        seen = False
        for k in range(150):                 # 1 s steady, then 0.5 s after letting go
            w[0] = held if k < 100 else after
            w[2] = 0.0 if k < 100 else other
            seen = release_step(w, friction, RELEASE_DROP, RELEASE_HOLD, alpha, forget,
                                smooth, peak, False) or seen
        return seen

    assert 0.0 < RELEASE_HOLD < RELEASE_DROP
    assert released(-6.0, 8.0)               # 0.4 δ held, then 8 N the other way
    assert released(6.0, -8.0)               # either sign
    assert not released(-6.0, 4.0)           # the peak relaxes: back by less than δ/2
    assert not released(-3.0, 8.0)           # 0.2 δ held (below RELEASE_HOLD): a new push
    assert not released(0.0, 8.0)            # a push from zero
    # a push against a standing 6 N phantom adds force (here 16 N along z): no release
    assert not released(-6.0, 8.0, other=-16.0)
    assert released(-6.0, 8.0, other=-3.0)  # a letting go that leaves a small z phantom


def test_a_slow_drift_under_a_steady_hand_is_not_a_release() -> None:
    """At rest under a steady 49 N pull the estimate drifts by 10 N/s (the drives' static
    friction takes up load): the peak forgets it, so the stopping friction is not renewed
    again and again (with a peak that never forgets, it would be, every ~0.75 s)."""
    alpha = DT / (RELEASE_SMOOTHING_S + DT)
    friction = np.full(6, 15.0)
    w = np.zeros(6)

    def releases(forget: float) -> int:
        smooth, peak = np.zeros(6), np.zeros(6)
        count = 0
        for k in range(700):                  # 7 s
            w[1] = 49.0 - 10.0 * max(0.0, k * DT - 1.0)
            count += release_step(w, friction, RELEASE_DROP, RELEASE_HOLD, alpha, forget,
                                  smooth, peak, False)
        return count

    assert releases(float(np.exp(-DT / RELEASE_WINDOW_S))) == 0
    assert releases(1.0) >= 5
