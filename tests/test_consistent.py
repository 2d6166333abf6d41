"""The consistent method: physical consistency, bounds, exact inner problem, clear failures."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.data.preprocess import ProcessedData
from leadthrough.dynamics import FrictionModel, model_torque, standard_parameters
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.identification.api import IdentificationResult, IdentifyConfig, identify
from leadthrough.identification.consistency import (
    link_bounds,
    min_pseudo_inertia_eigenvalues,
    pseudo_inertia,
)
from leadthrough.identification.consistent import SolverError
from leadthrough.identification.proposed import ProposedConfig
from leadthrough.robot import Robot, builtin_robot_path, load_robot
from leadthrough.robot.urdf_export import write_urdf_with_inertias
from leadthrough.sim.link_truth import perturb_inertia
from test_identification import _data, _trajectory, _true_params


def test_pseudo_inertia_of_real_bodies_is_psd(er20: Robot) -> None:
    rng = np.random.default_rng(0)
    for j in range(1, 7):
        for _ in range(20):
            inertia = perturb_inertia(er20.model.inertias[j], rng, 0.3)
            phi = np.asarray(inertia.toDynamicParameters())
            assert np.linalg.eigvalsh(pseudo_inertia(phi))[0] >= -1e-12
    # a body violating the triangle inequality is caught (the 3×3 inertia is still PD)
    bad = pin.Inertia(2.0, np.zeros(3), np.diag([1.0, 0.2, 0.2]))
    assert np.all(np.linalg.eigvalsh(bad.inertia) > 0)
    assert min_pseudo_inertia_eigenvalues(np.asarray(bad.toDynamicParameters()))[0] < 0


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 6), st.lists(st.floats(-1, 1), min_size=10, max_size=10))
def test_relaxed_bounds_contain_the_papers_box(j: int, u: list[float]) -> None:
    """Every (m, c, I_c) inside the ±30 % box of eq. 37 satisfies our convex bounds."""
    nominal = load_robot("er20").model.inertias[j]
    m0, c0, I0 = nominal.mass, np.asarray(nominal.lever), np.asarray(nominal.inertia)
    m = m0 * (1 + 0.3 * u[0])
    c = c0 + 0.3 * np.abs(c0).max() * np.array(u[1:4])
    d = 0.3 * np.abs(I0).max() * np.array(u[4:])
    I_c = I0 + np.array([[d[0], d[1], d[3]], [d[1], d[2], d[4]], [d[3], d[4], d[5]]])
    I_o = I_c + m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))  # parallel axis
    phi = np.array([m, *(m * c), I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2],
                    I_o[2, 2]])
    b = link_bounds(np.asarray(nominal.toDynamicParameters()), 0.3)
    tol = 1e-9
    assert b.mass[0] - tol <= phi[0] <= b.mass[1] + tol
    assert np.all(phi[1:4] >= phi[0] * b.com_lower - tol)
    assert np.all(phi[1:4] <= phi[0] * b.com_upper + tol)
    assert np.all(phi[4:] >= b.inertia_lower - tol) and np.all(phi[4:] <= b.inertia_upper + tol)


@pytest.fixture(scope="module")
def stribeck_consistent(er20: Robot) -> tuple[DriveModelParameters, ProcessedData,
                                              IdentificationResult]:
    """Eq. 15 truth, its noise-free data (run 1) and the consistent method's result on it,
    computed once for the tests that only read them (the method reads no ``proposed``
    settings)."""
    truth = _true_params(er20, FrictionModel.STRIBECK)
    data = _data(er20, truth, 1)
    return truth, data, identify(data, er20, "consistent")


def test_consistent_beats_proposed_fast_and_physical(
        er20: Robot, stribeck_consistent: tuple[DriveModelParameters, ProcessedData,
                                                IdentificationResult]) -> None:
    truth, data, cons = stribeck_consistent
    cfg = IdentifyConfig(proposed=ProposedConfig(generations=40, polish_iterations=400))
    prop = identify(data, er20, "proposed", cfg)
    assert cons.J < prop.J
    assert np.all(cons.min_pseudo_inertia_eig >= 0)
    # the link part is exact up to the Stribeck grid: it predicts other motions well
    other = _data(er20, truth, 2)
    tau_other = model_torque(er20, cons.params, other.q, other.qd, other.qdd)
    rel = np.linalg.norm(tau_other - other.torque) / np.linalg.norm(other.torque)
    assert rel < 0.02


def test_ols_results_can_be_unphysical_and_it_shows(er20: Robot) -> None:
    truth = _true_params(er20, FrictionModel.COULOMB_VISCOUS)
    data = _data(er20, truth, 1)
    noisy = ProcessedData(time=data.time, q=data.q, qd=data.qd, qdd=data.qdd,
                          torque=data.torque + np.random.default_rng(0).normal(
                              0, 0.02 * er20.max_torque, data.torque.shape),
                          moving=data.moving, rate_hz=data.rate_hz, source="noisy")
    ols = identify(noisy, er20, "ols-cv")
    cons = identify(noisy, er20, "consistent")
    assert ols.min_pseudo_inertia_eig.min() < 0 <= cons.min_pseudo_inertia_eig.min()


def test_infeasible_bounds_name_the_link(tmp_path: Path, er20: Robot) -> None:
    src = builtin_robot_path("er20")
    shutil.copy(src, tmp_path / "er20.toml")
    urdf = (src.parent / "er20.urdf").read_text()
    urdf = urdf.replace('<inertia ixx="0.0020" ixy="0.0" ixz="0.0" iyy="0.0014" iyz="0.0" '
                        'izz="0.0014"/>',
                        '<inertia ixx="0.05" ixy="0.0" ixz="0.0" iyy="0.001" iyz="0.0" '
                        'izz="0.001"/>')
    (tmp_path / "er20.urdf").write_text(urdf)
    bad = load_robot(tmp_path / "er20.toml")
    s = _trajectory(bad, 1)
    truth = _true_params(er20, FrictionModel.STRIBECK)
    tau = model_torque(er20, truth, s.q, s.qd, s.qdd)
    data = ProcessedData(time=s.time, q=s.q, qd=s.qd, qdd=s.qdd, torque=tau,
                         moving=np.abs(s.qd) > 0.02, rate_hz=100.0, source="synthetic")
    with pytest.raises(SolverError) as e:
        identify(data, bad, "consistent")
    assert e.value.field == "links.joint_6" and "bounds" in str(e.value)


def test_urdf_export_round_trip(
        tmp_path: Path, er20: Robot,
        stribeck_consistent: tuple[DriveModelParameters, ProcessedData, IdentificationResult]
        ) -> None:
    res = stribeck_consistent[2]
    path = write_urdf_with_inertias(er20, res.params.phi, tmp_path / "identified.urdf")
    model = pin.buildModelFromUrdf(str(path))
    np.testing.assert_allclose(standard_parameters(model), res.params.phi, atol=1e-10)
