"""Estimation: causal filters, the real-time estimator's contract, payload identification."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from leadthrough.damped_least_squares import damping_of, smallest_eigenvalue_3
from leadthrough.data.recording import Recording
from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.errors import DataError
from leadthrough.estimation.estimator import (
    EstimatorConfig,
    ExternalForceEstimator,
)
from leadthrough.estimation.estimator import EstimatorStatus as Status
from leadthrough.estimation.filters import (
    differentiate,
    differentiator_coefficients,
    low_pass_alpha,
    restart_differentiator,
)
from leadthrough.estimation.payload import estimate_payload
from leadthrough.estimation.wrench import friction_weights, wrench_from_torque
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim import ConstantWrench, Payload, SimConfig, SimRobot, hold
from leadthrough.sim.mujoco_model import build_mujoco_model
from leadthrough.state_records import view
from test_identification import _trajectory

Q0 = np.array([0.3, -0.6, 0.4, 0.5, 0.8, 0.2])


def test_differentiator_tracks_a_sine() -> None:
    dt, w = 1e-3, 2 * np.pi * 0.5
    coef = differentiator_coefficients(20.0, dt)[0]
    t = np.arange(0, 4, dt)
    position, velocity, acceleration = np.zeros(1), np.zeros(1), np.zeros(1)
    restart_differentiator(np.zeros(1), position, velocity, acceleration)
    v, a = np.empty(t.size), np.empty(t.size)
    for k, tk in enumerate(t):
        differentiate(coef, np.array([np.sin(w * tk)]), position, velocity, acceleration)
        v[k], a[k] = velocity[0], acceleration[0]
    late = t > 1.0
    # critically damped 2nd order at 20 Hz: small lag at 0.5 Hz (≈ 2·ζ/ω_c = 16 ms)
    lag = 2.0 / (2 * np.pi * 20.0)
    np.testing.assert_allclose(v[late], w * np.cos(w * (t[late] - lag)), atol=0.02 * w)
    # acceleration: half a sample more lag (backward difference)
    np.testing.assert_allclose(a[late], -w * w * np.sin(w * (t[late] - lag - 5e-4)),
                               atol=0.05 * w * w)


def test_low_pass_step_response() -> None:
    """y ← y + α·(x − y) with α = 1 − e^(−2π·f·dt): after 1 s at 3 Hz the step's error is
    e^(−6π) ≈ 6.5e-9 of the step."""
    alpha = low_pass_alpha(3.0, 1e-3)
    assert alpha == pytest.approx(1 - np.exp(-2 * np.pi * 3.0 * 1e-3), rel=1e-15)
    y = np.zeros(2)
    for _ in range(1000):
        y += alpha * (np.array([1.0, -2.0]) - y)
    np.testing.assert_allclose(y, [1.0, -2.0], rtol=1e-8)
    assert abs(y[0] - 1.0) == pytest.approx(np.exp(-6 * np.pi), rel=1e-6)
    with pytest.raises(DataError, match="cutoff_hz"):
        differentiator_coefficients(600.0, 1e-3)
    with pytest.raises(DataError, match="cutoff_hz"):
        low_pass_alpha(0.0, 1e-3)


def _quiet_config() -> SimConfig:
    """A simulator of exactly the nominal model: no sensor noise, no friction, no CAD error
    (the ideal plant: the realistic one's dress pack, drives and timing are model errors)."""
    from leadthrough.sim.drivetrain import DriveTrainConfig
    from leadthrough.sim.sensors import SensorConfig

    return SimConfig(seed=1, link_deviation=0.0, plant="ideal",
                     sensors=SensorConfig(current_noise=0.0, current_drift=0.0,
                                          current_bias=0.0, adc_bits=32),
                     drive=DriveTrainConfig(coulomb_motor=0, coulomb_gear=0, stribeck_motor=0,
                                            stribeck_gear=0, viscous=0, bristle=0,
                                            load_coefficient=0, ripple=0,
                                            rotor_inertia_spread=0))


def _estimator(robot: Robot, **kw: object) -> ExternalForceEstimator:
    return ExternalForceEstimator(robot, nominal_drive_parameters(robot), np.zeros(robot.n),
                                  EstimatorConfig(**kw))  # type: ignore[arg-type]


@pytest.mark.parametrize("method", ["direct", "momentum"])
def test_estimates_a_push_with_the_true_model(er20: Robot, method: str) -> None:
    """With a noise-free simulator of the nominal model, the estimate converges to J^T F."""
    quiet = _quiet_config()
    force = np.array([30.0, -40.0, 20.0])
    sim = SimRobot(er20, quiet, q0=Q0, operator=ConstantWrench((*force, 0, 0, 0), 0.5))
    log = hold(sim, 3.0)
    params = nominal_drive_parameters(er20)
    est = ExternalForceEstimator(er20, params, np.zeros(6), EstimatorConfig(method=method))
    inp, out = est.make_input(), est.make_output()
    est.reset(log.q[0])
    for k in range(log.time.size):
        inp.t, inp.q[:], inp.current[:] = log.time[k], log.q[k], log.current[k]
        status = est.update(inp, out)
    assert status is Status.OK
    np.testing.assert_allclose(out.wrench[:3], force, atol=1.0)
    np.testing.assert_allclose(out.tau_ext, log.truth.external_torque[-1], atol=0.5)


def test_nonfinite_input_latches_a_fault(er20: Robot) -> None:
    est = _estimator(er20)
    inp, out = est.make_input(), est.make_output()
    est.reset(Q0)
    inp.q[:] = Q0
    for _ in range(10):
        est.update(inp, out)
    last = out.wrench.copy()
    inp.current[2] = np.nan
    assert est.update(inp, out) is Status.FAULT_NONFINITE
    inp.current[2] = 0.0
    assert est.update(inp, out) is Status.FAULT_NONFINITE  # latched until reset
    np.testing.assert_array_equal(out.wrench, last)
    est.reset(Q0)
    assert est.update(inp, out) is Status.WARMING_UP


@pytest.mark.parametrize("method", ["direct", "momentum"])
@pytest.mark.parametrize("bad", ["qd_cmd nan", "qd_cmd inf", "q 1e155", "current 1.7e308"])
def test_bad_command_or_overflow_latches_a_fault_and_keeps_the_output(
        er20: Robot, method: str, bad: str) -> None:
    """A non-finite commanded velocity (the friction follows it), or a finite input so large
    that the filters overflow: FAULT_NONFINITE, the last valid output kept and finite, latched
    until reset (never an OK status over NaN)."""
    est = _estimator(er20, method=method, axes="force", friction_velocity="command")
    inp, out = est.make_input(), est.make_output()
    est.reset(Q0)
    inp.q[:] = Q0
    for k in range(600):
        inp.t = k * 1e-3
        est.update(inp, out)
    last_wrench, last_tau = out.wrench.copy(), out.tau_ext.copy()
    name, value = bad.split()
    getattr(inp, name)[2] = float(value)
    inp.t += 1e-3
    assert est.update(inp, out) is Status.FAULT_NONFINITE
    getattr(inp, name)[2] = Q0[2] if name == "q" else 0.0
    for _ in range(100):
        inp.t += 1e-3
        assert est.update(inp, out) is Status.FAULT_NONFINITE
    np.testing.assert_array_equal(out.wrench, last_wrench)
    np.testing.assert_array_equal(out.tau_ext, last_tau)
    est.reset(Q0)
    for _ in range(600):
        inp.t += 1e-3
        status = est.update(inp, out)
    assert status is Status.OK and np.all(np.isfinite(out.wrench))


_BAD_SAMPLES = [("q", np.nan), ("q", np.inf), ("q", 1e155), ("current", -np.inf),
                ("current", 1.7e308), ("qd_cmd", np.nan), ("t", np.nan)]


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.sampled_from(["direct", "momentum"]), st.sampled_from(["wrench", "force"]),
       st.integers(0, 2**32 - 1), st.sampled_from(_BAD_SAMPLES), st.integers(0, 5),
       st.integers(60, 250))
def test_never_raises_never_ok_over_nan_and_latches(er20: Robot, method: str, axes: str,
                                                    seed: int, bad: tuple[str, float],
                                                    joint: int, k_bad: int) -> None:
    """Random motion (jumps, missed samples), then one bad sample: before it, no fault and
    finite outputs; from it on, FAULT_NONFINITE with the last output held; after a reset, the
    same outputs as a fresh estimator (no state left over)."""
    rng = np.random.default_rng(seed)
    n_samples = 300
    q = Q0 + np.cumsum(rng.normal(0.0, 2e-4, (n_samples, 6)), axis=0)
    q[rng.integers(n_samples):, rng.integers(6)] += rng.choice([0.05, -0.5])
    current = rng.normal(0.0, 0.3, (n_samples, 6))
    qd_cmd = np.where(rng.random((n_samples, 6)) < 0.5, 0.0, rng.normal(0, 0.3, (n_samples, 6)))
    t = np.cumsum(rng.choice([1e-3, 1e-3, 1e-3, 4e-3], n_samples))      # some samples missed
    cfg = dict(method=method, axes=axes, friction_velocity="command", warm_up_s=0.02,
               tare_s=0.02)
    est, fresh = _estimator(er20, **cfg), _estimator(er20, **cfg)

    def feed(e: ExternalForceEstimator, rows: range) -> list[tuple[Status, np.ndarray]]:
        inp, out = e.make_input(), e.make_output()
        res = []
        for k in rows:
            inp.t, inp.q[:], inp.current[:], inp.qd_cmd[:] = t[k], q[k], current[k], qd_cmd[k]
            if k == k_bad:
                field, value = bad
                if field == "t":
                    inp.t = value
                else:
                    getattr(inp, field)[joint] = value
            res.append((e.update(inp, out), np.concatenate([out.tau_ext, out.wrench])))
        return res

    est.reset(q[0])
    rows = feed(est, range(n_samples))
    before, after = rows[:k_bad], rows[k_bad:]
    assert all(s >= 0 and np.all(np.isfinite(v)) for s, v in before)
    held = before[-1][1]
    assert all(s is Status.FAULT_NONFINITE and np.array_equal(v, held) for s, v in after)
    est.reset(q[0])
    fresh.reset(q[0])
    k_bad = -1                                  # no bad sample this time
    for (s1, v1), (s2, v2) in zip(feed(est, range(n_samples)), feed(fresh, range(n_samples)),
                                  strict=True):
        assert s1 == s2 and np.array_equal(v1, v2)


def test_an_input_for_another_robot_latches_a_fault(er20: Robot) -> None:
    """The input's arrays are its record's (they cannot be resized), but an input or output
    made for another robot can be passed: FAULT_INPUT_SIZE, latched until reset."""
    from leadthrough.estimation.estimator import EstimatorInput, EstimatorOutput

    est = _estimator(er20, friction_velocity="command")
    out = est.make_output()
    for inp, o in ((EstimatorInput(5), out), (EstimatorInput(7), out),
                   (est.make_input(), EstimatorOutput(5))):
        est.reset(Q0)
        o.wrench[:] = 1.0
        assert est.update(inp, o) is Status.FAULT_INPUT_SIZE
        good = est.make_input()
        good.q[:] = Q0
        assert est.update(good, out) is Status.FAULT_INPUT_SIZE   # latched
        assert np.all(out.wrench == 0.0)
    est.reset(Q0)
    good = est.make_input()
    good.q[:] = Q0
    assert est.update(good, out) is Status.WARMING_UP


@pytest.mark.parametrize("missed", [1, 5, 25])
def test_missed_samples_are_bridged_not_differentiated_as_one_period(er20: Robot,
                                                                     missed: int) -> None:
    """A joint moving at a constant 0.1 rad/s, with ``missed`` samples that never arrive: the
    velocity estimate after the gap is that of the run that missed nothing (q is linear, so the
    interpolation is exact), where it would jump by the gap's motion over one period."""
    velocity, runs = 0.1, []
    for gap in (0, missed):
        est = _estimator(er20)
        inp, out = est.make_input(), est.make_output()
        est.reset(Q0)
        qd = np.full(1500, np.nan)
        for k in range(1500):
            if 1000 <= k < 1000 + gap:
                continue
            inp.t = k * 1e-3
            inp.q[:] = Q0
            inp.q[1] += velocity * inp.t
            est.update(inp, out)
            qd[k] = out.qd[1]
        runs.append(qd)
    after = slice(1000 + missed, None)
    assert abs(runs[0][999] - velocity) < 5e-3 * velocity      # settled before the gap
    np.testing.assert_allclose(runs[1][after], runs[0][after], rtol=1e-9)


def test_a_gap_too_long_to_bridge_restarts_at_the_gaps_mean_velocity(er20: Robot) -> None:
    """150 samples missed (beyond MAX_GAP_SAMPLES): the differentiator restarts with the
    gap's mean velocity, so the velocity estimate stays near the joint's 0.1 rad/s (a restart
    at rest would read 0, and differentiating the jump 15 rad/s)."""
    est = _estimator(er20)
    inp, out = est.make_input(), est.make_output()
    est.reset(Q0)
    qd = []
    for k in range(1500):
        if 1000 <= k < 1150:
            continue
        inp.t = k * 1e-3
        inp.q[:] = Q0
        inp.q[1] += 0.1 * inp.t
        est.update(inp, out)
        qd.append(out.qd[1])
    np.testing.assert_allclose(qd[1000:], 0.1, rtol=0.02)


def test_rezero_takes_any_window_without_raising(er20: Robot) -> None:
    est = _estimator(er20)
    inp, out = est.make_input(), est.make_output()
    est.reset(Q0)
    inp.q[:] = Q0
    for k in range(3000):                 # past the start's settling (rezero waits for it)
        inp.t = k * 1e-3
        est.update(inp, out)
    assert out.status == Status.OK
    # documented clamping (the loop calls it in the hot path, so it never raises): NaN or
    # less than one sample is a one-sample window, a huge window is capped at 2**31
    for samples, window in ((float("inf"), 2**31), (2**70, 2**31), (float("nan"), 1), (-3, 1),
                            (0, 1), (0.5, 1), (7, 7)):
        est.rezero(samples)  # type: ignore[arg-type]
        assert est.rezeroing
        assert int(view(est.record).rezero_left) == window
        inp.t += 1e-3
        est.update(inp, out)
        assert est.rezeroing == (window > 1)
    assert np.all(np.isfinite(out.wrench))


@settings(max_examples=50, deadline=None)
@given(st.floats(-0.2, 0.2), st.floats(0.0, 1.0))
def test_wrench_stays_bounded_near_the_wrist_singularity(er20: Robot, q5: float, scale: float
                                                         ) -> None:
    """q5 → 0 aligns axes 4 and 6: the damped inverse keeps the wrench bounded, by the damped
    least squares' largest gain max_i σ_i/(σ_i² + λ²) ≤ 1/(2λ) (σ_i the singular values of J),
    and it is the damped solution (J Jᵀ + λ²·1)⁻¹·J·τ itself."""
    cfg = EstimatorConfig()
    q = np.array([0.2, -0.5, 0.3, 0.4, q5, 0.1])
    J = pin.computeFrameJacobian(er20.model, er20.model.createData(), q, er20.tcp_frame_id,
                                 pin.LOCAL_WORLD_ALIGNED)
    tau = scale * np.array([50.0, 50.0, 20.0, 5.0, 5.0, 5.0])
    wrench = np.zeros(6)
    info = wrench_from_torque(J, tau, np.ones(6), False, cfg.manipulability_threshold,
                               cfg.max_damping, cfg.min_force_lever, wrench,
                               np.zeros((6, 6)), np.zeros((6, 6)))
    assert np.all(np.isfinite(wrench))
    mu, lam = info
    sigma = np.linalg.svd(J, compute_uv=False)
    gain = float(np.max(sigma / (sigma**2 + lam**2)))
    assert np.linalg.norm(wrench) <= gain * np.linalg.norm(tau) * (1 + 1e-9) + 1e-12
    if lam > 0:
        assert gain <= 1.0 / (2.0 * lam) * (1 + 1e-12)
        np.testing.assert_allclose(wrench, np.linalg.solve(J @ J.T + lam**2 * np.eye(6), J @ tau),
                                   rtol=1e-7, atol=1e-9 * max(1.0, np.linalg.norm(tau)))
    assert mu == pytest.approx(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)), rel=1e-6, abs=1e-6)
    assert lam == damping_of(mu, cfg.manipulability_threshold, cfg.max_damping)
    if mu < cfg.manipulability_threshold:
        assert lam > 0


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-10.0, 10.0), min_size=6, max_size=6),
       st.floats(0.0, 1.0))
@example([0.0, 0.0, 0.0, 0.0, 0.0, 2e-117], 0.0)    # p³ would underflow
@example([1e150, 0.0, 0.0, -1e150, 0.0, 1e150], 0.0)  # and overflow
def test_smallest_eigenvalue_3_matches_lapack(entries: list[float], shrink: float) -> None:
    """Closed form vs ``numpy.linalg.eigvalsh``, including (near) repeated and zero
    eigenvalues (``shrink`` pulls the matrix toward a multiple of the identity) and extreme
    scales, to the documented accuracy (~1e-8 of the scale; the arccos near a repeated
    eigenvalue)."""
    a = np.zeros((6, 6))
    a[np.triu_indices(3)] = entries
    a[:3, :3] = a[:3, :3] + np.triu(a[:3, :3], 1).T
    a[:3, :3] = (1 - shrink) * a[:3, :3] + shrink * entries[0] * np.eye(3)
    a[3:, 3:] = -1e3 * np.eye(3)          # outside the leading block: never read
    ref = np.linalg.eigvalsh(a[:3, :3])[0]
    scale = max(1.0, float(np.abs(a[:3, :3]).max()))
    assert smallest_eigenvalue_3(a) == pytest.approx(ref, abs=5e-8 * scale)


def test_force_fit_is_undamped_at_the_wrist_singularity(er20: Robot) -> None:
    """At q5 = 0 the full wrench is damped (μ = 0) but a pure force is still observed by the
    other joints: the force fit recovers it exactly, undamped."""
    cfg = EstimatorConfig(axes="force")
    q = np.array([0.2, -0.5, 0.3, 0.4, 0.0, 0.1])
    J = pin.computeFrameJacobian(er20.model, er20.model.createData(), q, er20.tcp_frame_id,
                                 pin.LOCAL_WORLD_ALIGNED)
    force = np.array([30.0, -40.0, 20.0])
    tau = J[:3].T @ force
    weight = 1.0 / np.array([15.0, 19.0, 3.0, 0.8, 0.8, 0.25])
    wrench = np.zeros(6)
    info = wrench_from_torque(J, tau, weight, True, cfg.manipulability_threshold,
                               cfg.max_damping, cfg.min_force_lever, wrench,
                               np.zeros((6, 6)), np.zeros((6, 6)))
    assert info[0] < 1e-9 < cfg.manipulability_threshold
    assert info[1] == 0.0
    np.testing.assert_allclose(wrench[:3], force, rtol=1e-9)
    np.testing.assert_array_equal(wrench[3:], 0.0)
    full = np.zeros(6)
    full_info = wrench_from_torque(J, tau, weight, False, cfg.manipulability_threshold,
                               cfg.max_damping, cfg.min_force_lever, full,
                               np.zeros((6, 6)), np.zeros((6, 6)))
    assert full_info[1] == pytest.approx(cfg.max_damping)


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 0.1), st.floats(0.1, 10.0), st.integers(0, 2**31 - 1))
def test_force_fit_damping_follows_the_shortest_lever(lever: float, w: float, seed: int
                                                      ) -> None:
    """A Jacobian whose translational part has the shortest lever ``lever``: with equal
    weights w the force fit is the unweighted damped least squares
    (Jᵥ Jᵥᵀ + λ²·1)⁻¹·Jᵥ·τ, λ from the lever (the weights' scale does not change it), and
    it stays finite at lever 0."""
    cfg = EstimatorConfig(axes="force")
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    v, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    J = np.zeros((6, 6))
    J[:3] = u @ np.diag([1.2, 0.7, lever]) @ v[:3]
    J[3:] = rng.normal(size=(3, 6))
    tau = rng.normal(scale=20.0, size=6)
    wrench = np.zeros(6)
    info = wrench_from_torque(J, tau, np.full(6, w), True, cfg.manipulability_threshold,
                               cfg.max_damping, cfg.min_force_lever, wrench,
                               np.zeros((6, 6)), np.zeros((6, 6)))
    lam = damping_of(lever, cfg.min_force_lever, cfg.max_damping)
    assert info[1] == pytest.approx(lam, abs=1e-7)
    Jv = J[:3]
    ref = np.linalg.solve(Jv @ Jv.T + info[1] ** 2 * np.eye(3), Jv @ tau)
    assert np.all(np.isfinite(wrench))
    np.testing.assert_allclose(wrench[:3], ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())
    if lever < cfg.min_force_lever:
        assert info[1] > 0.0


def _quiet_payload_run(robot: Robot, seconds: float, payload: Payload | None
                       ) -> tuple[Recording, DriveModelParameters]:
    """A recording of the noise-free, friction-free simulator of the nominal model (with
    ``payload``), and that model's parameters (its true rotor inertia, no friction)."""
    from leadthrough.sim.run import run_trajectory

    s = _trajectory(robot, 3, seconds=seconds, rate=1000.0, amplitude=0.04)
    sim = SimRobot(robot, _quiet_config(), q0=s.q[0], payload=payload)
    log = run_trajectory(sim, s.q, s.qd)
    rec = Recording(time=log.time, q=log.q, current=log.current, robot=robot.name)
    nominal = nominal_drive_parameters(robot)
    params = type(nominal)(phi=nominal.phi, friction_model=nominal.friction_model,
                           rotor_inertia=sim.truth.drive.armature, coulomb=np.zeros(robot.n),
                           viscous=np.zeros(robot.n))
    return rec, params


def test_payload_from_motion_with_the_nominal_model(er20: Robot) -> None:
    """Noise-free, friction-free simulator of the nominal model: mass and CoM are exact."""
    rec, params = _quiet_payload_run(er20, 20.0, Payload(8.0, (0.02, -0.01, 0.12)))
    est = estimate_payload(rec, er20, params, "motion", refit_friction=False)
    assert est.mass_kg == pytest.approx(8.0, rel=5e-3)
    assert est.com_tcp is not None
    np.testing.assert_allclose(est.com_tcp, [0.02, -0.01, 0.12], atol=5e-3)
    with pytest.raises(DataError, match="unknown method"):
        estimate_payload(rec, er20, params, "guess")
    mj = build_mujoco_model(er20)
    assert mj.nq == er20.n
    # the same links: MuJoCo's total mass is Pinocchio's
    pin_mass = sum(er20.model.inertias[i].mass for i in range(1, er20.model.njoints))
    assert float(mj.body_mass.sum()) == pytest.approx(pin_mass, rel=1e-12)


def test_no_payload_gives_no_com_and_a_negative_mass_warns(er20: Robot) -> None:
    """Without a payload the mass is ~0 and no CoM is reported (a first moment over a mass
    of zero); a model whose last link is 1 kg too heavy reads about −1 kg, with a warning."""
    from leadthrough.errors import DataWarning

    rec, params = _quiet_payload_run(er20, 10.0, None)
    est = estimate_payload(rec, er20, params, "motion", refit_friction=False)
    assert abs(est.mass_kg) < 0.02 and est.com_tcp is None
    phi = params.phi.copy()
    phi[10 * 5] += 1.0                              # m of the last link
    heavy = type(params)(phi=phi, friction_model=params.friction_model,
                         rotor_inertia=params.rotor_inertia, coulomb=np.zeros(6),
                         viscous=np.zeros(6))
    with pytest.warns(DataWarning, match="payload mass is negative"):
        est = estimate_payload(rec, er20, heavy, "motion", refit_friction=False)
    assert est.mass_kg == pytest.approx(-1.0, abs=0.05) and est.com_tcp is None


def test_payload_against_an_unloaded_run_of_the_same_trajectory(er20: Robot) -> None:
    """An unloaded model with wrong links reads the payload wrong; against an unloaded run of
    the same trajectory the model's error cancels and the mass is exact. A reference on
    another path, or with the static method, is refused."""
    from leadthrough.dynamics import FrictionModel
    from test_identification import _data, _true_params

    truth = _true_params(er20, FrictionModel.STRIBECK)
    phi_p = pin.Inertia(10.0, np.array([0.0, 0.02, 0.1]),
                        pin.Inertia.FromBox(10.0, 0.1, 0.1, 0.1).inertia).toDynamicParameters()
    loaded_phi = truth.phi.copy()
    loaded_phi[10 * (er20.n - 1):] += phi_p
    loaded = _data(er20, replace(truth, phi=loaded_phi), seed=4)
    unloaded = _data(er20, truth, seed=4)              # the same trajectory, no payload
    wrong = truth.phi.copy()
    wrong[20:30] *= 1.15                                # link 3 15 % heavy (a scaled body)
    wrong[40:50] *= 0.9                                 # link 5 10 % light
    model = replace(truth, phi=wrong)
    alone = estimate_payload(loaded, er20, model, "motion")
    assert abs(alone.mass_kg - 10.0) > 0.1              # the links' error reads as payload
    est = estimate_payload(loaded, er20, model, "motion", reference=unloaded)
    assert est.mass_kg == pytest.approx(10.0, rel=1e-6)
    assert est.com_tcp is not None and est.reference_shift_s == pytest.approx(0.0, abs=1e-9)
    # a reference that starts 3.7 s later in the program: found and aligned
    late = replace(unloaded, **{k: getattr(unloaded, k)[370:] for k in
                                ("q", "qd", "qdd", "torque", "moving")},
                   time=unloaded.time[370:] - unloaded.time[370] + 5.0)
    est = estimate_payload(loaded, er20, model, "motion", reference=late)
    assert est.reference_shift_s == pytest.approx(-3.7, abs=1e-9)
    assert est.mass_kg == pytest.approx(10.0, rel=1e-6)
    other = _data(er20, truth, seed=5)
    with pytest.raises(DataError, match="another path") as e:
        estimate_payload(loaded, er20, model, "motion", reference=other)
    assert e.value.field.startswith("q")
    with pytest.raises(DataError, match="only from motion"):
        estimate_payload(loaded, er20, model, "static", reference=unloaded)


@pytest.mark.parametrize("model", ["stribeck", "coulomb-viscous", "cbrt", "stribeck-load",
                                   "cbrt-load"])
def test_real_time_model_equals_eq21_away_from_standstill(er20: Robot, model: str) -> None:
    """The estimator's per-sample model (its identified links in Pinocchio, its compiled
    friction with the smoothed sign, rotor inertia and offset) equals the offline eq. 21 for
    |q̇| > v_ε; with a load-dependent Coulomb level, given the same τ_load (the link torque)."""
    from leadthrough.dynamics import FrictionModel, model_torque
    from leadthrough.dynamics.friction import StribeckParameters
    from leadthrough.estimation.friction_torque import smoothed_friction
    from leadthrough.estimation.identified_model import IdentifiedModel

    base = nominal_drive_parameters(er20)
    n = er20.n
    ones = np.ones(n)
    params = {
        "stribeck": replace(base, friction_model=FrictionModel.STRIBECK,
                            stribeck=StribeckParameters(30 * ones, 20 * ones, 40 * ones,
                                                        10 * ones, 0.1 * ones, 5 * ones),
                            offset=np.linspace(-2, 2, n)),
        "coulomb-viscous": replace(base, coulomb=12 * ones, viscous=3 * ones),
        "cbrt": replace(base, friction_model=FrictionModel.CBRT,
                        coulomb=12 * ones, viscous=3 * ones, cbrt=4 * ones),
    }[model.removesuffix("-load")]
    if model.endswith("-load"):
        params = replace(params, load_friction=np.linspace(0.01, 0.1, n))
    rt = IdentifiedModel(er20, params)
    rng = np.random.default_rng(3)
    out, sign, friction = np.zeros(n), np.zeros(n), np.zeros(n)
    for _ in range(50):
        q = rng.uniform(er20.lower_limits, er20.upper_limits)
        qd = rng.choice([-1.0, 1.0], n) * rng.uniform(0.03, 2.0, n)
        qdd = rng.normal(size=n)
        links = pin.rnea(rt.model, rt.data, q, qd, qdd)
        smoothed_friction(qd, np.full(n, 1 / 0.02), rt.friction[0], links, sign, friction)
        out[:] = links + friction + rt.rotor * qdd + rt.offset
        expected = model_torque(er20, params, q[None], qd[None], qdd[None])[0]
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-9)


def test_tare_removes_a_static_model_error(er20: Robot) -> None:
    """A model torque offset shows as a wrench at rest; taring removes it, a push still shows."""
    from dataclasses import replace

    force = np.array([0.0, 0.0, -50.0])
    sim = SimRobot(er20, _quiet_config(), q0=Q0,
                   operator=ConstantWrench((*force, 0, 0, 0), 1.5))
    log = hold(sim, 3.5)
    wrong = replace(nominal_drive_parameters(er20), offset=np.array([8.0, -6.0, 4.0, 1, 1, 1]))
    cfg = EstimatorConfig(tare_s=0.5)
    results = {}
    for name, c in (("no tare", EstimatorConfig()), ("tare", cfg)):
        est = ExternalForceEstimator(er20, wrong, np.zeros(6), c)
        inp, out = est.make_input(), est.make_output()
        est.reset(log.q[0])
        statuses, wrench = [], np.zeros((log.time.size, 6))
        for k in range(log.time.size):
            inp.t, inp.q[:], inp.current[:] = log.time[k], log.q[k], log.current[k]
            statuses.append(est.update(inp, out))
            wrench[k] = out.wrench
        results[name] = (np.array(statuses), wrench)
    statuses, wrench = results["tare"]
    t = log.time
    assert np.all(statuses[t < 0.49] == Status.WARMING_UP)
    assert np.all(statuses[(t > 0.51) & (t < 0.99)] == Status.TARING)
    assert np.all(statuses[t > 1.01] == Status.OK)
    rest = (t > 1.2) & (t < 1.5)
    assert np.linalg.norm(results["no tare"][1][rest, :3], axis=1).min() > 5.0
    assert np.linalg.norm(wrench[rest, :3], axis=1).max() < 0.5
    np.testing.assert_allclose(wrench[-1, :3], force, atol=1.0)
    with pytest.raises(DataError, match="duration_s"):
        ExternalForceEstimator(er20, wrong, np.zeros(6)).tare(0.0)


def test_friction_can_follow_the_commanded_velocity(er20: Robot) -> None:
    """friction_velocity="command": the friction term uses the servo's velocity command."""
    from dataclasses import replace

    n = er20.n
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                     viscous=np.full(n, 4.0))
    qd_cmd = np.array([0.5, -0.5, 0.5, -0.5, 0.5, -0.5])
    tau = {}
    for mode in ("measured", "command"):
        est = ExternalForceEstimator(er20, params, np.zeros(n),
                                     EstimatorConfig(friction_velocity=mode, warm_up_s=0.0))
        inp, out = est.make_input(), est.make_output()
        est.reset(Q0)
        for k in range(3000):  # the robot stands still at Q0; the command says it moves
            inp.t, inp.q[:], inp.qd_cmd[:] = k * 1e-3, Q0, qd_cmd
            inp.current[:] = 0.0
            est.update(inp, out)
        tau[mode] = out.tau_ext.copy()
    np.testing.assert_allclose(tau["command"] - tau["measured"],
                               np.sign(qd_cmd) * 10.0 + 4.0 * qd_cmd, atol=1e-6)


def test_commanded_friction_keeps_its_value_after_a_stop(er20: Robot) -> None:
    """friction_velocity="command": the Coulomb part turns over a few z₀ of commanded motion and
    keeps its last value once the command stops (Dahl/LuGre memory), unlike sgn(0) = 0."""
    from dataclasses import replace

    n = er20.n
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                     viscous=np.zeros(n))
    z0 = 2e-4
    v = 0.01  # rad/s: 1e-5 rad per 1 ms step, so z₀ takes 20 steps
    taus = {}
    for speed in (0.0, v):
        est = ExternalForceEstimator(er20, params, np.zeros(n), EstimatorConfig(
            friction_velocity="command", warm_up_s=0.0, presliding_length=z0,
            output_cutoff_hz=400.0))
        inp, out = est.make_input(), est.make_output()
        est.reset(Q0)
        rows = []
        for k in range(400):  # the robot stands still at Q0; the command moves, then stops
            inp.t, inp.q[:], inp.current[:] = k * 1e-3, Q0, 0.0
            inp.qd_cmd[:] = speed if k < 200 else 0.0
            est.update(inp, out)
            rows.append(out.tau_ext.copy())
        taus[speed] = np.array(rows)
    friction = taus[v] - taus[0.0]  # τ̂_d differs by the friction term only
    # after 20 steps (0.2 mrad = z₀) the friction is at 1 − e⁻¹ of its level (the 400 Hz
    # output filter lags it by ~0.4 ms), after 200 steps (10·z₀) at the level, and it stays there
    # after the command stops
    np.testing.assert_allclose(friction[20], 10.0 * (1.0 - np.exp(-1.0)), rtol=0.05)
    np.testing.assert_allclose(friction[199], 10.0, rtol=1e-3)
    np.testing.assert_allclose(friction[399], 10.0, rtol=1e-3)


def test_rezero_zeroes_a_constant_error_and_cancel_keeps_the_tare(er20: Robot) -> None:
    """A zero-velocity update averages τ_ext and subtracts it, the status staying OK."""
    from dataclasses import replace

    n = er20.n
    wrong = replace(nominal_drive_parameters(er20), offset=np.array([8.0, -6.0, 4.0, 1, 1, 1]))
    est = ExternalForceEstimator(er20, wrong, np.zeros(n), EstimatorConfig(warm_up_s=0.0))
    gravity = est.model  # current that exactly holds the identified model with no offset
    inp, out = est.make_input(), est.make_output()
    est.reset(Q0)
    tau_hold = pin.rnea(gravity.model, gravity.data, Q0, np.zeros(n), np.zeros(n))
    current = er20.torque_to_current(tau_hold)

    def run(samples: int) -> None:
        for _ in range(samples):
            inp.q[:], inp.current[:] = Q0, current
            assert est.update(inp, out) == Status.OK

    run(2000)
    np.testing.assert_allclose(out.tau_ext, wrong.offset, atol=1e-6)
    est.rezero(100)
    run(50)
    assert est.rezeroing
    est.cancel_rezero()
    run(100)
    assert not est.rezeroing
    np.testing.assert_allclose(out.tau_ext, wrong.offset, atol=1e-6)   # unchanged
    est.rezero(100)
    run(100)
    assert not est.rezeroing
    run(1)  # the sample that completes the window still reports the old tare
    np.testing.assert_allclose(out.tau_ext, 0.0, atol=1e-6)


def test_friction_weights_count_a_turning_joint_less_and_recover() -> None:
    """friction_weights: 1/σ in steady sliding; half way through a turnover (F = 0) the
    gap g lowers the weight to 1/√(σ² + (κg)²); the envelope then decays by ``decay`` per step."""

    sigma = np.array([10.0, 1.0])
    level = np.array([50.0, 5.0])
    envelope, weight = np.zeros(2), np.zeros(2)
    friction_weights(level, level.copy(), level.copy(), 0.9, 2.0, sigma, envelope, weight)
    np.testing.assert_allclose(weight, 1.0 / sigma)
    state = np.array([50.0, 0.0])  # joint 2 turning over after a reversal
    friction_weights(level, state, state.copy(), 0.9, 2.0, sigma, envelope, weight)
    np.testing.assert_allclose(weight, [0.1, 1.0 / np.sqrt(1.0 + (2.0 * 5.0) ** 2)])
    for _ in range(10):  # turned over: the envelope holds the peak, decaying
        friction_weights(level, -level, -level, 0.9, 2.0, sigma, envelope, weight)
    np.testing.assert_allclose(envelope, [0.0, 5.0 * 0.9**10])
    np.testing.assert_allclose(weight[1], 1.0 / np.sqrt(1.0 + (2.0 * 5.0 * 0.9**10) ** 2))


@settings(max_examples=30, deadline=None)
@given(stuck=st.floats(0.0, 1.0))
def test_friction_weights_doubt_a_joint_the_command_turned_and_the_encoder_did_not(
        stuck: float) -> None:
    """Steady sliding on the command's side (|F| = g) while the encoder's state is still
    ``stuck``·g on the old side: the gap F − F_enc = (1 + stuck)·g sets the weight; agreeing
    states give 1/σ."""
    sigma, level = np.array([1.0]), np.array([10.0])
    envelope, weight = np.zeros(1), np.zeros(1)
    turned, encoder = -level, stuck * level
    friction_weights(level, turned, encoder, 0.9, 2.0, sigma, envelope, weight)
    gap = (1.0 + stuck) * 10.0
    np.testing.assert_allclose(envelope, [gap])
    np.testing.assert_allclose(weight, [1.0 / np.sqrt(1.0 + (2.0 * gap) ** 2)])
    friction_weights(level, turned, turned.copy(), 0.0, 2.0, sigma, np.zeros(1), weight)
    np.testing.assert_allclose(weight, 1.0 / sigma)


def test_friction_weighting_needs_the_force_fit_and_commanded_friction() -> None:
    with pytest.raises(DataError, match="friction_weighting"):
        EstimatorConfig(friction_weighting=1.0)  # wrench axes, measured friction
    with pytest.raises(DataError, match="friction_weighting"):
        EstimatorConfig(axes="force", friction_velocity="command", friction_weighting=-1.0)
    EstimatorConfig(axes="force", friction_velocity="command", friction_weighting=1.0)


@pytest.mark.parametrize("bad", [-0.01, float("inf"), float("nan")])
def test_min_force_lever_must_be_finite_and_not_negative(bad: float) -> None:
    with pytest.raises(DataError, match="min_force_lever") as err:
        EstimatorConfig(axes="force", min_force_lever=bad)
    assert "finite value >= 0 m" in str(err.value)
    assert EstimatorConfig(axes="force", min_force_lever=0.0).min_force_lever == 0.0


def test_a_joint_the_command_moves_and_the_encoder_does_not_counts_less(er20: Robot) -> None:
    """Joint 3 commanded to move at 0.01 rad/s: while its encoder stands still (a joint stuck
    before breakaway) the command's friction has turned to g and the encoder's has not, and
    the force fit weighs the joint by that gap (without it, by 1/σ: the command's friction is
    at its level); once the encoder follows the command the weight returns to 1/σ (after the
    envelope's decay). The other joints stand still: weighed by the gap to their static
    level, as before, whatever joint 3 does."""
    n = er20.n
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 10.0),
                     viscous=np.zeros(n), presliding=np.full(n, 2e-4))
    sigma = np.linspace(1.0, 3.0, n)
    cfg = EstimatorConfig(axes="force", friction_velocity="command", friction_weighting=1.0,
                          warm_up_s=0.0, presliding_play_counts=0.0)
    est = ExternalForceEstimator(er20, params, np.zeros(n), cfg, noise_std=sigma)
    inp, out = est.make_input(), est.make_output()
    q = guide_start_pose(er20).copy()
    est.reset(q)
    inp.qd_cmd[:] = 0.0
    inp.qd_cmd[2] = 0.01

    def run(steps: int, follow: bool) -> np.ndarray:
        for _ in range(steps):
            if follow:
                q[2] += 0.01 * 1e-3
            inp.t, inp.q[:], inp.current[:] = inp.t + 1e-3, q, 0.0
            est.update(inp, out)
        return est.record["joint_weight"][0].copy()

    stuck = run(300, follow=False)
    at_rest = 1.0 / np.hypot(sigma, 10.0)   # the gap to the static level g = 10 N·m
    # from rest (both states 0) the command turned its friction to g, the encoder not
    np.testing.assert_allclose(stuck, at_rest, rtol=1e-3)
    moving = run(2000, follow=True)
    assert moving[2] == pytest.approx(1.0 / sigma[2], rel=1e-3)
    np.testing.assert_allclose(np.delete(moving, 2), np.delete(at_rest, 2), rtol=1e-3)
