"""The calibration recipe (``identification.calibration.calibrate``) and the check that
parameters can guide (``ready_to_guide``): what ``leadthrough identify``, the demo and the
simulator's shipped parameters share."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_COMMAND_LAG_S
from leadthrough.errors import DataError
from leadthrough.excitation.design import ExcitationConfig, design_excitation
from leadthrough.identification.calibration import calibrate, ready_to_guide
from leadthrough.identification.command_lag import measure_command_lag
from leadthrough.identification.params_file import ParamsFile
from leadthrough.identification.presliding import fit_presliding
from leadthrough.robot.description import Robot
from leadthrough.sim.calibration_set import SimRecording, record_excitation
from leadthrough.sim.robot import SimConfig

#: Commands shifted this many samples ahead of the positions: a lag of 3 ms at 1 kHz.
LEAD_SAMPLES = 3


@pytest.fixture(scope="module")
def excitation(er20: Robot) -> Recording:
    """A short excitation of the simulated er20 (instance 1) whose logged commands lead the
    positions by :data:`LEAD_SAMPLES` (the in-process simulator's own lag is 0)."""
    exc = design_excitation(er20, ExcitationConfig(starts=1, seed=0, max_iterations=20))
    rec = record_excitation(er20, exc, 6.0, SimConfig(seed=1, run=0)).measured
    assert rec.q_cmd is not None
    q_cmd = np.vstack([rec.q_cmd[LEAD_SAMPLES:], np.repeat(rec.q_cmd[-1:], LEAD_SAMPLES, 0)])
    return replace(rec, q_cmd=q_cmd)


@pytest.fixture(scope="module")
def presliding_test(presliding_test_run: SimRecording) -> Recording:
    """A presliding test of the same instance (conftest's, shared with test_presliding)."""
    return presliding_test_run.measured


def _synthetic(n: int) -> Recording:
    t = np.arange(200, dtype=np.float64) * 1e-3
    q = np.outer(np.sin(t), np.ones(n))
    return Recording(time=t, q=q, current=np.zeros_like(q), q_cmd=q)


def test_a_friction_sweep_needs_the_consistent_method(er20: Robot) -> None:
    rec = _synthetic(er20.n)
    with pytest.raises(DataError, match="consistent method only") as e:
        calibrate(rec, er20, "ols-cv", friction_sweep=rec)
    assert e.value.field == "method" and e.value.value == "ols-cv"


def test_calibrate_applies_the_presliding_fit_and_the_measured_lag(
        er20: Robot, excitation: Recording, presliding_test: Recording, tmp_path: Path) -> None:
    # without logged commands nor a presliding test, the recipe is the identification alone
    plain = calibrate(replace(excitation, q_cmd=None), er20, "ols-cv")
    assert plain.command_lag is None and plain.presliding is None
    assert plain.params.command_lag == 0.0 and plain.params.presliding.size == 0
    cal = calibrate(excitation, er20, "ols-cv", presliding_test=presliding_test)
    fit = fit_presliding(presliding_test, er20)
    lag = measure_command_lag(excitation)
    assert lag is not None and lag.lag_s == pytest.approx(LEAD_SAMPLES * 1e-3, abs=5e-4)
    assert cal.command_lag is not None and cal.command_lag.lag_s == lag.lag_s
    assert cal.params.command_lag == lag.lag_s
    np.testing.assert_array_equal(cal.params.phi, plain.params.phi)
    np.testing.assert_array_equal(cal.params.coulomb, plain.params.coulomb)
    np.testing.assert_array_equal(cal.params.presliding, fit.presliding)
    np.testing.assert_array_equal(cal.params.presliding_relaxation, fit.relaxation)
    assert cal.result.stats.J == plain.result.stats.J
    assert cal.sweep is None and not cal.friction_sweep
    # saved as returned: the lag and each joint's z0 in the file, no sweep
    text = cal.save(tmp_path / "p.toml", er20, sim_seed=1).read_text()
    assert f"command_lag = {lag.lag_s!r}" in text and "friction_sweep" not in text
    assert text.count("presliding = ") == er20.n
    pf = cal.params_file(tmp_path / "p.toml", 1)
    assert pf.params is cal.params and pf.J == plain.result.J and not pf.friction_sweep


def test_parameters_without_a_sweep_cannot_guide_unless_allowed(
        nominal_params: ParamsFile) -> None:
    with pytest.raises(DataError, match="cannot guide") as e:
        ready_to_guide(nominal_params)
    assert e.value.field == "meta.friction_sweep" and "allow_no_sweep=True" in str(e.value)
    assert ready_to_guide(nominal_params, allow_no_sweep=True) is nominal_params
    swept = replace(nominal_params, friction_sweep=True)
    assert ready_to_guide(swept) is swept


@pytest.mark.parametrize("bad", [float("nan"), -1e-3, MAX_COMMAND_LAG_S * 1.01, float("inf")])
def test_a_command_lag_out_of_range_is_refused(nominal_params: ParamsFile, bad: float) -> None:
    with pytest.raises(DataError, match="out of range") as e:
        ready_to_guide(nominal_params, allow_no_sweep=True, command_lag=bad)
    assert e.value.field == "command_lag"


def test_a_given_command_lag_replaces_the_measured_one(nominal_params: ParamsFile) -> None:
    pf = ready_to_guide(nominal_params, allow_no_sweep=True, command_lag=0.004)
    assert pf.params.command_lag == 0.004 and nominal_params.params.command_lag == 0.0
    np.testing.assert_array_equal(pf.params.phi, nominal_params.params.phi)
