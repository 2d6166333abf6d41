"""K·φ (eq. 3) against Pinocchio RNEA and MuJoCo inverse dynamics; base parameters."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from leadthrough.dynamics import (
    compute_base_parameters,
    link_regressor_batch,
    link_torque,
    standard_parameter_names,
    standard_parameters,
)
from leadthrough.dynamics.base_parameters import random_samples
from leadthrough.robot import BUILTIN_ROBOTS, load_robot
from leadthrough.sim.checks import check_regressor
from leadthrough.sim.link_truth import true_link_inertias

BASE_COUNTS = {"er20": 36, "ur5": 36, "ur10": 36, "panda": 43}


@pytest.mark.parametrize("name", BUILTIN_ROBOTS)
def test_regressor_matches_rnea_and_mujoco(name: str) -> None:
    check = check_regressor(load_robot(name), samples=1000, seed=3)
    assert check.rel_error_rnea < 1e-9
    assert check.rel_error_mujoco < 1e-9
    assert check.rel_error_base < 1e-9
    assert check.base_parameters == BASE_COUNTS[name]


@pytest.mark.parametrize("name", ["er20", "panda"])
def test_regressor_with_perturbed_parameters(name: str) -> None:
    """K·φ for non-nominal φ equals RNEA of a model carrying those inertias."""
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    model = robot.model.copy()
    for j, inertia in enumerate(true_link_inertias(model, rng, 0.3), start=1):
        model.inertias[j] = inertia
    phi = standard_parameters(model)
    q, qd, qdd = random_samples(model, 50, rng)
    tau = link_torque(robot.model, phi, q, qd, qdd)
    data = model.createData()
    ref = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(50)])
    np.testing.assert_allclose(tau, ref, atol=1e-9 * np.abs(ref).max())


def test_base_mapping_is_explicit_and_stable(er20) -> None:
    base = compute_base_parameters(er20.model)
    names = standard_parameter_names(er20.model)
    assert len(names) == 60 and names[0] == "joint_1.m" and names[12] == "joint_2.my"
    assert base.combination.shape == (36, 60)
    # anchors map with coefficient 1, and the mapping does not depend on the sample seed
    np.testing.assert_array_equal(base.combination[np.arange(36), base.independent], 1.0)
    other = compute_base_parameters(er20.model, seed=11)
    np.testing.assert_array_equal(other.independent, base.independent)
    np.testing.assert_allclose(other.combination, base.combination, atol=1e-8)
    # joint 1 about a vertical axis: only its Izz (regrouped) is identifiable
    assert [n for n in base.names if n.startswith("joint_1.")] == ["joint_1.Izz'"]
    # textbook regrouping: the mass of link 6 adds to the first moment of link 5 by d6 = 0.125
    k = base.names.index("joint_5.mx'")
    assert base.combination[k, names.index("joint_6.m")] == pytest.approx(0.125)


def test_base_regressor_reproduces_torque_for_any_phi(er20) -> None:
    base = compute_base_parameters(er20.model)
    rng = np.random.default_rng(0)
    q, qd, qdd = random_samples(er20.model, 200, rng)
    K = link_regressor_batch(er20.model, q, qd, qdd)
    phi = rng.normal(size=60)  # not even physical: the mapping is linear algebra
    np.testing.assert_allclose(base.regressor(K) @ base.from_standard(phi), K @ phi,
                               atol=1e-9 * np.abs(K @ phi).max())
