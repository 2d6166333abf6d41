"""Fourier excitation: rest-to-rest by construction, derivatives, optimised design."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from leadthrough.excitation.design import ExcitationConfig, design_excitation
from leadthrough.excitation.fourier import FourierTrajectory
from leadthrough.robot import Robot

coef = arrays(np.float64, (3, 4), elements=st.floats(-2.0, 2.0))


@settings(max_examples=100, deadline=None)
@given(coef, coef, st.floats(0.05, 1.0))
def test_starts_and_ends_at_rest(a: np.ndarray, b: np.ndarray, f0: float) -> None:
    traj = FourierTrajectory(f0, np.zeros(3), a, b)
    s = traj.sample(np.array([0.0, traj.period, 3 * traj.period]))
    scale = 1.0 + np.abs(a).sum() + np.abs(b).sum() * 2 * np.pi * f0 * 5
    np.testing.assert_allclose(s.qd, 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(s.qdd, 0.0, atol=1e-10 * scale)
    np.testing.assert_allclose(s.q[0], s.q[1], atol=1e-12 * scale)


def test_derivatives_match_finite_differences() -> None:
    rng = np.random.default_rng(0)
    traj = FourierTrajectory(0.1, rng.normal(size=6), rng.normal(size=(6, 4)),
                             rng.normal(size=(6, 4)))
    t = np.linspace(0.0, 10.0, 20001)
    s = traj.sample(t)
    np.testing.assert_allclose(np.gradient(s.q, t, axis=0)[2:-2], s.qd[2:-2], atol=1e-5)
    np.testing.assert_allclose(np.gradient(s.qd, t, axis=0)[2:-2], s.qdd[2:-2], atol=1e-4)


def test_design_is_well_conditioned_and_feasible(er20: Robot) -> None:
    cfg = ExcitationConfig(starts=1, max_iterations=60, seed=0)
    res = design_excitation(er20, cfg)
    assert res.condition_number < 150.0  # the goal for er20
    dense = res.trajectory.sample(np.linspace(0.0, res.trajectory.period, 4000))
    assert np.all(np.abs(dense.qd) <= cfg.velocity_fraction * er20.velocity_limit + 1e-6)
    assert np.all(np.abs(dense.qdd) <= cfg.acceleration_fraction * er20.acceleration_limit
                  + 1e-5)
    assert np.all(dense.q >= er20.lower_limits) and np.all(dense.q <= er20.upper_limits)
    assert res.max_torque_ratio <= cfg.torque_fraction + 1e-3
    # TCP above the floor, checked independently with Pinocchio on the dense grid
    data = er20.model.createData()
    z = []
    for q in dense.q[::20]:
        pin.framesForwardKinematics(er20.model, data, q)
        z.append(data.oMf[er20.tcp_frame_id].translation[2])
    assert min(z) >= cfg.floor_height - 0.02
