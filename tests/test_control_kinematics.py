"""Differential IK (DLS, joint limits) and the automatic friction of eq. 36, on the er20."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from leadthrough.control import (
    AutoFriction,
    AutoFrictionConfig,
    DifferentialIK,
    IKConfig,
    ik_step,
    se3,
)
from leadthrough.control.ik import ik_dtype
from leadthrough.damped_least_squares import (
    cholesky_factor,
    cholesky_solve,
    damping_of,
    gram_manipulability,
)
from leadthrough.errors import ControlError
from leadthrough.robot import Robot
from leadthrough.state_records import new_record, view

DT = 0.01


def _ik_record(jacobian: np.ndarray, error: np.ndarray, lower: np.ndarray, upper: np.ndarray,
               vmax: np.ndarray, dv: np.ndarray, half_inv_a: np.ndarray) -> np.void:
    """An IK record (no damping) for a given Jacobian, log6 error and joint bounds."""
    rec = new_record(ik_dtype(jacobian.shape[1]))
    r = view(rec)
    r.jacobian, r.gram, r.error, r.dt = jacobian, jacobian @ jacobian.T, error, DT
    r.lower, r.upper, r.max_velocity, r.velocity_step = lower, upper, vmax, dv
    r.half_inverse_acceleration = half_inv_a
    return rec[0]


Q_WORK = np.array([0.3, -0.6, 0.9, 0.4, 0.8, 0.2])
Q_WRIST_SINGULAR = np.array([0.0, -0.6, 0.9, 0.0, 0.0, 0.0])


def _fk(robot: Robot, q: np.ndarray) -> pin.SE3:
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    return d.oMf[robot.tcp_frame_id].copy()


def _random_poses(robot: Robot, k: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = robot.lower_limits + 0.2, robot.upper_limits - 0.2
    return rng.uniform(lo, hi, size=(k, robot.n))


@pytest.mark.parametrize("frame", ["tool", "base"])
def test_jacobian_matches_finite_differences(er20: Robot, frame: str) -> None:
    """The Jacobian used by the IK (tool) and by eq. 36 (base axes at the TCP) vs central
    differences of the forward kinematics."""
    ik = DifferentialIK(er20, dt=DT)
    J = np.zeros((6, er20.n))
    h = 1e-6
    for q in _random_poses(er20, 5, seed=3):
        ik.compute_kinematics(q)
        ik.jacobian_in_frame(frame, J)
        T0 = _fk(er20, q)
        fd = np.zeros_like(J)
        for j in range(er20.n):
            e = np.zeros(er20.n)
            e[j] = h
            Tp, Tm = _fk(er20, q + e), _fk(er20, q - e)
            if frame == "tool":
                fd[:, j] = (pin.log6(T0.actInv(Tp)).vector
                            - pin.log6(T0.actInv(Tm)).vector) / (2 * h)
            else:
                fd[:3, j] = (Tp.translation - Tm.translation) / (2 * h)
                fd[3:, j] = (pin.log3(Tp.rotation @ T0.rotation.T)
                             - pin.log3(Tm.rotation @ T0.rotation.T)) / (2 * h)
        np.testing.assert_allclose(J, fd, atol=1e-8)


def test_tcp_pose_and_its_views_follow_each_kinematics_update(er20: Robot) -> None:
    """``transform_tool_to_base`` is Pinocchio's frame placement, updated in place, and the
    rotation / translation views follow it."""
    ik = DifferentialIK(er20, dt=DT)
    data = er20.model.createData()
    T, R, p = ik.transform_tool_to_base, ik.rotation_tool_to_base, ik.translation_tool_to_base
    for q in (Q_WORK, Q_WRIST_SINGULAR):
        ik.compute_kinematics(q)
        pin.framesForwardKinematics(er20.model, data, q)
        ref = data.oMf[er20.tcp_frame_id]
        assert ik.transform_tool_to_base is T
        np.testing.assert_array_equal(R, ref.rotation)
        np.testing.assert_array_equal(p, ref.translation)
        np.testing.assert_array_equal(T.homogeneous, ref.homogeneous)


def test_manipulability_and_damping(er20: Robot) -> None:
    ik = DifferentialIK(er20, dt=DT)
    ik.compute_kinematics(Q_WORK)
    J = ik.jacobian
    assert ik.manipulability == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)), rel=1e-10)
    assert ik.manipulability > 0.02 and ik.damping == 0.0
    ik.compute_kinematics(Q_WRIST_SINGULAR)
    assert ik.manipulability < 1e-6
    assert ik.damping == pytest.approx(0.05, rel=1e-6)
    assert damping_of(0.01, 0.02, 0.05) == pytest.approx(0.05 * np.sqrt(0.75))
    assert damping_of(0.03, 0.02, 0.05) == 0.0


def test_ik_step_reaches_a_nearby_target(er20: Robot) -> None:
    """One undamped step toward a target 2–3 mm / mrad away (0.2 m/s, 0.2 rad/s for 10 ms) is
    q̇ = J⁻¹·ν and leaves a second-order residual (halving the step quarters it); a few steps
    converge to machine precision."""
    ik = DifferentialIK(er20, dt=DT)
    res = ik.make_result()
    nu = np.array([0.2, -0.1, 0.05, 0.1, 0.15, -0.05])
    tested = 0
    for q in _random_poses(er20, 20, seed=4):
        ik.compute_kinematics(q)
        if ik.manipulability < 0.05:                 # well-conditioned poses only
            continue
        tested += 1
        after = []
        for scale in (1.0, 0.5):
            target = _fk(er20, q) * pin.exp6(scale * nu * DT)
            # q̇ = J⁻¹·ν, given as the previous q̇ so that no acceleration bound applies
            expected = np.linalg.solve(ik.jacobian,
                                       pin.log6(_fk(er20, q).actInv(target)).vector / DT)
            ik.solve(q, expected, target, res)
            assert res.residual == pytest.approx(np.linalg.norm(scale * nu * DT), rel=1e-9)
            assert not res.limited
            np.testing.assert_allclose(res.qd, expected, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(res.q, q + res.qd * DT, rtol=0, atol=1e-15)
            after.append(np.linalg.norm(pin.log6(_fk(er20, res.q).actInv(target)).vector))
        assert after[0] < 0.1 * np.linalg.norm(nu * DT)
        assert 3.0 < after[0] / after[1] < 5.0       # second order
        qk = res.q.copy()
        for _ in range(4):                           # static target: Newton iterations
            ik.compute_kinematics(qk)
            ik.solve(qk, np.zeros(er20.n), target, res)
            qk = res.q.copy()
        assert np.linalg.norm(pin.log6(_fk(er20, qk).actInv(target)).vector) < 1e-12
    assert tested >= 5


def test_ik_stops_on_the_joint_limit_margin_braking_at_the_joint_limit(er20: Robot) -> None:
    """A target out of reach pulls joint 3 onto its lower limit: the joint stops on the margin,
    never beyond, at no more than its acceleration limit; all joints scale together."""
    cfg = IKConfig(joint_limit_margin=0.01)
    ik = DifferentialIK(er20, cfg, dt=DT)
    res = ik.make_result()
    q = np.array([0.0, -0.6, 0.9, 0.0, 0.8, 0.0])
    qd = np.zeros(er20.n)
    start = _fk(er20, q)
    lo = er20.lower_limits[2] + 0.01
    traj, vel, scales = [], [], []
    for k in range(600):
        # a target moving along +x at 0.3 m/s, far beyond the reach of the arm
        target = pin.SE3(start.rotation, start.translation + np.array([0.3 * DT * (k + 1), 0, 0]))
        ik.compute_kinematics(q)
        ik.solve(q, qd, target, res)
        q, qd = res.q.copy(), res.qd.copy()
        traj.append(q)
        vel.append(qd)
        scales.append(res.scale)
    traj, vel = np.array(traj), np.array(vel)
    assert np.all(traj[:, 2] >= lo - 1e-12)
    assert np.all(traj >= ik.lower - 1e-12) and np.all(traj <= ik.upper + 1e-12)
    assert traj[-1, 2] == pytest.approx(lo, abs=1e-6)            # it did reach the margin
    assert np.all(np.abs(vel) <= er20.velocity_limit * (1 + 1e-12))
    acc = np.abs(np.diff(vel[:, 2])) / DT
    assert acc.max() <= er20.acceleration_limit[2] * (1 + 1e-9)
    assert min(scales) < 1.0


def test_ik_scaling_keeps_the_direction(er20: Robot) -> None:
    """With a joint speed bound active, q̇ is the DLS solution scaled by one factor."""
    free = DifferentialIK(er20, dt=DT)
    b = free.make_result()
    target = _fk(er20, Q_WORK) * pin.exp6(np.array([0.2, 0.1, 0.0, 0.0, 0.0, 0.1]) * DT)
    free.compute_kinematics(Q_WORK)
    free.solve(Q_WORK, np.zeros(er20.n), target, b)        # from rest: acceleration-bounded
    assert b.limited
    qd_dls = b.qd_dls.copy()
    free.solve(Q_WORK, qd_dls, target, b)                   # already moving: unbounded
    assert not b.limited
    np.testing.assert_allclose(b.qd, qd_dls, rtol=1e-12)
    # speed limits 3 % under the fastest joint's speed: bound by speed, not by acceleration
    fraction = 0.97 * float(np.max(np.abs(qd_dls) / er20.velocity_limit))
    slow = DifferentialIK(er20, IKConfig(velocity_scale=fraction), dt=DT)
    a = slow.make_result()
    slow.compute_kinematics(Q_WORK)
    slow.solve(Q_WORK, qd_dls, target, a)
    assert a.limited and a.scale == pytest.approx(0.97, rel=1e-9)
    np.testing.assert_allclose(a.qd, a.scale * b.qd, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(a.qd) <= fraction * er20.velocity_limit * (1 + 1e-12))


def test_ik_braking_at_a_position_limit_slows_no_other_joint_beyond_its_acceleration() -> None:
    """Joint 0 brakes before its position limit; the common factor would slow the fast joint 1
    by more than a·dt, so joint 1 slows at its acceleration limit instead (DLS on J = 1)."""
    n, a = 6, 6.0
    dv, dt = np.full(n, a * DT), DT
    lower, upper = np.full(n, -3.0), np.full(n, 3.0)
    q = np.zeros(n)
    q[0] = upper[0] - 0.05
    bound = ik_step._braking_speed(0.05, dv[0], dt)
    qd_prev = np.zeros(n)
    qd_prev[0], qd_prev[1] = bound + 0.5 * dv[0], 2.0           # both keep their speed
    qd_dls, qd, q_next = np.zeros(n), np.zeros(n), np.zeros(n)
    ik = _ik_record(np.eye(n), qd_prev * dt, lower, upper, np.full(n, 10.0), dv,
                    np.full(n, 0.5 / a))
    scale = ik_step.dls_step(ik, q, qd_prev, qd_dls, qd, q_next)
    np.testing.assert_allclose(qd_dls, qd_prev, rtol=1e-12)
    assert scale == pytest.approx(bound / qd_prev[0], rel=1e-12)
    assert qd[0] == pytest.approx(bound, rel=1e-12)              # the bound holds
    assert 2.0 * (1 - scale) > dv[1]                             # the common factor would not
    assert qd[1] == pytest.approx(2.0 - dv[1], rel=1e-12)        # slows at its limit
    np.testing.assert_allclose(q_next, q + qd * dt, rtol=0, atol=1e-15)


def test_ik_is_finite_at_a_singularity(er20: Robot) -> None:
    ik = DifferentialIK(er20, dt=DT)
    res = ik.make_result()
    target = _fk(er20, Q_WRIST_SINGULAR) * pin.exp6(np.array([0, 0, 0, 0.2, 0, 0]) * DT)
    ik.compute_kinematics(Q_WRIST_SINGULAR)
    ik.solve(Q_WRIST_SINGULAR, np.zeros(er20.n), target, res)
    assert np.isfinite(res.qd).all()
    assert np.all(np.abs(res.qd) <= er20.velocity_limit * (1 + 1e-12))


def test_ik_stop_cycles_leave_part_of_the_joint_acceleration(er20: Robot) -> None:
    """A planned stop gives each joint |q̇_j|/(f·a_j·dt) cycles; the slowest joint sets it."""
    qd = np.zeros(er20.n)
    assert DifferentialIK(er20, dt=DT).stop_cycles(qd) == 0.0
    qd[0], qd[3] = -1.2, 0.9
    expected = max(1.2 / er20.acceleration_limit[0], 0.9 / er20.acceleration_limit[3]) / DT
    assert DifferentialIK(er20, IKConfig(stop_acceleration_fraction=1.0), dt=DT).stop_cycles(
        qd) == pytest.approx(expected, rel=1e-12)
    assert DifferentialIK(er20, dt=DT).stop_cycles(qd) == pytest.approx(2 * expected, rel=1e-12)


def test_ik_config_errors(er20: Robot) -> None:
    with pytest.raises(ControlError, match=r"ik.velocity_scale"):
        IKConfig(velocity_scale=0.0)
    with pytest.raises(ControlError, match=r"ik.stop_acceleration_fraction"):
        IKConfig(stop_acceleration_fraction=1.5)
    with pytest.raises(ControlError, match="dt"):
        DifferentialIK(er20, dt=-1.0)


# --------------------------------------------------------------------- eq. 36


def _jacobian(er20: Robot, q: np.ndarray, frame: str) -> tuple[np.ndarray, float]:
    ik = DifferentialIK(er20, dt=DT)
    ik.compute_kinematics(q)
    J = np.zeros((6, er20.n))
    ik.jacobian_in_frame(frame, J)
    return J, ik.manipulability


def test_compiled_base_frame_step_matches_pinocchio_exp3() -> None:
    """The controller's compiled base-axes integration (Rodrigues) vs pin.exp3, including
    rotations far below and far above the small-angle branch."""
    rng = np.random.default_rng(5)
    R_out, p_out = np.zeros((3, 3)), np.zeros(3)
    for scale in (1e-12, 1e-9, 1e-6, 1e-2, 1.0, 3.0, 30.0):
        for _ in range(20):
            twist = rng.normal(size=6) * scale
            R = pin.exp3(rng.normal(size=3))
            p = rng.normal(size=3)
            se3.integrate_base(R, p, twist, DT, R_out, p_out)
            np.testing.assert_allclose(R_out, pin.exp3(twist[3:] * DT) @ R, atol=1e-14)
            np.testing.assert_allclose(p_out, p + twist[:3] * DT, atol=1e-15)


def test_compiled_tool_frame_step_matches_pinocchio_exp6() -> None:
    """T·exp6(ν·dt) compiled vs Pinocchio, on both sides of the series branch (0.1 rad)."""
    rng = np.random.default_rng(6)
    R_out, p_out = np.zeros((3, 3)), np.zeros(3)
    for scale in (0.0, 1e-12, 1e-6, 1e-2, 1.0, 9.9, 10.1, 100.0, 300.0):
        for _ in range(20):
            T = pin.SE3.Random()
            twist = rng.normal(size=6) * scale
            se3.integrate_tool(T.rotation, T.translation, twist, DT, R_out, p_out)
            ref = T * pin.exp6(pin.Motion(twist * DT))
            np.testing.assert_allclose(R_out, ref.rotation, atol=1e-14)
            np.testing.assert_allclose(p_out, ref.translation, atol=1e-13)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-7, 1e-3, 0.0999, 0.1001, 1.0, 3.0,
                                   np.pi - 1e-3, np.pi - 1e-6])
def test_compiled_log6_matches_pinocchio(angle: float) -> None:
    """log6(T_a⁻¹·T_b) compiled vs pin.log6 (and its norm), from the identity to a half
    turn: 1e-12 up to 3 rad; closer to π the problem itself is ill-conditioned (the axis of
    a half turn is only determined up to its sign), and both agree to 1e-9."""
    rng = np.random.default_rng(7)
    out = np.zeros(6)
    tol = 1e-12 if angle <= 3.0 else 1e-9
    for _ in range(50):
        Ta = pin.SE3.Random()
        axis = rng.normal(size=3)
        xi = np.concatenate([rng.normal(size=3), axis / np.linalg.norm(axis) * angle])
        Tb = Ta * pin.exp6(pin.Motion(xi))
        norm = se3.log6_between(Ta.rotation, Ta.translation, Tb.rotation,
                                        Tb.translation, out)
        ref = pin.log6(Ta.actInv(Tb)).vector
        np.testing.assert_allclose(out, ref, atol=tol)
        assert norm == pytest.approx(np.linalg.norm(ref), abs=tol)


def test_compiled_manipulability_matches_numpy(er20: Robot) -> None:
    """μ = √det(J Jᵀ) of the compiled kernel vs NumPy, at random and singular poses."""
    ik = DifferentialIK(er20, dt=DT)
    gram, factor = np.zeros((6, 6)), np.zeros((6, 6))
    for q in [*_random_poses(er20, 10, seed=8), Q_WRIST_SINGULAR]:
        ik.compute_kinematics(q)
        J = ik.jacobian
        mu = gram_manipulability(J, gram, factor)
        np.testing.assert_allclose(gram, J @ J.T, rtol=1e-12, atol=1e-14)
        assert mu == pytest.approx(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)), rel=1e-9,
                                   abs=1e-12)


def test_compiled_cholesky_solves_like_numpy() -> None:
    """The allocation-free solve of the kernels vs numpy.linalg.solve, shifted and not; a
    singular matrix is reported, not solved."""
    rng = np.random.default_rng(4)
    factor = np.zeros((6, 6))
    for m, shift in [(6, 0.0), (6, 1e-3), (3, 0.0), (3, 0.5)]:
        B = rng.normal(size=(m, m + 2))
        A = np.zeros((6, 6))
        A[:m, :m] = B @ B.T
        b = rng.normal(size=6)
        x = b.copy()
        assert cholesky_factor(A, m, shift, factor)
        cholesky_solve(factor, m, x)
        np.testing.assert_allclose(x[:m], np.linalg.solve(A[:m, :m] + shift * np.eye(m),
                                                          b[:m]), rtol=1e-10)
        np.testing.assert_array_equal(x[m:], b[m:])  # beyond the block: untouched
    singular = np.ones((6, 6))  # rank 1
    assert not cholesky_factor(singular, 6, 0.0, factor)
    assert cholesky_factor(singular, 6, 1e-6, factor)


@pytest.mark.parametrize("frame", ["base", "tool"])
def test_eq36_is_r_times_inverse_transpose_of_the_mean_noise(er20: Robot, frame: str) -> None:
    tau_mean = np.array([-4.2, -0.05, 1.25, 0.34, 0.52, -0.37])   # Table II, ols-cv
    auto = AutoFriction(tau_mean, config=AutoFrictionConfig(guiding_ratio=1.5,
                                                            stopping_ratio=4.0))
    J, mu = _jacobian(er20, Q_WORK, frame)
    delta, delta_s = np.zeros(6), np.zeros(6)
    auto.update(J, mu, delta, delta_s)
    expected = np.abs(np.linalg.solve(J.T, tau_mean))
    np.testing.assert_allclose(delta, 1.5 * expected, rtol=1e-9)
    np.testing.assert_allclose(delta_s, 4.0 * expected, rtol=1e-9)
    # the wrench it stands for maps back onto τ̄ through Jᵀ (virtual work)
    np.testing.assert_allclose(J.T @ np.linalg.solve(J.T, tau_mean), tau_mean, atol=1e-9)


def test_eq36_threshold_follows_the_pose(er20: Robot) -> None:
    tau_mean = np.array([-4.2, -0.05, 1.25, 0.34, 0.52, -0.37])
    auto = AutoFriction(tau_mean)
    out = []
    for q in (Q_WORK, np.array([0.3, -1.0, 1.5, 0.4, 1.2, 0.2])):
        J, mu = _jacobian(er20, q, "base")
        d, ds = np.zeros(6), np.zeros(6)
        auto.update(J, mu, d, ds)
        out.append(d)
    assert np.max(np.abs(out[0] - out[1]) / np.maximum(out[0], out[1])) > 0.1


def test_eq36_std_basis_is_the_std_of_the_mapped_noise(er20: Robot) -> None:
    """basis="std": √(Σ_j A_ij²σ_j²) equals the standard deviation of J^(−T)·ε for
    independent joint noise ε_j ~ N(0, σ_j²) (Monte Carlo, 40 000 samples)."""
    sigma = np.array([15.0, 19.0, 3.2, 0.9, 1.0, 0.43])            # ≈ 0.85 % of max torque
    auto = AutoFriction(np.zeros(6), sigma, AutoFrictionConfig(basis="std"))
    J, mu = _jacobian(er20, Q_WORK, "base")
    w = np.zeros(6)
    auto.noise_wrench(J, mu, w)
    eps = np.random.default_rng(5).normal(0.0, sigma, size=(40000, 6))
    samples = np.linalg.solve(J.T, eps.T).T
    np.testing.assert_allclose(w, samples.std(axis=0), rtol=0.02)
    both = AutoFriction(np.full(6, 1.0), sigma, AutoFrictionConfig(basis="mean+std"))
    w2 = np.zeros(6)
    both.noise_wrench(J, mu, w2)
    np.testing.assert_allclose(w2, w + np.abs(np.linalg.solve(J.T, np.full(6, 1.0))),
                               rtol=1e-9)


def test_eq36_floor_and_singularity(er20: Robot) -> None:
    auto = AutoFriction(np.zeros(6), config=AutoFrictionConfig(
        min_friction=(15.0,) * 6, min_stopping_friction=(50.0,) * 6))
    J, mu = _jacobian(er20, Q_WORK, "base")
    d, ds = np.zeros(6), np.zeros(6)
    auto.update(J, mu, d, ds)
    assert np.all(d == 15.0) and np.all(ds == 50.0)
    # near a singularity the damped pseudo-inverse keeps the threshold finite
    auto = AutoFriction(np.full(6, 1.0))
    J, mu = _jacobian(er20, Q_WRIST_SINGULAR, "base")
    auto.update(J, mu, d, ds)
    assert np.isfinite(d).all() and np.isfinite(ds).all()
    # bounded by the damped least squares' largest gain: |(J Jᵀ + λ²)⁻¹ J τ̄| ≤ |τ̄| / (2λ)
    cfg = auto.config
    lam = damping_of(mu, cfg.manipulability_threshold, cfg.max_damping)
    assert lam > 0.5 * cfg.max_damping                  # the pose is near singular indeed
    gain_bound = np.linalg.norm(np.full(6, 1.0)) / (2.0 * lam)
    assert np.all(d <= np.maximum(np.asarray(cfg.min_friction),
                                  cfg.guiding_ratio * gain_bound) + 1e-9)
    # and it is that damped solution itself
    damped = np.abs(np.linalg.solve(J @ J.T + lam**2 * np.eye(6), J @ np.full(6, 1.0)))
    np.testing.assert_allclose(d, np.maximum(cfg.guiding_ratio * damped,
                                             np.asarray(cfg.min_friction)), rtol=1e-9)


def test_eq36_config_errors() -> None:
    with pytest.raises(ControlError, match=r"auto_friction.guiding_ratio"):
        AutoFrictionConfig(guiding_ratio=0.5)
    with pytest.raises(ControlError, match=r"auto_friction.stopping_ratio"):
        AutoFrictionConfig(stopping_ratio=2.0)
    with pytest.raises(ControlError, match="noise_std"):
        AutoFriction(np.zeros(6), config=AutoFrictionConfig(basis="std"))
    with pytest.raises(ControlError, match="noise_mean"):
        AutoFriction(np.array([np.nan, 0.0]))


def test_ik_step_on_a_singular_system_brakes_instead_of_failing() -> None:
    """λ = 0 exactly at a singularity (manipulability threshold 0): J Jᵀ is singular, and the
    step brakes every joint at its acceleration limit instead of raising in the loop."""
    n = 6
    J = np.zeros((6, n))
    J[0, 0] = 1.0  # rank 1
    dv = np.full(n, 0.05)
    qd_prev = np.array([0.2, -0.2, 0.03, 0.0, -0.01, 0.1])
    qd_dls, qd, q_next = np.zeros(n), np.zeros(n), np.zeros(n)
    q = np.zeros(n)
    ik = _ik_record(J, np.ones(6), np.full(n, -3.0), np.full(n, 3.0), np.full(n, 10.0), dv,
                    np.full(n, 0.1))
    scale = ik_step.dls_step(ik, q, qd_prev, qd_dls, qd, q_next)
    assert scale == 0.0
    np.testing.assert_allclose(qd, [0.15, -0.15, 0.0, 0.0, 0.0, 0.05])
    np.testing.assert_allclose(q_next, qd * DT)
