"""The friction check: a short sweep rescales identified friction that has drifted (a robot
calibrated cold, guided warm, or the other way round)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leadthrough.dynamics.friction import StribeckParameters, stribeck_friction
from leadthrough.dynamics.model import (
    DriveModelParameters,
    FrictionModel,
    nominal_drive_parameters,
)
from leadthrough.errors import DataError
from leadthrough.excitation.friction_sweep import FRICTION_CHECK, design_friction_sweep
from leadthrough.identification.friction_refresh import refresh_friction
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import load_params, save_params
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import SimRecording, record_friction_sweep
from leadthrough.sim.robot import SimConfig, SimRobot

#: The drift the tests put into the model: friction identified cold is this much too high
#: (level part, viscous part; ratios of the published cold/warm range).
COLD_LEVEL = np.array([1.5, 1.3, 1.6, 1.4, 1.7, 1.5])
COLD_VISCOUS = np.array([1.8, 2.0, 1.6, 1.9, 1.7, 2.1])
GUIDING_SPEEDS = np.geomspace(0.02, 0.3, 12)


@pytest.fixture(scope="module")
def check(er20: Robot) -> SimRecording:
    # the ideal plant: its friction is eq. 15, so a known scaling of it is a known drift (the
    # realistic plant's drift is measured by benchmarks/friction_drift.py)
    return record_friction_sweep(er20, seed=1, run=4, q_start=guide_start_pose(er20),
                                 sweep_config=FRICTION_CHECK, plant="ideal")


def _true_eq15(robot: Robot) -> StribeckParameters:
    """The simulated drives' friction closest to eq. 15 (to report errors against)."""
    return StribeckParameters(**SimRobot(robot, SimConfig(seed=1, plant="ideal"))
                              .truth.drive.equivalent_eq15())


def _scaled(robot: Robot, level: np.ndarray, viscous: np.ndarray) -> DriveModelParameters:
    t = _true_eq15(robot)
    st = StribeckParameters(f1=t.f1 * level, f2=t.f2 * level, qd_sm=t.qd_sm, f3=t.f3 * level,
                            qd_sg=t.qd_sg, f4=t.f4 * viscous)
    return replace(nominal_drive_parameters(robot), friction_model=FrictionModel.STRIBECK,
                   stribeck=st)


def _error_at_guiding_speeds(robot: Robot, p: DriveModelParameters) -> np.ndarray:
    """Largest relative friction error per joint over 0.02–0.3 rad/s, against the truth."""
    assert p.stribeck is not None
    qd = np.repeat(GUIDING_SPEEDS[:, None], robot.n, axis=1)
    truth = stribeck_friction(qd, robot.gear_ratio, _true_eq15(robot))
    model = stribeck_friction(qd, robot.gear_ratio, p.stribeck)
    return np.max(np.abs(model / truth - 1.0), axis=0)


def test_the_check_is_short(er20: Robot) -> None:
    sweep = design_friction_sweep(er20, guide_start_pose(er20), FRICTION_CHECK)
    assert sweep.duration_s < 20.0 and sweep.speeds.shape[0] == 4


def test_a_cold_calibration_is_brought_back_to_the_robots_friction(
        er20: Robot, check: SimRecording) -> None:
    cold = _scaled(er20, COLD_LEVEL, COLD_VISCOUS)
    done = refresh_friction(cold, check.measured, er20)
    # the level part's scale is found to 7 % on every joint
    np.testing.assert_allclose(done.level_scale * COLD_LEVEL, 1.0, atol=0.07)
    # at guiding speeds: 30-70 % too high before, within 10 % after
    before = _error_at_guiding_speeds(er20, cold)
    after = _error_at_guiding_speeds(er20, done.params)
    assert np.all(before > 0.29) and np.all(after < 0.10), (before, after)
    assert np.all(done.error_after < 0.5 * done.error_before)
    # the shape is kept: Stribeck velocities and links unchanged
    assert done.params.stribeck is not None and cold.stribeck is not None
    np.testing.assert_array_equal(done.params.stribeck.qd_sm, cold.stribeck.qd_sm)
    np.testing.assert_array_equal(done.params.phi, cold.phi)


def test_a_current_model_is_left_alone(er20: Robot, check: SimRecording) -> None:
    first = refresh_friction(_scaled(er20, COLD_LEVEL, COLD_VISCOUS), check.measured, er20)
    again = refresh_friction(first.params, check.measured, er20)
    np.testing.assert_allclose(again.level_scale, 1.0, atol=0.02)
    np.testing.assert_allclose(again.viscous_scale, 1.0, atol=0.02)


def test_a_viscous_part_far_off_ends_at_its_bound_and_says_so(
        er20: Robot, check: SimRecording) -> None:
    # the level part right, the viscous part 16 times too high (the sweep-based split between
    # Stribeck and viscous friction can be far off): not an error, b at its bound, a kept
    level = np.ones(6)
    done = refresh_friction(_scaled(er20, level, np.full(6, 16.0)), check.measured, er20)
    fitted = done.separable
    assert fitted.any()
    np.testing.assert_array_equal(done.viscous_at_bound, fitted)
    np.testing.assert_allclose(done.viscous_scale[fitted], 0.25, rtol=1e-6)
    np.testing.assert_allclose(done.level_scale, 1.0, atol=0.1)
    assert np.all(done.error_after[fitted] < 0.25 * done.error_before[fitted])
    # without the viscous part in question nothing is at a bound
    assert not refresh_friction(_scaled(er20, level, level), check.measured,
                                er20).viscous_at_bound.any()


def test_a_model_far_off_is_an_error_not_a_drift(er20: Robot, check: SimRecording) -> None:
    with pytest.raises(DataError) as e:
        refresh_friction(_scaled(er20, np.full(6, 8.0), np.full(6, 8.0)), check.measured, er20)
    assert "friction scale" in str(e.value.field) and e.value.expected is not None
    assert e.value.value > 0.0
    with pytest.raises(DataError) as e:  # no eq. 15 friction to rescale
        refresh_friction(nominal_drive_parameters(er20), check.measured, er20)
    assert e.value.field == "friction_model"


def test_refresh_friction_command(er20: Robot, check: SimRecording, tmp_path: Path) -> None:
    from leadthrough.data.io import save_recording

    cold = _scaled(er20, COLD_LEVEL, COLD_VISCOUS)
    n = er20.n
    stats = ResidualStats(mean=np.zeros(n), std=np.ones(n), std_pct_max=np.ones(n),
                          rms=np.ones(n), rel_error_pct=1.0, J=6.0, k_omega=1.0,
                          samples=np.ones(n, dtype=np.int64))
    params = save_params(tmp_path / "cold.toml", er20, "consistent", cold, stats, sim_seed=1)
    rec = save_recording(check.measured, tmp_path / "check.parquet")
    out = tmp_path / "now.toml"
    done = subprocess.run([sys.executable, "-m", "leadthrough", "refresh-friction", str(params),
                           str(rec), "--robot", "er20", "-o", str(out), "--json"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)["joints"]
    assert [r["joint"] for r in rows] == list(er20.joint_names)
    now = load_params(out, er20)
    assert now.sim_seed == 1 and now.method == "consistent"
    np.testing.assert_array_equal(now.noise_std, np.ones(n))
    assert _error_at_guiding_speeds(er20, now.params).max() < 0.10
    # a wrong params file (friction 8x) writes nothing
    far = save_params(tmp_path / "far.toml", er20, "consistent",
                      _scaled(er20, np.full(6, 8.0), np.full(6, 8.0)), stats)
    bad = subprocess.run([sys.executable, "-m", "leadthrough", "refresh-friction", str(far),
                          str(rec), "--robot", "er20", "-o", str(tmp_path / "x.toml")],
                         capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "friction scale" in bad.stderr
    assert not (tmp_path / "x.toml").exists()


def test_excite_friction_check(tmp_path: Path) -> None:
    out = tmp_path / "check.csv"
    done = subprocess.run([sys.executable, "-m", "leadthrough", "excite", "--robot", "er20",
                           "--friction-check", "-o", str(out), "--json"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    info = json.loads(done.stdout)
    assert info["kind"] == "friction check" and info["duration_s"] < 20.0
    assert len(info["speeds_rad_s"]) == 4 and out.exists()
    both = subprocess.run([sys.executable, "-m", "leadthrough", "excite", "--robot", "er20",
                           "--friction-check", "--sweep", "-o", str(tmp_path / "x.csv")],
                          capture_output=True, text=True, check=False)
    assert both.returncode == 2 and not (tmp_path / "x.csv").exists()
