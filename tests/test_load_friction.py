"""Load-dependent friction: the Coulomb level f_c0 + f_cL·|τ_load| (Bittencourt et al. 2010) in
the model, the identification, the params file and the estimator."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.dynamics import (
    DriveModelParameters,
    FrictionModel,
    StribeckParameters,
    coulomb_level,
    model_torque,
    nominal_drive_parameters,
)
from leadthrough.errors import DataError
from leadthrough.robot import Robot


def _stribeck(n: int) -> StribeckParameters:
    return StribeckParameters(*(np.full(n, x) for x in (10.0, 5.0, 12.0, 3.0, 0.1, 2.0)))


def _states(robot: Robot, samples: int, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.lower_limits, robot.upper_limits, (samples, robot.n))
    return q, rng.normal(size=(samples, robot.n)), rng.normal(size=(samples, robot.n))


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e3, 1e3), st.floats(-1e6, 1e6) | st.just(np.nan) | st.just(np.inf))
def test_coulomb_level_without_load_term_is_the_coefficient_itself(f_c0: float,
                                                                   load: float) -> None:
    with np.errstate(invalid="ignore"):  # the compiled select may evaluate the other branch
        assert coulomb_level(f_c0, 0.0, load) == f_c0  # whatever τ_load is, even not finite


def test_model_torque_adds_the_load_term_of_the_link_torque(er20: Robot) -> None:
    """τ = RNEA(φ) + (f1 + f_cL·|RNEA(φ)|)·sgn(q̇) + Stribeck + f4·q̇ + M_j·q̈, written out."""
    q, qd, qdd = _states(er20, 20, 1)
    base = nominal_drive_parameters(er20)
    fl = np.linspace(0.01, 0.1, 6)
    st_ = _stribeck(6)
    params = DriveModelParameters(phi=base.phi, friction_model=FrictionModel.STRIBECK,
                                  rotor_inertia=np.full(6, 0.5), stribeck=st_, load_friction=fl)
    data = er20.model.createData()
    links = np.array([pin.rnea(er20.model, data, *x) for x in zip(q, qd, qdd, strict=True)])
    s = np.sign(qd)
    friction = ((st_.f1 + fl * np.abs(links)) * s
                + st_.f2 * np.exp(-(er20.gear_ratio * qd / st_.qd_sm) ** 2) * s
                + st_.f3 * np.exp(-(qd / st_.qd_sg) ** 2) * s + st_.f4 * qd)
    np.testing.assert_allclose(model_torque(er20, params, q, qd, qdd),
                               links + friction + 0.5 * qdd, rtol=1e-12, atol=1e-9)
    # the baselines' Coulomb term carries it the same way
    cv = replace(base, coulomb=np.full(6, 7.0), viscous=np.full(6, 2.0), load_friction=fl)
    np.testing.assert_allclose(
        model_torque(er20, cv, q, qd, qdd),
        links + (7.0 + fl * np.abs(links)) * s + 2.0 * qd + base.rotor_inertia * qdd,
        rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("model", list(FrictionModel))
def test_zero_load_friction_leaves_the_model_bit_identical(er20: Robot, model: FrictionModel
                                                           ) -> None:
    q, qd, qdd = _states(er20, 50, 2)
    base = replace(nominal_drive_parameters(er20), friction_model=model,
                   stribeck=_stribeck(6), coulomb=np.full(6, 7.0), viscous=np.full(6, 2.0),
                   cbrt=np.full(6, 0.5), offset=np.linspace(-1, 1, 6))
    zero = replace(base, load_friction=np.zeros(6))
    assert not zero.has_load_friction
    assert np.array_equal(model_torque(er20, zero, q, qd, qdd),
                          model_torque(er20, base, q, qd, qdd))


@pytest.mark.parametrize("bad", [[-0.01] + [0.0] * 5, [0.0] * 5 + [1.0], [np.nan] * 6,
                                 [0.01] * 5])
def test_bad_load_friction_is_refused(er20: Robot, bad: list[float]) -> None:
    with pytest.raises(DataError, match="load-dependent friction") as e:
        replace(nominal_drive_parameters(er20), load_friction=np.array(bad))
    assert e.value.field == "load_friction"


def test_load_friction_needs_the_load_torque(er20: Robot) -> None:
    p = replace(nominal_drive_parameters(er20), load_friction=np.full(6, 0.05))
    with pytest.raises(DataError, match="load torque"):
        p.friction(np.ones((1, 6)), er20.gear_ratio)
