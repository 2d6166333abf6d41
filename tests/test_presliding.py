"""Presliding test: the design, the Dahl state, the fit of z₀ (synthetic and on the simulator),
the params file, and the estimator's friction at rest driven by the measured displacement."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import DriveModelParameters, nominal_drive_parameters
from leadthrough.errors import DataError
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.excitation.presliding import PreslidingTestConfig, design_presliding_test
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import load_params, save_params
from leadthrough.identification.presliding import (
    PreslidingAnalysisConfig,
    dahl_states,
    fit_presliding,
)
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import SimRecording, record_presliding_test
from leadthrough.sim.robot import SimConfig, SimRobot

SHORT = PreslidingTestConfig(amplitudes=(3e-5, 1e-4, 2e-4, 4e-4, 8e-4, 1.5e-3), move_s=0.3,
                             rest_s=0.6)


def test_design_rests_at_the_start_and_its_velocity_is_the_derivative(er20: Robot) -> None:
    q0 = guide_start_pose(er20)
    test = design_presliding_test(er20, q0, SHORT)
    q, qd, dt = test.samples.q, test.samples.qd, 1e-3
    np.testing.assert_array_equal(q[0], q0)
    np.testing.assert_allclose(q[-1], q0, atol=1e-15)
    assert test.amplitude.size == 2 * len(SHORT.amplitudes)
    np.testing.assert_array_equal(test.sign, np.tile([1.0, -1.0], len(SHORT.amplitudes)))
    # every joint follows the same offset; its extremes are the preconditioning moves
    offset = q - q0
    np.testing.assert_allclose(offset, offset[:, :1] * np.ones(er20.n), atol=1e-15)
    assert np.isclose(np.abs(offset).max(), SHORT.precondition)
    # velocity: the derivative of the position (central differences; the cosine moves start
    # and stop with a finite acceleration, a·dt/2 of difference error there)
    np.testing.assert_allclose(np.gradient(q, dt, axis=0)[1:-1], qd[1:-1],
                               atol=1e-2 * np.abs(qd).max())
    # each trial: precondition out by −s·P and back, then the excursion out by −s·A and back
    for a, s, t0 in zip(test.amplitude, test.sign, test.trial_start_s, strict=True):
        i = round(t0 / dt)
        trial = offset[i:i + round(2 * (2 * SHORT.move_s + SHORT.rest_s) / dt), 0]
        half = trial.size // 2
        assert np.isclose(trial[:half].min() if s > 0 else -trial[:half].max(),
                          -SHORT.precondition)
        assert np.isclose(-s * trial[half:].min() if s > 0 else trial[half:].max(), a)


def test_design_refuses_a_start_too_close_to_a_limit(er20: Robot) -> None:
    q0 = guide_start_pose(er20)
    q0[2] = er20.upper_limits[2] - 0.05
    with pytest.raises(DataError, match="joint limits") as e:
        design_presliding_test(er20, q0)
    assert e.value.field == f"q_start[{er20.joint_names[2]}]"
    with pytest.raises(DataError, match="precondition"):
        PreslidingTestConfig(amplitudes=(1e-4, 3e-3), precondition=2e-3)


def test_dahl_state_of_an_excursion_and_the_play_operator() -> None:
    """Out by x₁·z₀ against a saturated state and back by x₂·z₀: the state changes by
    2(1 − e^{−x₁})e^{−x₂}; chatter within the play band changes nothing."""
    z0 = 2e-4
    x1, x2 = 0.8, 0.5
    top = 40 * z0
    ramp = np.concatenate([np.linspace(0.0, top, 500),                  # saturate at +1
                           np.linspace(top, top - x1 * z0, 100)[1:],
                           np.linspace(top - x1 * z0, top - x1 * z0 + x2 * z0, 100)[1:]])
    s = dahl_states(ramp[:, None], np.zeros(1), np.array([z0]), np.ones(1))
    change = s[-1, 0] - s[499, 0]
    # from +1: out (down) by x₁ → 1 − 2(1 − e^{−x₁}); back (up) by x₂ → +1 − (…)·e^{−x₂}
    assert np.isclose(change, -2 * (1 - np.exp(-x1)) * np.exp(-x2), rtol=1e-9)
    # chatter of one count at rest (the last move was up, the chatter goes down and back):
    # the raw encoder wears the state down, the play operator passes none of it
    count = 3.3e-7
    chatter = np.concatenate([ramp, ramp[-1] - count * (np.arange(5000) % 2)])
    raw = dahl_states(chatter[:, None], np.zeros(1), np.array([z0]), np.ones(1))
    played = dahl_states(chatter[:, None], np.array([1.25 * count]), np.array([z0]),
                         np.ones(1))
    assert abs(raw[-1, 0]) < 0.1 * abs(s[-1, 0])
    assert played[-1, 0] == dahl_states(ramp[:, None], np.array([1.25 * count]),
                                        np.array([z0]), np.ones(1))[-1, 0]


def test_dahl_state_relaxes_at_rest_at_its_rate() -> None:
    """Saturated, then 2 s at rest with r = 0.25 /s: s = e^{−0.5}; r = 0 keeps it."""
    z0, dt, rate = 2e-4, 1e-3, 0.25
    q = np.concatenate([np.linspace(0.0, 40 * z0, 500), np.full(2000, 40 * z0)])[:, None]
    relaxed = dahl_states(q, np.zeros(1), np.array([z0]), np.array([np.exp(-rate * dt)]))
    kept = dahl_states(q, np.zeros(1), np.array([z0]), np.ones(1))
    assert kept[499, 0] == pytest.approx(1.0, abs=1e-9) and kept[-1, 0] == kept[499, 0]
    assert relaxed[-1, 0] / relaxed[499, 0] == pytest.approx(np.exp(-rate * 2000 * dt),
                                                             rel=1e-9)


def _synthetic(er20: Robot, z0: np.ndarray, level: np.ndarray, noise: float,
               seed: int = 0, rate: np.ndarray | None = None) -> Recording:
    """The designed test played exactly (no servo), torque = gravity + Dahl friction (relaxing
    at ``rate`` [1/s], default none) + noise."""
    test = design_presliding_test(er20, guide_start_pose(er20), SHORT)
    q = test.samples.q
    data = er20.model.createData()
    gravity = np.array([pin.computeGeneralizedGravity(er20.model, data, qi) for qi in q])
    dt = test.samples.time[1] - test.samples.time[0]
    decay = np.ones(er20.n) if rate is None else np.exp(-dt * rate)
    s = dahl_states(q, np.zeros(er20.n), z0, decay)
    rng = np.random.default_rng(seed)
    torque = gravity + level * s + noise * rng.standard_normal(q.shape)
    return Recording(time=test.samples.time, q=q, torque=torque, robot=er20.name,
                     source="synthetic presliding test")


def test_fit_recovers_z0_and_level_of_a_dahl_drive(er20: Robot) -> None:
    z0 = np.array([2.3, 2.4, 1.7, 1.5, 1.9, 2.2]) * 1e-4
    level = np.array([130.0, 190.0, 32.0, 9.0, 9.5, 2.9])
    cfg = PreslidingAnalysisConfig(play_counts=0.0)
    exact = fit_presliding(_synthetic(er20, z0, level, 0.0), er20, cfg)
    np.testing.assert_allclose(exact.presliding, z0, rtol=1e-3)
    np.testing.assert_allclose(exact.level, level, rtol=1e-3)
    assert exact.pairs.first.size == 2 * 2 * len(SHORT.amplitudes)
    noisy = fit_presliding(_synthetic(er20, z0, level, 0.02 * level), er20, cfg)
    # 2 % torque noise averaged over 250 samples per rest: z₀ within 2 %, and the reported
    # standard error covers the actual error
    np.testing.assert_allclose(noisy.presliding, z0, rtol=0.02)
    assert np.all(np.abs(noisy.presliding - z0) <= 4 * noisy.presliding_std)
    # no relaxation in the data: none fitted (r at the grid's 0 or within its error of it)
    assert np.all(exact.relaxation <= 1e-3)
    assert np.all(noisy.relaxation <= 4 * noisy.relaxation_std + 1e-3)


def test_fit_recovers_a_friction_that_relaxes_at_rest(er20: Robot) -> None:
    """A drive whose friction relaxes at rest (the simulated wrists' rates): z₀, r and g are
    recovered; fitted without r, z₀ reads short (here by 6-9 %) and fits far worse."""
    z0 = np.array([2.3, 2.4, 1.7, 1.5, 1.9, 2.2]) * 1e-4
    level = np.array([130.0, 190.0, 32.0, 9.0, 9.5, 2.9])
    rate = np.array([0.0, 0.01, 0.03, 0.17, 0.12, 0.08])
    cfg = PreslidingAnalysisConfig(play_counts=0.0)
    rec = _synthetic(er20, z0, level, 0.0, rate=rate)
    fit = fit_presliding(rec, er20, cfg)
    np.testing.assert_allclose(fit.presliding, z0, rtol=1e-2)
    np.testing.assert_allclose(fit.relaxation, rate, rtol=2e-2, atol=1e-3)
    np.testing.assert_allclose(fit.level, level, rtol=1e-2)
    plain = fit_presliding(rec, er20, replace(cfg, max_relaxation=0.0))
    assert np.all(plain.relaxation == 0.0)
    assert np.all(plain.presliding[3:] < 0.95 * z0[3:])
    assert np.all(plain.rms[3:] > 10 * fit.rms[3:] + 1e-3)
    params = fit.applied_to(nominal_drive_parameters(er20))
    np.testing.assert_array_equal(params.presliding, fit.presliding)
    np.testing.assert_array_equal(params.presliding_relaxation, fit.relaxation)


def test_fit_refuses_a_recording_without_rests(er20: Robot) -> None:
    t = np.arange(5000) * 1e-3
    q = guide_start_pose(er20) + 0.1 * np.sin(2 * np.pi * 0.5 * t)[:, None]
    rec = Recording(time=t, q=q, torque=np.zeros_like(q), robot=er20.name, source="sine.csv")
    with pytest.raises(DataError, match="too few out-and-back") as e:
        fit_presliding(rec, er20)
    assert e.value.source == "sine.csv" and "presliding" in (e.value.expected or "")


def test_fit_on_the_simulator_measures_the_gears_presliding(er20: Robot) -> None:
    """The simulated drives' LuGre bristles (σ₁ damping, load-dependent level, the servo's
    integrator) are not a Dahl model. Joints 1–3 read z₀ within 12 % and the static level
    within 10 %. The wrists read short: their servo leaves them a few counts off the command,
    and the load-dependent level then drifts at rest (noted in the README)."""
    rec = record_presliding_test(er20, seed=1, run=3, q_start=guide_start_pose(er20),
                                 plant="ideal")  # the bounds are the ideal plant's (issue 24)
    fit = fit_presliding(rec.measured, er20)
    truth = SimRobot(er20, SimConfig(seed=1, plant="ideal")).truth.drive
    static = (truth.coulomb_motor + truth.coulomb_gear + truth.stribeck_motor
              + truth.stribeck_gear + truth.bristle)
    np.testing.assert_allclose(fit.presliding[:3], truth.bristle_presliding[:3], rtol=0.12)
    np.testing.assert_allclose(fit.level[:3], static[:3], rtol=0.10)
    assert fit.pairs.first.size >= 30 and fit.pairs.unpaired == 0


def test_the_wrists_friction_relaxes_at_rest_on_the_simulator(
        er20: Robot, presliding_test_run: SimRecording) -> None:
    """The simulated servo dithers a joint held still far below one count, and the plant's
    LuGre bristles wear under it (the friction at rest decays over seconds). On the true
    positions with no play operator, the plain Dahl fit reads the wrists' z₀ to 10 %, so the
    motion explains it; on the encoder it reads them 20-30 % short, and the relaxation rate r
    takes the unseen motion's place: the wrists' residual falls 2-5×."""
    rec = presliding_test_run
    truth = SimRobot(er20, SimConfig(seed=1)).truth.drive
    plain_cfg = PreslidingAnalysisConfig(max_relaxation=0.0)
    seen = replace(rec.measured, q=rec.log.truth.q)
    exact = fit_presliding(seen, er20, replace(plain_cfg, play_counts=0.0))
    np.testing.assert_allclose(exact.presliding[3:], truth.bristle_presliding[3:], rtol=0.10)
    plain = fit_presliding(rec.measured, er20, plain_cfg)
    assert np.all(plain.presliding[3:] < 0.85 * truth.bristle_presliding[3:])
    fit = fit_presliding(rec.measured, er20)
    assert np.all(fit.relaxation[3:] > 0.05) and np.all(fit.relaxation[3:] < 0.3)
    assert np.all(fit.relaxation[3:] > 5 * fit.relaxation_std[3:])
    assert np.all(fit.rms[3:] < plain.rms[3:] / 2)
    assert np.all(fit.rms[3:5] < plain.rms[3:5] / 3)


@pytest.mark.xfail(strict=True, reason="known bias: with the relaxation the wrists' z₀ reads "
                   "11-22 % long (19-29 % short without it; README, Presliding test)")
def test_the_wrists_presliding_within_the_main_axes_tolerance(
        er20: Robot, presliding_test_run: SimRecording) -> None:
    """The wrists held to joints 1–3's 12 %: fails today (strict), so a fix shows up."""
    rec = presliding_test_run
    fit = fit_presliding(rec.measured, er20)
    truth = SimRobot(er20, SimConfig(seed=1)).truth.drive
    np.testing.assert_allclose(fit.presliding[3:], truth.bristle_presliding[3:], rtol=0.12)


def test_params_file_keeps_presliding_and_refuses_bad_values(er20: Robot, tmp_path: Path
                                                             ) -> None:
    z0 = np.linspace(1e-4, 3e-4, er20.n)
    params = replace(nominal_drive_parameters(er20), presliding=z0)
    zeros = np.zeros(er20.n)
    stats = ResidualStats(mean=zeros, std=np.ones(er20.n), std_pct_max=zeros, rms=zeros,
                          rel_error_pct=0.0, J=1.0, k_omega=1.0,
                          samples=np.ones(er20.n, dtype=np.int64))
    path = save_params(tmp_path / "p.toml", er20, "ols", params, stats)
    np.testing.assert_array_equal(load_params(path, er20).params.presliding, z0)
    text = path.read_text()
    first = f"presliding = {float(z0[0])!r}"
    (tmp_path / "partial.toml").write_text(text.replace(first + "\n", "", 1))
    with pytest.raises(DataError, match="some joints only"):
        load_params(tmp_path / "partial.toml", er20)
    (tmp_path / "neg.toml").write_text(text.replace(first, "presliding = -1e-4", 1))
    with pytest.raises(DataError, match="out of range") as e:
        load_params(tmp_path / "neg.toml", er20)
    assert e.value.field == f"joints.{er20.joint_names[0]}.presliding"
    with pytest.raises(DataError, match="presliding"):
        replace(params, presliding=np.full(er20.n - 1, 1e-4))
    assert load_params(save_params(tmp_path / "none.toml", er20, "ols",
                                   nominal_drive_parameters(er20), stats),
                       er20).params.presliding.size == 0


def test_params_file_keeps_the_relaxation_and_refuses_bad_values(er20: Robot, tmp_path: Path
                                                                 ) -> None:
    n = er20.n
    rate = np.linspace(0.0, 0.2, n)
    params = replace(nominal_drive_parameters(er20), presliding=np.full(n, 2e-4),
                     presliding_relaxation=rate)
    zeros = np.zeros(n)
    stats = ResidualStats(mean=zeros, std=np.ones(n), std_pct_max=zeros, rms=zeros,
                          rel_error_pct=0.0, J=1.0, k_omega=1.0,
                          samples=np.ones(n, dtype=np.int64))
    path = save_params(tmp_path / "p.toml", er20, "ols", params, stats)
    np.testing.assert_array_equal(load_params(path, er20).params.presliding_relaxation, rate)
    text = path.read_text()
    last = f"presliding_relaxation = {float(rate[-1])!r}"
    assert last in text
    (tmp_path / "partial.toml").write_text(text.replace(last + "\n", "", 1))
    with pytest.raises(DataError, match="some joints only") as e:
        load_params(tmp_path / "partial.toml", er20)
    assert e.value.field == "joints.*.presliding_relaxation"
    (tmp_path / "neg.toml").write_text(text.replace(last, "presliding_relaxation = -0.1", 1))
    with pytest.raises(DataError, match="out of range") as e:
        load_params(tmp_path / "neg.toml", er20)
    assert e.value.field == f"joints.{er20.joint_names[-1]}.presliding_relaxation"
    assert e.value.value == -0.1
    alone = "\n".join(line for line in text.splitlines() if not line.startswith("presliding ="))
    (tmp_path / "alone.toml").write_text(alone)
    with pytest.raises(DataError, match="without presliding"):
        load_params(tmp_path / "alone.toml", er20)
    with pytest.raises(DataError, match="relaxation"):
        replace(params, presliding=np.zeros(0))
    with pytest.raises(DataError, match="relaxation"):
        replace(params, presliding_relaxation=np.full(n, np.nan))


def _tau_ext_without_current(er20: Robot, params: DriveModelParameters, q_path: np.ndarray,
                             config: EstimatorConfig, qd_cmd: np.ndarray | None = None
                             ) -> np.ndarray:
    """τ_ext of an estimator fed ``q_path`` with no current and the commands ``qd_cmd`` (shape
    of ``q_path``; None: none): friction + τ̂_d of the rigid body, per sample."""
    est = ExternalForceEstimator(er20, params, np.zeros(er20.n), config)
    inp, out = est.make_input(), est.make_output()
    est.reset(q_path[0])
    commands = np.zeros_like(q_path) if qd_cmd is None else qd_cmd
    rows = []
    for k, (qk, ck) in enumerate(zip(q_path, commands, strict=True)):
        inp.t, inp.q[:], inp.current[:], inp.qd_cmd[:] = k * 1e-3, qk, 0.0, ck
        est.update(inp, out)
        rows.append(out.tau_ext.copy())
    return np.array(rows)


@settings(max_examples=15, deadline=None)
@given(x=st.floats(0.1, 4.0), joint=st.integers(0, 5))
def test_estimator_friction_at_rest_follows_the_displacement_with_each_joints_z0(
        er20: Robot, x: float, joint: int) -> None:
    """A joint commanded to stand still but displaced by x·z₀_j (a push) has its friction turn
    by g·(1 − e^{−x}) with its own z₀ from the params, whatever the others' z₀."""
    n = er20.n
    z0 = np.linspace(1.0e-4, 3.5e-4, n)
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                     viscous=np.zeros(n), presliding=z0)
    steps = 300
    q0 = guide_start_pose(er20)
    path = np.tile(q0, (steps + 200, 1))
    path[:steps, joint] += np.linspace(0.0, x * z0[joint], steps)
    path[steps:, joint] += x * z0[joint]
    cfg = EstimatorConfig(friction_velocity="command", warm_up_s=0.0, output_cutoff_hz=400.0,
                          presliding_play_counts=0.0)
    moved = _tau_ext_without_current(er20, params, path, cfg)
    still = _tau_ext_without_current(er20, params, np.tile(path[-1], (path.shape[0], 1)), cfg)
    friction = moved[-1, joint] - still[-1, joint]   # τ̂_d differs by the friction only
    assert friction == pytest.approx(10.0 * (1.0 - np.exp(-x)), rel=1e-3)


@pytest.mark.parametrize("joint", [1, 4])
def test_estimator_friction_at_rest_relaxes_at_the_params_rate(er20: Robot, joint: int
                                                                ) -> None:
    """A joint pushed over by 10 z₀ and then held still: its friction relaxes as e^{−r·t} with
    the params' ``presliding_relaxation``, and stays with none (the old params)."""
    n = er20.n
    rate = np.linspace(0.05, 0.3, n)
    base = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                   viscous=np.zeros(n), presliding=np.full(n, 2e-4))
    q0 = guide_start_pose(er20)
    path = np.tile(q0, (2300, 1))
    path[:300, joint] += np.linspace(0.0, 2e-3, 300)
    path[300:, joint] += 2e-3
    cfg = EstimatorConfig(friction_velocity="command", warm_up_s=0.0, output_cutoff_hz=400.0,
                          presliding_play_counts=0.0)
    still = _tau_ext_without_current(er20, base, np.tile(path[-1], (path.shape[0], 1)), cfg)
    held = _tau_ext_without_current(er20, base, path, cfg)[:, joint] - still[:, joint]
    relaxing = _tau_ext_without_current(
        er20, replace(base, presliding_relaxation=rate), path, cfg)[:, joint] - still[:, joint]
    assert held[-1] == pytest.approx(held[500], rel=1e-6) and held[-1] > 9.9
    assert relaxing[-1] / relaxing[500] == pytest.approx(np.exp(-rate[joint] * 1.799),
                                                         rel=1e-3)


def test_estimator_play_operator_ignores_encoder_chatter_at_rest(er20: Robot) -> None:
    n = er20.n
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                     viscous=np.zeros(n), presliding=np.full(n, 2e-4))
    q0 = guide_start_pose(er20)
    res = er20.encoder_resolution
    push = np.tile(q0, (3000, 1))
    push[:500] += np.linspace(0.0, 1e-3, 500)[:, None]       # turn the friction to +g
    push[500:] += 1e-3
    push[1000:] += res * (np.arange(2000) % 2)[:, None]      # then one count of chatter
    still = np.tile(push[999], (3000, 1))
    for counts, worn in ((2.5, False), (0.0, True)):
        cfg = EstimatorConfig(friction_velocity="command", warm_up_s=0.0,
                              output_cutoff_hz=400.0, presliding_play_counts=counts)
        # averaged over the last second: the chatter's acceleration estimate alternates
        friction = (_tau_ext_without_current(er20, params, push, cfg)
                    - _tau_ext_without_current(er20, params, still, cfg))[-1000:].mean(axis=0)
        if worn:
            assert np.all(friction < 5.0)      # the chatter has worn the state down
        else:
            np.testing.assert_allclose(friction, 10.0 * (1 - np.exp(-5.0)), rtol=1e-3)


@pytest.mark.parametrize("measured_z0", [True, False])
def test_a_creeping_joint_keeps_the_friction_its_encoder_says(er20: Robot,
                                                              measured_z0: bool) -> None:
    """slow_command_velocity: a joint that slid forward and is then commanded back at a creep,
    while its encoder stands still (the gear sticks), keeps its forward friction; once the
    encoder moves back by x·z₀ (its measured z₀), the friction turns by the Dahl step over
    that displacement. Without a measured z₀ the setting does nothing: the command turns it."""
    n, j, g = er20.n, 4, 10.0
    z0 = np.full(n, 2e-4)
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, g),
                     viscous=np.zeros(n), presliding=z0 if measured_z0 else np.empty(0))
    q0 = guide_start_pose(er20)
    slide, stick, back = 200, 300, 300
    steps = slide + stick + back
    qd_cmd = np.zeros((steps, n))
    qd_cmd[:slide, j] = 0.05                       # slides forward: friction +g
    qd_cmd[slide:, j] = -0.005                     # then a creeping command back
    path = np.tile(q0, (steps, 1))
    path[:slide, j] += 0.05 * 1e-3 * np.arange(slide)
    path[slide:, j] = path[slide - 1, j]           # the gear sticks
    x = 3.0
    path[slide + stick:, j] -= np.linspace(0.0, x * 2e-4, back)   # then follows, x·z₀
    cfg = EstimatorConfig(friction_velocity="command", warm_up_s=0.0, output_cutoff_hz=400.0,
                          presliding_play_counts=0.0, slow_command_velocity=0.01)
    frictionless = replace(params, coulomb=np.zeros(n))
    # τ̂_d differs by the friction term only
    friction = (_tau_ext_without_current(er20, params, path, cfg, qd_cmd)
                - _tau_ext_without_current(er20, frictionless, path, cfg, qd_cmd))
    at = slide + stick - 1
    if measured_z0:
        assert friction[at, j] == pytest.approx(g, rel=1e-3)     # still the forward friction
        turned = g - 2.0 * g * (1.0 - np.exp(-x))                 # Dahl over x·z₀ toward −g
        assert friction[-1, j] == pytest.approx(turned, rel=2e-2)
    else:
        # 0.3 s at −0.005 rad/s is 7.5 z₀ of commanded motion: the command has turned it
        assert friction[at, j] < -0.9 * g


def test_slow_command_velocity_must_be_finite_and_not_negative() -> None:
    for bad in (-0.01, float("nan"), float("inf")):
        with pytest.raises(DataError, match="slow_command_velocity"):
            EstimatorConfig(slow_command_velocity=bad)
