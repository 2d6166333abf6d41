"""The stop after the hand lets go of the moving tool (leadthrough.control.hand_release): the
controller on scripted force estimates (a residual after the release, a push that goes on, a
grip again), and end to end on the simulated er20 with a deliberately wrong model."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from leadthrough.control import (
    Fault,
    GuidingConfig,
    GuidingController,
    HandReleaseConfig,
    VirtualFrictionConfig,
)
from leadthrough.control.hand_release import level_let_go
from leadthrough.control.release import RELEASE_DROP, RELEASE_WINDOW_S
from leadthrough.errors import ControlError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.session.loop_config import LoopConfig
from leadthrough.session.metrics import release_motion_times, release_overruns
from leadthrough.sim.guiding_params import shipped_guiding_params
from leadthrough.sim.session import SimSessionConfig, light_guiding, run_sim_session
from test_control_guiding import DT, Q_WORK, pose_ik, run

#: The estimator's 3 Hz low-pass: a step of the hand's force reaches the estimate with this
#: time constant [s].
TAU = 1.0 / (2 * np.pi * 3.0)
MASS = 100.0
A_MAX = 0.4                           # Table IV's linear acceleration limit [m/s²]


def _config(enabled: bool = True, settle_s: float = 0.3) -> GuidingConfig:
    return GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(MASS,) * 6),
                         settle_s=settle_s, hand_release=HandReleaseConfig(enabled=enabled))


def _q0(er20: Robot) -> np.ndarray:
    return pose_ik(er20, np.array([-np.pi / 2, -0.6, 0.9, 0.0, 0.8, 0.0]), [-0.65, -0.85, 0.31])


def _let_go(w: np.ndarray, start: int, held: float, residual: float) -> None:
    """The estimate of x from cycle ``start``: from ``held`` to ``residual`` (the model's
    error) at the estimator's pace."""
    t = np.arange(w.shape[0] - start) * DT
    w[start:, 0] = residual + (held - residual) * np.exp(-t / TAU)


def test_config_is_validated() -> None:
    for bad in ({"drop_fraction": 0.0}, {"drop_fraction": 1.5}, {"lockout_s": -0.1},
                {"smoothing_s": 0.0}, {"window_s": float("nan")}, {"rise_window_s": 0.0}):
        with pytest.raises(ControlError, match=next(iter(bad))):
            HandReleaseConfig(**bad)  # type: ignore[arg-type]


def test_a_residual_above_the_friction_after_letting_go_stops_at_the_limit(er20: Robot) -> None:
    """40 N push, then let go while the estimate keeps 22 N (> δ = 15 N, < δ_s = 50 N: the
    model's error). The paper's law alone keeps accelerating; the stop decelerates at the
    acceleration limit once the fall is seen and holds the tool exactly at rest."""
    k_n, release = 500, 100
    w = np.zeros((k_n, 6))
    w[:release, 0] = 40.0
    _let_go(w, release, 40.0, 22.0)
    paper = run(GuidingController(er20, _config(False)), _q0(er20), w, interpolate=False)
    ours = run(GuidingController(er20, _config()), _q0(er20), w, interpolate=False)
    v0 = ours.twist_base[release - 1, 0]
    assert v0 > 0.2 * 0.9 and np.all(ours.fault == Fault.NONE)
    # the paper's law: (22 - 15)/100 m/s² on and on, capped at 0.2 m/s
    assert paper.twist_base[-1, 0] == pytest.approx(0.2)
    vx = ours.twist_base[release:, 0]
    seen = int(np.argmax(np.diff(vx) < -1e-9))          # the first cycle of the stop
    # the stop starts once the smoothed estimate has fallen by δ = 15 N (to a cycle or two:
    # the twist of a cycle is the next pose's)
    smooth = w[release - 1, 0] + np.zeros(1)
    alpha = HandReleaseConfig().alpha(DT)
    fallen = next(k for k in range(k_n - release)
                  if 40.0 - (smooth := smooth + alpha * (w[release + k, 0] - smooth))[0] >= 15.0)
    assert abs(seen - fallen) <= 2 and seen * DT <= 0.2
    np.testing.assert_allclose(-np.diff(vx[seen:])[vx[seen + 1:] > 0.0] / DT, A_MAX, rtol=1e-6)
    travel = ours.position[-1, 0] - ours.position[release - 1, 0]
    assert travel <= v0 * seen * DT + v0 ** 2 / (2 * A_MAX) + 1e-3
    stop = release + seen + int(np.argmax(vx[seen:] == 0.0))
    assert np.all(ours.twist_base[stop:] == 0.0)         # and stays at rest with 22 N on it


def test_a_push_that_goes_on_is_not_braked(er20: Robot) -> None:
    """A push with the estimate's ripple (±5 N at 1 Hz, ±5 N noise) and a slow decrease
    (60 -> 20 N over 3 s: the operator slowing down): the commands are the paper's law's,
    bit for bit. (What the detector tolerates: a fall within its 0.3 s window below δ.)"""
    k_n = 600
    t = np.arange(k_n) * DT
    rng = np.random.default_rng(3)
    w = np.zeros((k_n, 6))
    w[:, 0] = np.where(t < 2.0, 40.0, 60.0 - 40.0 * np.clip((t - 3.0) / 3.0, 0.0, 1.0))
    w[:, 0] += 5.0 * np.sin(2 * np.pi * t) + rng.uniform(-5.0, 5.0, k_n)
    w[:, 1:3] = rng.uniform(-5.0, 5.0, (k_n, 2))
    paper = run(GuidingController(er20, _config(False)), _q0(er20), w, interpolate=False)
    ours = run(GuidingController(er20, _config()), _q0(er20), w, interpolate=False)
    assert paper.twist_base[:, 0].max() == pytest.approx(0.2)
    np.testing.assert_array_equal(ours.twist_base, paper.twist_base)


def test_a_fresh_grip_resumes_a_slow_drift_does_not(er20: Robot) -> None:
    """After a letting go and the stop, a grip (a step of 40 N) moves the tool again; an
    estimate that drifts up while the drives settle, as slowly as they unload (20 N/s to
    40 N), does not, where the paper's law moves as soon as the settling ends; once they have
    settled, leaning in by more than δ over the settled level does, if faster than the
    drives' drift (20 N/s: above δ/drift_s = 10 N/s, rest_drift.py)."""
    k_n, grip = 500, 250
    w = np.zeros((k_n, 6))
    w[:50, 0] = 40.0
    _let_go(w, 50, 40.0, 0.0)
    w[grip:, 0] = 40.0 * (1.0 - np.exp(-(np.arange(k_n - grip) * DT) / TAU))
    tr = run(GuidingController(er20, _config()), _q0(er20), w, interpolate=False)
    vx = tr.twist_base[:, 0]
    assert np.all(vx[grip - 50:grip] == 0.0) and vx[-1] > 0.0
    # the settling after the stop is over by the grip: it moves within the smoothing's time
    assert int(np.argmax(vx[grip:] > 0.0)) * DT <= 2 * TAU + 0.05
    k_n, settle = 800, 3.0
    drift = np.zeros((k_n, 6))
    drift[:50, 0] = 40.0
    _let_go(drift, 50, 40.0, 0.0)
    t = np.arange(k_n) * DT
    drift[100:, 0] = np.minimum(20.0 * (t[100:] - 1.0), 40.0)
    lean = 600                                       # 5.5 s after the letting go
    drift[lean:, 0] += 20.0 * (t[lean:] - t[lean])
    cfg = _config(settle_s=settle)
    tr = run(GuidingController(er20, cfg), _q0(er20), drift, interpolate=False)
    vx = tr.twist_base[:, 0]
    assert np.all(vx[100:lean] == 0.0)
    starts = lean + int(np.argmax(vx[lean:] > 0.0))
    # the lean is seen once it passes δ = 15 N over the settled 40 N (0.75 s at 20 N/s), plus
    # what the baseline followed (10 N/s at most) until the smoothings' gap showed the rate
    # (~0.2 s, 0.3 s slow smoothing): up to 3 N, 0.15 s more
    assert lean + 75 < starts <= lean + 90
    paper = run(GuidingController(er20, _config(False, settle)), _q0(er20), drift,
                interpolate=False)
    assert np.any(paper.twist_base[100:lean, 0] > 0.0)


def test_a_hold_at_rest_let_go_stays_put_while_the_estimate_swings(er20: Robot) -> None:
    """A hand resting on the still tool (12 N) lets go and the estimate swings to -30 N (the
    drives unloading, within the estimator's filter time) and stays there: the tool never
    moves; the paper's law with the settling moves it once the settling is over."""
    w = np.zeros((300, 6))
    w[:100, 0] = 12.0
    w[100:, 0] = -30.0 + 42.0 * np.exp(-np.arange(200) * DT / TAU)
    tr = run(GuidingController(er20, _config()), Q_WORK, w, interpolate=False)
    assert np.all(tr.twist_base == 0.0) and np.all(tr.fault == Fault.NONE)
    paper = run(GuidingController(er20, _config(False)), Q_WORK, w, interpolate=False)
    assert paper.twist_base[-1, 0] < 0.0


def _estimate(k_n: int, steps: list[tuple[int, tuple[float, float, float]]]) -> np.ndarray:
    """The force estimate of ``k_n`` cycles: from each (cycle, force) on, toward that force at
    the estimator's pace (its 3 Hz low-pass), from where the one before had got to."""
    w = np.zeros((k_n, 6))
    now = np.zeros(3)
    for (start, force), (stop, _) in zip(steps, [*steps[1:], (k_n, (0.0, 0.0, 0.0))],
                                         strict=True):
        t = np.arange(stop - start)[:, None] * DT
        target = np.array(force)
        w[start:stop, :3] = target + (now - target) * np.exp(-t / TAU)
        now = w[stop - 1, :3]
    return w


def test_a_let_go_of_the_level_is_a_quick_fall_back_against_it() -> None:
    """Against a level that took up a hold, a letting go (a step of 20 N, 4/3 δ, at the
    estimator's pace, back against the level, on any axis where the level has a component)
    is activity, also where the magnitude rises (the estimate swings past zero); a change
    along the level (a lean, the drives' ramp), a slow drift back (10 N/s, rest_drift.py) and
    a step of a third of δ are not; the torque part is measured against the torque's δ."""
    forget = float(np.exp(-DT / RELEASE_WINDOW_S))
    alpha = HandReleaseConfig().alpha(DT)
    friction = np.array([15.0, 15.0, 15.0, 3.0, 3.0, 3.0])

    def active(level: np.ndarray, change: np.ndarray, ramp: bool = False) -> bool:
        smooth, reference = level.copy(), level.copy()
        seen = False
        for k in range(300):
            t = k * DT
            w = level + (change * t if ramp else change * (1.0 - np.exp(-t / TAU)))
            smooth += alpha * (w - smooth)
            seen = level_let_go(smooth, friction, RELEASE_DROP, forget, level,
                                reference) or seen
        return seen

    hold = np.array([-6.0, 5.0, -16.0, 0.0, 0.0, 0.0])     # a hold the level took up
    assert active(hold, np.array([22.0, -7.0, 7.0, 0.0, 0.0, 0.0]))  # |w| 17.8 -> 18.7 N
    for axis, sign in ((0, 1.0), (1, -1.0), (2, 1.0)):
        step = np.zeros(6)
        step[axis] = 20.0 * sign
        assert active(hold, step)
        assert not active(hold, -step)               # along the level: a lean
    assert not active(hold, np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0]))
    assert not active(hold, np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0]), ramp=True)
    assert not active(hold, np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0]), ramp=True)
    twist = np.array([0.0, 0.0, 0.0, 0.0, 2.0, 0.0])
    assert active(twist, np.array([0.0, 0.0, 0.0, 0.0, -4.0, 0.0]))  # 4 N·m > 3/2
    assert not active(twist, np.array([0.0, 0.0, 0.0, 0.0, -1.0, 0.0]))


def test_a_hold_taken_in_during_the_stop_does_not_resume_at_its_letting_go(
        er20: Robot) -> None:
    """During the stop after a letting go the estimate swings to a 28 N phantom; a hand grips
    against it (the estimate falls to a 25 N hold: no fresh rise, and x's fall is taken for a
    release at rest, which restarts the settling), holds 2.5 s, and lets go (x back to the
    phantom's level). Read against the hold as the settled level, that letting go is a rise
    of 18 N (> δ) with no hand on the tool: the fall back against the level clears it until
    the estimate is quiet again, so the tool stays put. A grip that adds 40 N then moves it,
    as before."""
    k_n, grip, letting_go, new_grip = 1100, 200, 450, 950
    w = _estimate(k_n, [(0, (40.0, 0.0, 0.0)), (50, (12.0, 0.0, -10.0)),
                        (120, (20.0, 0.0, -20.0)), (grip, (2.0, 0.0, -25.0)),
                        (letting_go, (20.0, 0.0, -14.0)), (new_grip, (60.0, 0.0, -14.0))])
    tr = run(GuidingController(er20, _config(settle_s=1.5)), _q0(er20), w, interpolate=False)
    vx = tr.twist_base[:, 0]
    stopped = 50 + int(np.argmax(vx[50:] == 0.0))
    assert vx[49] > 0.0 and stopped < grip and np.all(tr.fault == Fault.NONE)
    assert np.all(tr.twist_base[stopped:new_grip] == 0.0)
    assert np.any(vx[new_grip:] > 0.0)


def test_a_lean_along_the_settled_level_resumes_as_before(er20: Robot) -> None:
    """The same hold taken up as the settled level, then the hand leans on along it at 50 N/s
    to 65 N (a seam's operator whose target moved on): a rise of δ over the level within about 0.3 s
    resumes guiding, toward the lean. Only a fall back against the level clears it; a rule
    that cleared it on any quick change would leave leans of 30–100 N/s to nothing (too slow
    for a fresh rise)."""
    k_n, grip, lean = 800, 200, 450
    w = _estimate(k_n, [(0, (40.0, 0.0, 0.0)), (50, (12.0, 0.0, -10.0)),
                        (120, (20.0, 0.0, -20.0)), (grip, (2.0, 0.0, -25.0))])
    w[lean:, 2] -= np.minimum(50.0 * np.arange(k_n - lean) * DT, 40.0)   # to 65 N
    tr = run(GuidingController(er20, _config(settle_s=1.5)), _q0(er20), w, interpolate=False)
    stopped = 50 + int(np.argmax(tr.twist_base[50:, 0] == 0.0))
    assert stopped < grip and np.all(tr.fault == Fault.NONE)
    assert np.all(tr.twist_base[stopped:lean] == 0.0)
    moved = lean + int(np.argmax(tr.twist_base[lean:, 2] < 0.0))
    assert tr.twist_base[moved, 2] < 0.0 and (moved - lean) * DT <= 0.45


def _friction_scaled(er20: Robot, scale: float) -> ParamsFile:
    pf = shipped_guiding_params(er20)
    st = pf.params.stribeck
    assert st is not None
    params = replace(pf.params, load_friction=scale * pf.params.load_friction,
                     stribeck=replace(st, f1=scale * st.f1, f2=scale * st.f2, f3=scale * st.f3,
                                      f4=scale * st.f4))
    return replace(pf, params=params)


def test_release_with_a_wrong_friction_model_stops_on_the_simulated_robot(er20: Robot) -> None:
    """The simulated er20 (realistic plant) guided with its identified model whose friction is
    30 % too high: after a 40 N push at the 0.2 m/s cap is released, the estimate keeps the
    friction's error in the direction of motion. With the stop the tool comes to rest within
    the shortest stop at the acceleration limit + 20 mm (issue 24's bound for any one release;
    with the shipped parameters of 2026-11-25 it measured 5.0 mm) and stays there; the paper's
    law alone runs on by 50 mm or more."""
    pf = _friction_scaled(er20, 1.3)
    travel = {}
    for enabled in (True, False):
        guiding = replace(light_guiding(), hand_release=HandReleaseConfig(enabled=enabled))
        s = run_sim_session(er20, pf, SimSessionConfig(operator="push-x", plant="realistic",
                                                       loop=LoopConfig(guiding=guiding)))
        log = s.result.log
        assert np.max(log.twist_cmd_base[:, 0]) == pytest.approx(0.2)
        over = release_overruns(log, A_MAX)
        moving = release_motion_times(log, A_MAX)
        assert over is not None and moving is not None and over.size == 1
        travel[enabled] = (float(over[0]), float(moving[0]))
        assert s.summary.faults == []
    assert travel[True][0] <= 20e-3 and travel[True][1] <= 0.1
    assert travel[False][0] >= 50e-3
