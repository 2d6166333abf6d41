"""Friction models (eq. 15, 5, 8), rotor inertia (eq. 16) and the model torque (eq. 21)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.dynamics import (
    DriveModelParameters,
    FrictionModel,
    StribeckParameters,
    cbrt_friction,
    coulomb_viscous_friction,
    link_torque,
    model_torque,
    nominal_drive_parameters,
    stribeck_friction,
)

R = np.array([147.0, 50.0])
P = StribeckParameters(f1=np.array([30.0, 1.0]), f2=np.array([20.0, 0.5]),
                       qd_sm=np.array([12.0, 10.0]), f3=np.array([10.0, 0.4]),
                       qd_sg=np.array([0.1, 0.2]), f4=np.array([15.0, 0.3]))


def test_stribeck_limits() -> None:
    tiny = stribeck_friction(np.array([[1e-9, -1e-9]]), R, P)
    np.testing.assert_allclose(tiny[0], [60.0, -1.9], rtol=1e-6)  # f1 + f2 + f3 at 0±
    fast = stribeck_friction(np.array([[2.0, -2.0]]), R, P)
    np.testing.assert_allclose(fast[0], [30.0 + 30.0, -(1.0 + 0.6)], rtol=1e-9)  # f1 + f4·q̇
    assert stribeck_friction(np.array([[0.0, 0.0]]), R, P).tolist() == [[0.0, 0.0]]


def test_motor_side_stribeck_uses_motor_speed() -> None:
    # at R·q̇ = q̇sm the motor term has decayed to e^-1; the gear term is separate
    qd = np.array([[12.0 / 147.0, 10.0 / 50.0]])
    only_motor = StribeckParameters(f1=np.zeros(2), f2=np.ones(2), qd_sm=P.qd_sm,
                                    f3=np.zeros(2), qd_sg=P.qd_sg, f4=np.zeros(2))
    np.testing.assert_allclose(stribeck_friction(qd, R, only_motor)[0], np.exp(-1.0))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-5.0, 5.0, allow_nan=False), min_size=2, max_size=2))
def test_friction_is_odd_and_dissipative(v: list[float]) -> None:
    qd = np.array([v])
    for tau in (stribeck_friction(qd, R, P),
                coulomb_viscous_friction(qd, P.f1, P.f4),
                cbrt_friction(qd, P.f1, P.f4, np.array([2.0, 0.1]))):
        assert np.all(tau * qd >= 0.0)
    np.testing.assert_allclose(stribeck_friction(-qd, R, P), -stribeck_friction(qd, R, P))


def test_model_torque_sums_the_terms(er20) -> None:
    rng = np.random.default_rng(1)
    q = rng.uniform(er20.lower_limits, er20.upper_limits, (20, 6))
    qd = rng.normal(size=(20, 6))
    qdd = rng.normal(size=(20, 6))
    base = nominal_drive_parameters(er20)
    params = DriveModelParameters(
        phi=base.phi, friction_model=FrictionModel.STRIBECK, rotor_inertia=np.full(6, 0.5),
        stribeck=StribeckParameters(*(np.full(6, x) for x in (10.0, 5.0, 12.0, 3.0, 0.1, 2.0))))
    expected = (link_torque(er20.model, base.phi, q, qd, qdd)
                + stribeck_friction(qd, er20.gear_ratio, params.stribeck) + 0.5 * qdd)
    np.testing.assert_allclose(model_torque(er20, params, q, qd, qdd), expected)
