"""Calibration methods: exact recovery on model-generated data, errors, params files, and the
paper's ordering end to end on the simulated robot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from leadthrough.data.preprocess import ProcessedData
from leadthrough.data.recording import Recording
from leadthrough.dynamics import (
    DriveModelParameters,
    FrictionModel,
    StribeckParameters,
    model_torque,
    standard_parameters,
)
from leadthrough.errors import DataError
from leadthrough.excitation.fourier import FourierTrajectory
from leadthrough.identification.api import IdentifyConfig, evaluate, identify
from leadthrough.identification.comparison import compare_methods, noise_floor
from leadthrough.identification.params_file import load_params, save_params
from leadthrough.identification.proposed import ProposedConfig
from leadthrough.robot import Robot, load_robot
from leadthrough.sim.calibration_set import CalibrationSet
from leadthrough.sim.link_truth import true_link_inertias


def _trajectory(robot: Robot, seed: int, seconds: float = 30.0, rate: float = 100.0,
                amplitude: float = 0.12):
    rng = np.random.default_rng(seed)
    mid = 0.5 * (robot.lower_limits + robot.upper_limits)
    half = 0.5 * (robot.upper_limits - robot.lower_limits)
    scale = amplitude * half[:, None]
    traj = FourierTrajectory(0.1, mid, rng.uniform(-1, 1, (robot.n, 4)) * scale,
                             rng.uniform(-1, 1, (robot.n, 4)) * scale)
    return traj.sample(np.arange(0.0, seconds, 1.0 / rate))


def _data(robot: Robot, params: DriveModelParameters, seed: int) -> ProcessedData:
    s = _trajectory(robot, seed)
    tau = model_torque(robot, params, s.q, s.qd, s.qdd)
    return ProcessedData(time=s.time, q=s.q, qd=s.qd, qdd=s.qdd, torque=tau,
                         moving=np.abs(s.qd) > 0.02, rate_hz=100.0, source=f"synthetic {seed}")


def _true_params(robot: Robot, model: FrictionModel) -> DriveModelParameters:
    m = robot.model.copy()
    for j, inertia in enumerate(true_link_inertias(m, np.random.default_rng(3), 0.2), start=1):
        m.inertias[j] = inertia
    tmax, n = robot.max_torque, robot.n
    return DriveModelParameters(
        phi=standard_parameters(m), friction_model=model,
        rotor_inertia=robot.reflected_rotor_inertia * 1.1,
        stribeck=StribeckParameters(f1=0.02 * tmax, f2=0.02 * tmax, qd_sm=np.full(n, 15.0),
                                    f3=0.015 * tmax, qd_sg=np.full(n, 0.15), f4=0.02 * tmax),
        coulomb=0.03 * tmax, viscous=0.02 * tmax, cbrt=0.01 * tmax)


@pytest.mark.parametrize("method, model", [("ols-cv", FrictionModel.COULOMB_VISCOUS),
                                           ("ols-cbrt", FrictionModel.CBRT)])
def test_least_squares_recover_their_own_model(er20: Robot, method: str,
                                               model: FrictionModel) -> None:
    truth = _true_params(er20, model)
    if model is FrictionModel.COULOMB_VISCOUS:  # [7] has no rotor inertia term
        truth = DriveModelParameters(phi=truth.phi, friction_model=model,
                                     rotor_inertia=np.zeros(6), coulomb=truth.coulomb,
                                     viscous=truth.viscous)
    res = identify(_data(er20, truth, 1), er20, method)
    assert 1e-6 * er20.max_torque.sum() > res.J
    # the identified model predicts other motions exactly (base parameters are right)
    other = _data(er20, truth, 2)
    assert 1e-6 * er20.max_torque.sum() > evaluate(res.params, er20, other).J
    np.testing.assert_allclose(res.params.coulomb, truth.coulomb, rtol=1e-6)


def test_proposed_fits_its_own_model(er20: Robot) -> None:
    """On noise-free eq. 15 data the paper's method clearly beats both baselines.

    (Its population search does not reach J = 0 on its own model class: the 2n Stribeck
    velocities make the problem non-convex. Measured: J ≈ 3.8 N·m vs 11.2 for ols-cbrt.)
    """
    truth = _true_params(er20, FrictionModel.STRIBECK)
    data = _data(er20, truth, 1)
    cfg = IdentifyConfig(proposed=ProposedConfig(generations=40, polish_iterations=400))
    res = identify(data, er20, "proposed", cfg)
    cbrt = identify(data, er20, "ols-cbrt")
    cv = identify(data, er20, "ols-cv")
    assert res.J < 0.5 * cbrt.J < 0.5 * cv.J
    assert res.iterations > 40
    # eq. 37 bounds hold for the mass of every link
    nominal = standard_parameters(er20.model)
    masses, nom = res.params.phi[0::10], nominal[0::10]
    assert np.all(np.abs(masses - nom) <= 0.3 * nom + 1e-9)


def test_joint_that_never_moves(er20: Robot) -> None:
    s = _trajectory(er20, 1, rate=1000.0)
    q = s.q.copy()
    q[:, 3] = 0.2
    rec = Recording(time=s.time, q=q, current=np.ones_like(q), robot="er20")
    with pytest.raises(DataError, match="joint_4' barely moves") as e:
        identify(rec, er20, "ols-cv")
    assert "excitation trajectory" in str(e.value)


def test_wrong_robot_and_too_short(er20: Robot) -> None:
    s = _trajectory(er20, 1, seconds=0.05, rate=1000.0)
    rec = Recording(time=s.time, q=s.q, current=np.ones_like(s.q), robot="er20")
    with pytest.raises(DataError, match="too few samples"):
        identify(rec, er20, "ols-cv")
    with pytest.raises(DataError, match="joint count"):
        identify(rec, load_robot("panda"), "ols-cv")
    with pytest.raises(DataError, match="unknown method"):
        identify(rec, er20, "magic")


def test_params_file_round_trip(tmp_path: Path, er20: Robot) -> None:
    truth = _true_params(er20, FrictionModel.STRIBECK)
    data = _data(er20, truth, 1)
    res = identify(data, er20, "ols-cbrt")
    path = save_params(tmp_path / "p.toml", er20, "ols-cbrt", res.params, res.stats)
    back = load_params(path, er20)
    assert back.method == "ols-cbrt" and back.J == res.J
    np.testing.assert_array_equal(back.params.phi, res.params.phi)
    np.testing.assert_array_equal(back.params.cbrt, res.params.cbrt)
    np.testing.assert_array_equal(back.noise_mean, res.stats.mean)
    with pytest.raises(DataError, match="another robot") as e:
        load_params(path, load_robot("ur5"))
    assert e.value.field == "meta.robot"


def test_table_ii_ordering_on_the_simulated_robot(er20: Robot,
                                                  ideal_calibration_set: CalibrationSet
                                                  ) -> None:
    """Paper's ordering J(proposed) < J(ols-cbrt) < J(ols-cv), ratio <= 0.8, near the floor, on
    the ideal plant (the paper's model class: eq. 15 friction, links inside the box). On the
    realistic plant the identification-data J of ``proposed`` (held to the ±30 % box) is above
    ols-cbrt's (seed 1: 49.5 vs 44.8 N·m; README, Limitations); on held-out data the order
    holds there too (the quick demo's Table II)."""
    cal = ideal_calibration_set  # conftest's: seed 1, 2 × 30 s, starts=1, 60 iterations
    cfg = IdentifyConfig(proposed=ProposedConfig(generations=60, polish_iterations=200))
    comp = compare_methods(er20, cal.identification.measured,
                           {"held-out": cal.held_out.measured},
                           ["ols-cv", "ols-cbrt", "proposed"], cfg)
    floor = noise_floor(er20, cal.identification.measured, cal.identification.true, cfg)
    for label in comp.labels:
        J = {m: comp.stats(m, label).J for m in comp.results}
        assert J["proposed"] < J["ols-cbrt"] < J["ols-cv"], (label, J)
        assert J["proposed"] / J["ols-cv"] <= 0.8, (label, J)
    assert comp.results["proposed"].J <= 1.5 * floor.J
