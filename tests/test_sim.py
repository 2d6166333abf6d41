"""The simulated robot: holding, currents vs the drive model, pushes, determinism, truth."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.errors import SimulationError
from leadthrough.robot import Robot
from leadthrough.sim import ConstantWrench, Payload, SimConfig, SimRobot, hold, run_trajectory
from leadthrough.sim.checks import check_hold, check_push
from leadthrough.sim.link_truth import second_moment

# "Within the noise": averaged current error below half the per-sample noise σ (see
# leadthrough.sim.checks for what the remaining physical residual is).
WITHIN_NOISE = 0.5
POSES = [
    np.array([0.3, -0.6, 0.4, 0.5, 0.8, 0.2]),
    np.array([-1.2, -1.5, 1.2, -2.0, -1.0, 3.0]),
    np.array([2.0, 0.5, -0.8, 1.0, 1.5, -1.0]),
]


@pytest.mark.parametrize("q0", POSES)
def test_holds_pose_and_currents_match_gravity(er20: Robot, q0: np.ndarray) -> None:
    h = check_hold(er20, SimConfig(seed=1), q0)
    assert h.max_joint_error.max() < 1e-4  # rad: below 0.1 mrad
    assert np.all(h.error_in_sigma < WITHIN_NOISE)


@pytest.mark.parametrize("force", [(50, 0, 0), (0, -50, 0), (0, 0, 50)])
def test_push_changes_currents_by_jacobian_transpose(er20: Robot, force: tuple) -> None:
    wrench = np.array([*force, 0.0, 0.0, 0.0], dtype=float)
    p = check_push(er20, SimConfig(seed=2), POSES[0], wrench)
    assert np.all(p.error_in_sigma < WITHIN_NOISE)
    # the push is clearly visible: on some joint the expected current change exceeds 4 of that
    # joint's per-sample noise σ (5.3-10 σ for these pushes), and the check's mean over many
    # samples resolves it far more finely
    assert np.max(np.abs(p.expected_delta) / p.noise_sigma) > 4.0


def test_true_external_torque_is_jacobian_transpose(er20: Robot) -> None:
    q0 = POSES[0]
    sim = SimRobot(er20, SimConfig(seed=3), q0=q0,
                   operator=ConstantWrench((10.0, -20.0, 30.0, 1.0, 2.0, -3.0)))
    hold(sim, 0.05)
    q = sim.true_state()[0]
    model, data = er20.model, er20.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = pin.getFrameJacobian(model, data, er20.tcp_frame_id, pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(sim.true_external_torque,
                               J.T @ sim.applied_wrench, rtol=1e-3, atol=1e-3)


def _record(robot: Robot, seed: int) -> tuple[np.ndarray, np.ndarray, SimRobot]:
    sim = SimRobot(robot, SimConfig(seed=seed), q0=POSES[0])
    t = np.arange(500) * 1e-3
    q_cmd = POSES[0] + 0.1 * np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(6)
    log = run_trajectory(sim, q_cmd)
    return log.q, log.current, sim


def test_same_seed_is_bit_identical(er20: Robot) -> None:
    q1, c1, _ = _record(er20, 5)
    q2, c2, _ = _record(er20, 5)
    assert np.array_equal(q1, q2) and np.array_equal(c1, c2)


def test_other_seed_differs(er20: Robot) -> None:
    _, c1, s1 = _record(er20, 5)
    _, c2, s2 = _record(er20, 6)
    assert not np.allclose(s1.truth.phi, s2.truth.phi)
    assert not np.allclose(s1.truth.drive.coulomb_gear, s2.truth.drive.coulomb_gear)
    assert not np.allclose(s1.truth.current_bias, s2.truth.current_bias)
    assert not np.array_equal(c1, c2)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_truth_is_consistent_and_within_30_percent(er20: Robot, seed: int) -> None:
    """The ideal plant's links stay in the identifiers' box (the realistic plant's leave it:
    tests/test_sim_plant.py)."""
    sim = SimRobot(er20, SimConfig(seed=seed, plant="ideal"))
    for j, true in enumerate(sim.truth.inertias, start=1):
        nom = er20.model.inertias[j]
        assert abs(true.mass - nom.mass) <= 0.3 * nom.mass + 1e-12
        assert np.all(np.abs(true.lever - nom.lever) <= 0.3 * np.abs(nom.lever).max() + 1e-12)
        dI = np.abs(true.inertia - nom.inertia)
        assert np.all(dI <= 0.3 * np.abs(nom.inertia).max() + 1e-12)
        assert np.linalg.eigvalsh(second_moment(true.inertia)).min() >= -1e-12  # consistent
    d = sim.truth.drive
    assert np.all(d.armature > 0) and np.all(d.coulomb_gear > 0) and np.all(d.viscous > 0)


def test_truth_differs_from_nominal(er20: Robot) -> None:
    from leadthrough.dynamics import standard_parameters

    sim = SimRobot(er20, SimConfig(seed=1))
    rel = np.abs(sim.truth.phi - standard_parameters(er20.model))
    assert rel.max() > 0.5  # the "CAD" model is clearly wrong somewhere


def test_payload_adds_its_weight(er20: Robot) -> None:
    q0 = POSES[0]
    base = check_hold(er20, SimConfig(seed=1), q0)
    sim = SimRobot(er20, SimConfig(seed=2), q0=q0, payload=Payload(10.0, (0.0, 0.0, 0.1)))
    log = hold(sim, 4.0)
    model = er20.model.copy()
    for j, inertia in enumerate(sim.truth.inertias, start=1):
        model.inertias[j] = inertia
    frame = model.frames[er20.tcp_frame_id]
    model.inertias[frame.parentJoint] += frame.placement.act(Payload(10.0, (0, 0, 0.1))
                                                             .as_pin_inertia())
    g = pin.computeGeneralizedGravity(model, model.createData(), q0)
    expected = (g - sim.true_cogging_torque(q0)) / sim.true_torque_per_amp  # the true drives
    assert np.all(np.abs(log.current.mean(0) - expected) < WITHIN_NOISE * sim.truth.current_noise)
    assert np.max(np.abs(expected - base.current_expected)) > 0.1  # A: the payload is visible


def test_bad_settings_raise() -> None:
    with pytest.raises(SimulationError):
        SimConfig(timestep=0.0)
    with pytest.raises(SimulationError):
        SimConfig(servo_bandwidth_hz=0.0)
    with pytest.raises(SimulationError):
        Payload(-1.0)


def test_bad_initial_pose(er20: Robot) -> None:
    with pytest.raises(SimulationError, match="outside the joint limits"):
        SimRobot(er20, q0=np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0]))
