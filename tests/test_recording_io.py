"""Recordings: validation, CSV/Parquet round trips, column maps, real logs."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from leadthrough.data.io import load_recording, save_recording
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError, DataWarning
from leadthrough.robot import Robot

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"


def _rec(n: int = 3, N: int = 50) -> Recording:
    rng = np.random.default_rng(0)
    t = np.arange(N) * 1e-3
    return Recording(time=t, q=rng.normal(size=(N, n)), current=rng.normal(size=(N, n)),
                     q_cmd=rng.normal(size=(N, n)), robot="er20")


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_is_exact(tmp_path: Path, suffix: str) -> None:
    rec = _rec()
    path = save_recording(rec, tmp_path / f"r{suffix}")
    back = load_recording(path)
    assert back.robot == "er20"
    for name in ("time", "q", "current", "q_cmd"):
        assert np.array_equal(getattr(back, name), getattr(rec, name))
    assert back.torque is None


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_simulated_robot_instance_round_trips(tmp_path: Path, suffix: str) -> None:
    from dataclasses import replace

    path = save_recording(replace(_rec(), sim_seed=4), tmp_path / f"r{suffix}")
    assert load_recording(path).sim_seed == 4
    assert load_recording(save_recording(_rec(), tmp_path / f"real{suffix}")).sim_seed is None
    for bad in (-1, True):  # True is an int to Python, not a robot instance
        with pytest.raises(DataError, match="sim_seed"):
            replace(_rec(), sim_seed=bad)


def test_malformed_sim_seed_in_a_csv_header_is_a_clear_error(tmp_path: Path) -> None:
    path = save_recording(_rec(), tmp_path / "r.csv")
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0], lines[1], "# sim_seed: two", *lines[2:]]) + "\n")
    with pytest.raises(DataError, match=r"r\.csv.*sim_seed.*two"):
        load_recording(path)


def test_csv_header_has_units(tmp_path: Path) -> None:
    path = save_recording(_rec(2), tmp_path / "r.csv")
    header = path.read_text().splitlines()[2]
    assert header.startswith("time [s],q1 [rad],q2 [rad],current1 [A]")


def test_nan_rows_dropped_with_warning(tmp_path: Path) -> None:
    path = save_recording(_rec(), tmp_path / "r.csv")
    lines = path.read_text().splitlines()
    lines[5] = ",".join(["nan", *lines[5].split(",")[1:]])
    lines[9] = lines[9].replace(lines[9].split(",")[2], "nan", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.warns(DataWarning, match="dropped 2 of 50 rows"):
        back = load_recording(path)
    assert back.samples == 48


@pytest.mark.parametrize("kwargs, field", [
    ({"time": np.array([0.0, 0.1, 0.1])}, "time"),
    ({"q": np.zeros((2, 3))}, "q"),
    ({"current": np.zeros((3, 2))}, "current"),
    ({"current": None}, "current/torque"),
])
def test_invalid_recordings(kwargs: dict, field: str) -> None:
    base = {"time": np.array([0.0, 0.1, 0.2]), "q": np.zeros((3, 3)), "current": np.zeros((3, 3))}
    base.update(kwargs)
    with pytest.raises(DataError) as e:
        Recording(**base)
    assert e.value.field == field


def test_joint_count_checked_against_robot(er20) -> None:
    with pytest.raises(DataError, match="joint count"):
        _rec(3).check_robot(er20)


def test_corrupt_parquet(tmp_path: Path) -> None:
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(b"PAR1 this is not parquet")
    with pytest.raises(DataError, match="Parquet"):
        load_recording(bad)


def test_missing_file_and_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="not found"):
        load_recording(tmp_path / "nope.csv")
    other = tmp_path / "x.dat"
    other.write_text("1,2\n")
    with pytest.raises(DataError, match="column map"):
        load_recording(other)


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    with pytest.raises(DataError):
        save_recording(_rec(), tmp_path / "r.xlsx")
    assert list(tmp_path.iterdir()) == []


def test_column_map_with_units_and_scale(tmp_path: Path) -> None:
    log = tmp_path / "log.txt"
    rows = [[1000.0 * k, 10.0 * k, 20.0 * k, 0.5, 1.5] for k in range(20)]
    log.write_text("t;a;b;c;d\n" + "\n".join(";".join(map(str, r)) for r in rows))
    cmap = tmp_path / "map.toml"
    cmap.write_text('delimiter = ";"\nskip_rows = 1\n[time]\ncolumn = 0\nunit = "ms"\n'
                    '[q]\ncolumns = [1, 2]\nunit = "deg"\n'
                    '[torque]\ncolumns = [3, 4]\nscale = [2.0, -1.0]\nunit = "N·m"\n')
    rec = load_recording(log, cmap)
    np.testing.assert_allclose(rec.time, np.arange(20.0))
    np.testing.assert_allclose(rec.q[3], np.deg2rad([30.0, 60.0]))
    np.testing.assert_allclose(rec.torque[0], [1.0, -1.5])


@pytest.mark.parametrize("text, field", [
    ('[time]\ncolumn = 0\n[q]\ncolumns = [1]\n', "current/torque"),
    ('[time]\ncolumn = 0\n[q]\ncolumns = [1]\nunit = "grad"\n[current]\ncolumns = [2]\n',
     "q.unit"),
    ('[time]\ncolumn = 0\n[q]\ncolumns = [1, 2]\n[current]\ncolumns = [3]\n',
     "current.columns"),
])
def test_bad_column_maps(tmp_path: Path, text: str, field: str) -> None:
    log = tmp_path / "log.csv"
    log.write_text("0,1,2,3\n1,1,2,3\n")
    cmap = tmp_path / "map.toml"
    cmap.write_text(text)
    with pytest.raises(DataError) as e:
        load_recording(log, cmap)
    assert e.value.field == field and str(cmap) in str(e.value)


@pytest.mark.skipif(not (SHARED / "ur10e").is_dir(), reason="../shared/data not available")
def test_real_ur10e_logs_load_as_they_are() -> None:
    cmap = ROOT / "examples" / "real" / "ur10e" / "columns.toml"
    rec = load_recording(SHARED / "ur10e/identification/ur-20_02_10-30sec_12harm.csv", cmap)
    assert rec.n == 6 and rec.samples > 3000 and rec.signal == "current"
    assert 0.009 < np.median(np.diff(rec.time)) < 0.012  # ~100 Hz
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bad = load_recording(SHARED / "ur10e/identification/ur-20_02_19_15harm50secLoad.csv",
                             cmap)
    assert any("dropped" in str(w.message) for w in caught)  # garbage rows counted
    assert np.all(np.diff(bad.time) > 0) and np.abs(bad.q).max() < 10


def test_joint_range_errs_on_corrupt_positions_and_warns_on_a_convention_mismatch(
        er20: Robot) -> None:
    """A position half a turn or more outside the limits is an error naming column and row; a
    smaller excess only warns (the column map's offsets may use another convention than the
    robot file's limits)."""
    t = np.arange(50) * 1e-3
    q = np.tile(0.5 * (er20.lower_limits + er20.upper_limits), (50, 1))
    rec = Recording(time=t, q=q, current=np.zeros_like(q), robot="er20")
    rec.check_joint_range(er20)                                   # inside: silent
    q_over = q.copy()
    q_over[7, 2] = er20.upper_limits[2] + 0.4
    with pytest.warns(DataWarning, match=r"q3 = .* row 7 lies 0.4 rad outside"):
        Recording(time=t, q=q_over, current=np.zeros_like(q), robot="er20").check_joint_range(er20)
    q_over[9, 3] = 2.26e6
    with pytest.raises(DataError, match=r"field 'q4' = 2260000.0: joint position far outside"):
        Recording(time=t, q=q_over, current=np.zeros_like(q), robot="er20").check_joint_range(er20)


@pytest.mark.skipif(not (SHARED / "kr300").is_dir(), reason="../shared/data not available")
def test_real_kr300_logs_pass_the_joint_range_check_with_a_warning() -> None:
    from leadthrough.robot import load_robot

    kr300 = load_robot(str(ROOT / "examples" / "real" / "kr300" / "robot.toml"))
    cmap = ROOT / "examples" / "real" / "kr300" / "columns.toml"
    rec = load_recording(SHARED / "kr300" / "FF_A_identification.mat", cmap)
    with pytest.warns(DataWarning, match="check the column map's offsets"):
        rec.check_joint_range(kr300)
