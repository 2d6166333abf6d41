"""Drive gains and the gears' load friction from a known mass, and the payload read through
them: exact on synthetic runs of a known model, against Pinocchio's inertia algebra, and the
refusals."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.data.preprocess import ProcessedData
from leadthrough.dynamics import FrictionModel
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.errors import DataError
from leadthrough.estimation.drive_gains import KnownPayload, estimate_drive_gains
from leadthrough.estimation.payload import estimate_payload
from leadthrough.estimation.payload_system import PayloadSystem, payload_regressor
from leadthrough.robot import Robot
from test_identification import _data, _true_params

#: The drives' true torque per torque read through the drive file (a few per cent off).
GAIN = np.array([1.03, 0.97, 1.02, 0.98, 1.04, 0.96])
#: The gears' Coulomb friction per N·m transmitted.
LOAD_FRICTION = np.array([0.06, 0.08, 0.05, 0.04, 0.07, 0.03])
KNOWN = KnownPayload(20.0, (0.05, 0.0, 0.15))
OTHER_MASS, OTHER_COM = 8.0, np.array([0.02, -0.01, 0.12])


def _loaded_phi(robot: Robot, truth: DriveModelParameters, phi_payload: np.ndarray
                ) -> np.ndarray:
    phi = truth.phi.copy()
    phi[10 * (robot.n - 1):] += phi_payload
    return phi


def _read(data: ProcessedData, gain: np.ndarray) -> ProcessedData:
    """The run as the drives read it: true torque / c."""
    return replace(data, torque=data.torque / gain)


@pytest.fixture(scope="module")
def runs(er20: Robot) -> dict[str, object]:
    """A robot with load-dependent gear friction and drive gains off the drive file: the same
    trajectory unloaded, with the known 20 kg and with an unknown 8 kg payload."""
    truth = replace(_true_params(er20, FrictionModel.STRIBECK), load_friction=LOAD_FRICTION)
    other = pin.Inertia(OTHER_MASS, OTHER_COM,
                        pin.Inertia.FromBox(OTHER_MASS, 0.1, 0.2, 0.1).inertia)
    tcp = er20.model.frames[er20.tcp_frame_id].placement
    phi_other = tcp.act(other).toDynamicParameters()
    return {
        "truth": truth,
        "unloaded": _data(er20, truth, seed=4),
        "known": _data(er20, replace(truth, phi=_loaded_phi(er20, truth,
                                                            KNOWN.parameters(er20))), seed=4),
        "other": _data(er20, replace(truth, phi=_loaded_phi(er20, truth, phi_other)), seed=4),
    }


def test_gains_and_load_friction_are_exact_on_a_known_model(er20: Robot, runs: dict) -> None:
    """Runs of the model itself, read through wrong drive gains: the gains and the load
    coefficients come out exact, and the 8 kg payload read through them too; through the drive
    file's gains it is off by the gains' error."""
    truth = runs["truth"]
    unloaded, known, other = (_read(runs[k], GAIN) for k in ("unloaded", "known", "other"))
    gains = estimate_drive_gains(known, unloaded, er20, truth, KNOWN)
    assert gains.robot == er20.name and gains.applied.all()
    np.testing.assert_allclose(gains.gain, GAIN, rtol=1e-6)
    np.testing.assert_allclose(gains.load_friction, LOAD_FRICTION, rtol=1e-5)
    assert gains.reference_shift_s == pytest.approx(0.0, abs=1e-9)
    est = estimate_payload(other, er20, truth, "motion", reference=unloaded, drive_gains=gains)
    assert est.mass_kg == pytest.approx(OTHER_MASS, rel=1e-6)
    assert est.com_tcp is not None
    np.testing.assert_allclose(est.com_tcp, OTHER_COM, atol=1e-6)
    assert est.iterations > 1
    off = estimate_payload(other, er20, truth, "motion", reference=unloaded)
    assert abs(off.mass_kg / OTHER_MASS - 1.0) > 0.01


def test_without_drive_gains_the_payloads_own_load_friction_is_not_modelled(
        er20: Robot, runs: dict) -> None:
    """The drive file's gains right, no drive gains: the identified load coefficients are not
    used for the payload's own friction (one fit, as with none identified), so the mass is off
    by that friction; drive gains measured with the known mass (all 1 here) make it exact."""
    truth = runs["truth"]
    est = estimate_payload(runs["other"], er20, truth, "motion", reference=runs["unloaded"])
    blind = replace(truth, load_friction=np.zeros(0))
    same = estimate_payload(runs["other"], er20, blind, "motion", reference=runs["unloaded"])
    assert est.iterations == 1 and est.mass_kg == same.mass_kg
    assert abs(est.mass_kg / OTHER_MASS - 1.0) > 1e-3
    gains = estimate_drive_gains(runs["known"], runs["unloaded"], er20, truth, KNOWN)
    np.testing.assert_allclose(gains.gain, 1.0, rtol=1e-6)
    est = estimate_payload(runs["other"], er20, truth, "motion", reference=runs["unloaded"],
                           drive_gains=gains)
    assert est.mass_kg == pytest.approx(OTHER_MASS, rel=1e-6) and est.iterations > 1


def test_a_joint_the_mass_barely_loads_is_not_applied(er20: Robot, runs: dict) -> None:
    """Noisy torque: a 20 kg mass gives the loaded joints' gains, a 20 g mass none (refused,
    naming the best joint's standard error); gains of another robot are refused."""
    rng = np.random.default_rng(0)
    truth = runs["truth"]

    def noisy(data: ProcessedData) -> ProcessedData:
        return replace(data, torque=data.torque + rng.normal(0.0, 0.01, data.torque.shape)
                       * er20.max_torque)

    unloaded, known = noisy(runs["unloaded"]), noisy(runs["known"])
    gains = estimate_drive_gains(known, unloaded, er20, truth, KNOWN)
    assert gains.applied[1] and gains.applied[2]          # shoulder and elbow carry the weight
    ok = gains.applied
    assert np.all(np.abs(gains.gain[ok] - 1.0) <= 3 * gains.gain_std[ok] + 1e-12)
    assert np.all(gains.gain_std[ok] <= 0.01 * gains.gain[ok])
    assert np.all(gains.load_friction[~ok] == 0.0)
    light = replace(truth, phi=_loaded_phi(er20, truth, KnownPayload(0.02).parameters(er20)))
    with pytest.raises(DataError, match="loads no joint enough") as e:
        estimate_drive_gains(noisy(_data(er20, light, seed=4)), unloaded, er20, truth,
                             KnownPayload(0.02))
    assert e.value.field is not None and e.value.field.startswith("gain_std")
    with pytest.raises(DataError, match="with and without the known mass follow different") as e:
        estimate_drive_gains(known, noisy(_data(er20, truth, seed=5)), er20, truth, KNOWN)
    assert e.value.field is not None and e.value.field.startswith("q")
    foreign = replace(gains, robot="ur5")
    with pytest.raises(DataError, match="another robot"):
        estimate_payload(known, er20, truth, "motion", reference=unloaded, drive_gains=foreign)


def test_known_payload_parameters_follow_pinocchio(er20: Robot) -> None:
    """The known payload's parameters in the last joint's frame are Pinocchio's inertia moved
    from the TCP frame; bad values are refused by field."""
    inertia = ((0.1, 0.01, 0.0), (0.01, 0.2, 0.0), (0.0, 0.0, 0.3))
    known = KnownPayload(5.0, (0.01, 0.02, 0.1), inertia)
    tcp = er20.model.frames[er20.tcp_frame_id].placement
    phi = known.parameters(er20)
    moved = pin.Inertia.FromDynamicParameters(phi)
    assert moved.mass == pytest.approx(5.0)
    np.testing.assert_allclose(moved.lever, tcp.act(np.array([0.01, 0.02, 0.1])), atol=1e-12)
    np.testing.assert_allclose(tcp.actInv(moved).inertia, np.array(inertia), atol=1e-12)
    for bad, name in ((dict(mass_kg=0.0), "mass_kg"), (dict(mass_kg=float("nan")), "mass_kg"),
                      (dict(mass_kg=1.0, com_tcp=(0.0, 0.1)), "com_tcp"),
                      (dict(mass_kg=1.0, inertia_com=((1, 0, 0), (0, -1, 0), (0, 0, 1))),
                       "inertia_com"),
                      (dict(mass_kg=1.0, inertia_com=((-1e-13, 0, 0), (0, 1, 0), (0, 0, 1))),
                       "inertia_com")):
        with pytest.raises(DataError) as e:
            KnownPayload(**bad)  # type: ignore[arg-type]
        assert e.value.field == f"known_payload.{name}"


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_payload_regressor_reads_the_payloads_torque_exactly(seed: int) -> None:
    """Times the payload's own parameters, the payload's columns give the torque the drives
    read: (y + f_cL·sgn(q̇)·(|τ_load + y| − |τ_load|))/c, for any state, including y = 0."""
    rng = np.random.default_rng(seed)
    samples, n = 40, 6
    K = rng.normal(size=(samples, n, 10 + n))
    K[:3] = 0.0                                            # y = 0 somewhere
    system = PayloadSystem(K, np.zeros((samples, n)), np.ones((samples, n), dtype=bool),
                           np.arange(10 + n), rng.normal(scale=5.0, size=(samples, n)),
                           rng.choice([-1.0, 0.0, 1.0], size=(samples, n)))
    phi = rng.normal(size=10)
    gain, mu = rng.uniform(0.9, 1.1, n), rng.uniform(0.0, 0.2, n)
    y = K[:, :, :10] @ phi
    tau = system.load_torque
    expected = (y + mu * system.velocity_sign * (np.abs(tau + y) - np.abs(tau))) / gain
    got = payload_regressor(system, phi, gain, mu)
    np.testing.assert_allclose(got[:, :, :10] @ phi, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got[:, :, 10:], K[:, :, 10:])     # the Coulomb columns stay
    np.testing.assert_array_equal(system.regressor, K)              # the input is not changed


def test_drive_gains_file_round_trip_and_refusals(er20: Robot, tmp_path) -> None:
    """A gains file reads back bit for bit (a joint not loaded: inf standard error, not
    applied); each bad entry is refused naming its field."""
    from leadthrough.estimation.drive_gains import DriveGains
    from leadthrough.estimation.drive_gains_file import load_drive_gains, save_drive_gains

    gains = DriveGains(robot=er20.name, gain=GAIN.copy(),
                       gain_std=np.array([np.inf, 1e-3, 2e-3, 5e-2, 4e-3, np.inf]),
                       load_friction=np.array([0.0, 0.08, 0.05, 0.0, 0.07, 0.0]),
                       applied=np.array([False, True, True, False, True, False]),
                       known=KnownPayload(20.0, (0.0, 0.0, 0.08), ((0.02, 0, 0), (0, 0.02, 0),
                                                                   (0, 0, 0.02))),
                       reference_shift_s=-0.25, samples=1234)
    path = save_drive_gains(tmp_path / "g.toml", er20, gains, sim_seed=7)
    read, seed = load_drive_gains(path, er20)
    assert seed == 7 and read.robot == er20.name and read.samples == 1234
    for name in ("gain", "gain_std", "load_friction", "applied"):
        np.testing.assert_array_equal(getattr(read, name), getattr(gains, name))
    np.testing.assert_array_equal(read.known.inertia(), gains.known.inertia())
    assert read.known.com_tcp == (0.0, 0.0, 0.08) and read.reference_shift_s == -0.25
    text = path.read_text()
    first = er20.joint_names[0]
    cases = [
        (text.replace('robot = "er20"', 'robot = "ur5"'), "meta.robot"),
        (text.replace("applied = false", 'applied = "no"', 1), f"joints.{first}.applied"),
        (text.replace("gain_std = inf", "gain_std = -1.0", 1), f"joints.{first}.gain_std"),
        (text.replace("load_friction = 0.0", "load_friction = 1.5", 1),
         f"joints.{first}.load_friction"),
        (text.replace(f"[joints.{first}]", "[joints.nothing]"), f"joints.{first}"),
        (text.replace("known_mass_kg = 20.0", "known_mass_kg = -2.0"), "meta.known_mass_kg"),
        (text.replace("sim_seed = 7", "sim_seed = -7"), "meta.sim_seed"),
    ]
    for bad_text, field in cases:
        bad = tmp_path / "bad.toml"
        bad.write_text(bad_text)
        with pytest.raises(DataError) as e:
            load_drive_gains(bad, er20)
        assert e.value.field == field and e.value.source == str(bad)
