"""Logs split over several files, time alignment, and the UR5 F/T validation on real data."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from leadthrough.data.align import estimate_lag, resample
from leadthrough.data.io import load_recording
from leadthrough.data.recording import Recording
from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.errors import DataError, DataWarning
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.estimation.estimator import EstimatorStatus as Status
from leadthrough.estimation.replay import replay
from leadthrough.identification.api import IdentificationResult
from leadthrough.robot import Robot

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
UR5 = ROOT / "examples" / "real" / "ur5"
HAS_DATA = (SHARED / "ur5-ft").is_dir()
needs_data = pytest.mark.skipif(not HAS_DATA, reason="../shared/data/ur5-ft not available")

_SPLIT_MAP = ('delimiter = ","\ndrop_unterminated_last_row = true\n[time]\ncolumn = 0\n'
              '[q]\nfile = "q.csv"\ncolumns = [1, 2]\n'
              '[current]\nfile = "i.csv"\ncolumns = [1, 2]\nunit = "mA"\n')


def _split_log(folder: Path) -> Path:
    """q every 10 ms for 0..0.19 s, current every 10 ms from 0.05 s, last line cut off."""
    folder.mkdir()
    (folder / "q.csv").write_text("".join(f"{0.01 * k:.6f}, {k}, {-k}\n" for k in range(20)))
    (folder / "i.csv").write_text(
        "".join(f"{0.01 * k:.6f}, {100 * k}, 7\n" for k in range(5, 25)) + "0.250000, 25, 7")
    cmap = folder.parent / "map.toml"
    cmap.write_text(_SPLIT_MAP)
    return cmap


def test_split_log_joins_files_on_time(tmp_path: Path) -> None:
    cmap = _split_log(tmp_path / "run")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_recording(tmp_path / "run", cmap)
    messages = " | ".join(str(w.message) for w in caught)
    assert "unterminated last line" in messages and "dropped 5 of 20 rows" in messages
    np.testing.assert_allclose(rec.time, 0.01 * np.arange(5, 20), atol=1e-12)
    np.testing.assert_array_equal(rec.q[:, 0], np.arange(5, 20))
    assert rec.current is not None
    np.testing.assert_allclose(rec.current[:, 0], 0.1 * np.arange(5, 20))  # mA → A, same row


@pytest.mark.parametrize("text, field", [
    (_SPLIT_MAP.replace('file = "i.csv"\n', ""), "current.file"),
    (_SPLIT_MAP.replace('"q.csv"', '"../q.csv"'), "q.file"),
    (_SPLIT_MAP.replace('[time]\ncolumn = 0\n', '[time]\ncolumn = 0\nfile = "q.csv"\n'),
     "time.file"),
    (_SPLIT_MAP.replace('"i.csv"', '"missing.csv"'), "current.file"),
])
def test_bad_split_maps_name_the_field(tmp_path: Path, text: str, field: str) -> None:
    cmap = _split_log(tmp_path / "run")
    cmap.write_text(text)
    with pytest.raises(DataError) as e, warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        load_recording(tmp_path / "run", cmap)
    assert e.value.field == field


def test_split_log_needs_its_folder(tmp_path: Path) -> None:
    cmap = _split_log(tmp_path / "run")
    with pytest.raises(DataError, match="folder"):
        load_recording(tmp_path / "run" / "q.csv", cmap)


def test_lag_recovered_between_differently_sampled_logs() -> None:
    rng = np.random.default_rng(3)
    t_a = np.arange(0.0, 20.0, 0.008)
    t_b = np.cumsum(rng.uniform(0.0045, 0.005, 4500))               # jittered, ~210 Hz
    knots = np.arange(-1.0, 22.0, 0.25)
    pulses = rng.uniform(0, 1, knots.size) ** 4 * 50.0               # sparse pushes [N]

    def signal(t: np.ndarray) -> np.ndarray:
        return np.interp(t, knots, pulses)

    true_lag = 0.0837                          # sample t + lag of b belongs to t of a
    a = signal(t_a) + rng.normal(0, 2.0, t_a.size)
    b = signal(t_b - true_lag)
    est = estimate_lag(t_a, a, t_b, b, max_lag_s=0.3, step_s=0.004)
    assert abs(est.lag_s - true_lag) < 0.002 and est.correlation > 0.9 and not est.at_limit
    two = estimate_lag(t_a, np.column_stack([a, -a]), t_b, np.column_stack([b, -b]), 0.3)
    assert abs(two.lag_s - true_lag) < 0.004
    line = np.column_stack([3.0 * t_b + 1.0, -t_b])                 # exact for linear data
    np.testing.assert_allclose(resample(t_b, line, t_a[10:60]), np.column_stack(
        [3.0 * t_a[10:60] + 1.0, -t_a[10:60]]), atol=1e-9)


@pytest.mark.parametrize("kwargs, field", [
    ({"x_other": np.zeros((50, 2))}, "x_other"),
    ({"t_ref": np.zeros(50)}, "x_ref time"),
    ({"max_lag_s": -1.0}, "max_lag_s"),
    ({"t_other": np.arange(50) + 1e3}, "max_lag_s"),                # no overlap
])
def test_lag_rejects_bad_input(kwargs: dict, field: str) -> None:
    t = np.arange(50) * 0.01
    args = {"t_ref": t, "x_ref": np.sin(t * 9), "t_other": t, "x_other": np.sin(t * 9),
            "max_lag_s": 0.1} | kwargs
    with pytest.raises(DataError) as e:
        estimate_lag(**args)
    assert e.value.field == field


def test_replay_feeds_every_sample_and_checks_the_rate(er20: Robot) -> None:
    est = ExternalForceEstimator(er20, nominal_drive_parameters(er20), np.zeros(er20.n),
                                 EstimatorConfig(dt=0.004, warm_up_s=0.1))
    t = np.arange(100, dtype=float) * 0.004
    q = np.tile(er20.neutral(), (100, 1))
    rec = Recording(time=t, q=q, torque=np.zeros((100, er20.n)))
    out = replay(est, rec)
    assert out.wrench.shape == (100, 6) and out.tau_ext.shape == (100, er20.n)
    assert out.status[0] == Status.WARMING_UP and out.status[-1] == Status.OK
    with pytest.raises(DataError) as e:
        replay(est, Recording(time=t * 2.0, q=q, torque=np.zeros((100, er20.n))))
    assert e.value.field == "time"


@pytest.fixture(scope="module")
def ur5() -> dict:
    """The UR5, its runs, and ols-cv / consistent models identified on No9_NoDist."""
    if not HAS_DATA:
        pytest.skip("../shared/data/ur5-ft not available")
    sys.path.insert(0, str(UR5))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import ft_sensor

    from ur5_ft import identify_on

    robot = ft_sensor.load_ur5()
    data = SHARED / "ur5-ft"
    recs = {n: ft_sensor.load_run(data, n) for n in ("No9", "No10_All", "No9_NoDist")}
    ids: dict[str, IdentificationResult] = identify_on(
        robot, [recs["No9_NoDist"]], ("ols-cv", "consistent"))
    fts = {n: ft_sensor.load_ft_log(data / ft_sensor.RUNS[n]) for n in ("No9", "No10_All")}
    return {"robot": robot, "recs": recs, "ids": ids, "fts": fts, "mod": ft_sensor}


@needs_data
def test_real_ur5_split_logs_load_uniformly(ur5: dict) -> None:
    rec = ur5["recs"]["No9"]
    assert rec.n == 6 and rec.signal == "current" and rec.samples == 4296
    np.testing.assert_allclose(np.diff(rec.time), 0.008, atol=1e-9)   # estimator's fixed dt


@needs_data
def test_ft_alignment_matches_independent_value_and_recovers_a_shift(ur5: dict) -> None:
    mod, robot, rec = ur5["mod"], ur5["robot"], ur5["recs"]["No9"]
    t, f = mod.offline_force_tool(robot, ur5["ids"]["ols-cv"].params, rec)
    aligned, lag = mod.align_ft(ur5["fts"]["No9"], t, f)
    # the dataset's own notes found the F/T at t_robot + 0.0896 s (another estimate, same idea)
    assert abs(aligned.offset_s - 0.0896) < 0.01 and not lag.at_limit
    moved, lag2 = mod.align_ft(ur5["fts"]["No9"].shifted(-0.1), t, f)   # artificial 100 ms
    assert abs((lag2.lag_s - lag.lag_s) - 0.1) < 0.004
    assert abs(moved.offset_s - aligned.offset_s) < 0.004


@needs_data
def test_estimate_and_sensor_share_frame_sign_and_units(ur5: dict) -> None:
    """Force on the robot in tool0 axes = +F_sensor: positive correlation and unit slope on Fz."""
    from ur5_ft import estimate

    rec = ur5["recs"]["No9"]
    truth = ur5["fts"]["No9"].shifted(0.08).force_tool(rec.time)
    w = estimate(ur5["robot"], ur5["ids"]["consistent"], rec, "direct", "force", True)[:, :3]
    corr = [np.corrcoef(truth[:, j], w[:, j])[0, 1] for j in range(3)]
    assert min(corr) > 0.4 and corr[2] > 0.85
    assert 0.8 < np.polyfit(truth[:, 2], w[:, 2], 1)[0] < 1.25     # drive gains, N, frame


@needs_data
def test_consistent_beats_plain_ols_on_standstill_pushes_along_x(ur5: dict) -> None:
    """No10_All (pushes in all directions at rest): ours is clearly better on Fx and better
    overall (the ratio the README reports; the 0.7 goal is not met, and Fy is 6 % worse)."""
    from ur5_ft import estimate

    rec = ur5["recs"]["No10_All"]
    truth = ur5["fts"]["No10_All"].force_tool(rec.time)
    err = {m: np.sqrt(np.mean((estimate(ur5["robot"], ur5["ids"][m], rec, "direct", "force",
                                        m == "consistent")[:, :3] - truth) ** 2, axis=0))
           for m in ("consistent", "ols-cv")}
    ratio = err["consistent"] / err["ols-cv"]
    assert ratio[0] < 0.9                       # measured 0.84
    assert np.sqrt(np.mean(ratio**2)) < 1.0     # better overall: measured 0.93 (Fy 1.06)
