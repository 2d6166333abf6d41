"""CLI: excite → record → identify → validate, JSON keys, and bad input (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from leadthrough.cli import main
from leadthrough.data.io import load_recording, save_recording
from leadthrough.data.recording import Recording


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short designed trajectory and two simulated recordings of it."""
    d = tmp_path_factory.mktemp("cli")
    assert main(["excite", "--robot", "er20", "--duration", "20", "--starts", "1",
                 "-o", str(d / "traj.csv")]) == 0
    for run in (0, 1):
        assert main(["record", "--robot", "er20", "--trajectory", str(d / "traj.csv"),
                     "--seed", "1", "--run", str(run), "-o", str(d / f"rec{run}.parquet")]) == 0
    return d


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


def test_excite_json_reports_condition(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    assert main(["excite", "--robot", "er20", "--duration", "10", "--starts", "1", "--json",
                 "-o", str(tmp_path / "t.csv")]) == 0
    out = _json(capsys)
    assert out["condition_number"] < 150 and out["max_velocity_ratio"] <= 0.8 + 1e-6
    assert (tmp_path / "t.csv").read_text().startswith("# leadthrough trajectory")


def test_record_is_reproducible(workdir: Path, tmp_path: Path) -> None:
    assert main(["record", "--robot", "er20", "--trajectory", str(workdir / "traj.csv"),
                 "--seed", "1", "--run", "0", "-o", str(tmp_path / "again.parquet")]) == 0
    a = load_recording(workdir / "rec0.parquet")
    b = load_recording(tmp_path / "again.parquet")
    assert np.array_equal(a.current, b.current) and a.robot == "er20"
    c = load_recording(workdir / "rec1.parquet")
    assert not np.array_equal(a.current, c.current)  # other run, other noise


@pytest.mark.parametrize("method", ["ols-cv", "ols-cbrt"])
def test_identify_and_validate_json(workdir: Path, capsys: pytest.CaptureFixture[str],
                                    method: str) -> None:
    params = workdir / f"{method}.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 method, "-o", str(params), "--json"]) == 0
    out = _json(capsys)
    assert {"method", "J", "per_joint", "runtime_s", "iterations"} <= out.keys()
    assert out["method"] == method and len(out["per_joint"]) == 6
    assert {"mean", "std", "std_pct_max"} <= out["per_joint"][0].keys()
    assert params.read_text().count('robot = "er20"') == 1
    assert main(["validate", str(params), str(workdir / "rec1.parquet"), "--robot", "er20",
                 "--json"]) == 0
    val = _json(capsys)
    assert {"method", "J", "per_joint", "rel_error_pct", "runtime_s"} <= val.keys()
    assert 0 < val["rel_error_pct"] < 20


def test_identify_proposed_json_same_keys(workdir: Path, capsys: pytest.CaptureFixture[str]
                                          ) -> None:
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "-o", str(workdir / "a.toml"), "--json"]) == 0
    keys_cv = set(_json(capsys))
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "proposed", "-o", str(workdir / "b.toml"), "--json"]) == 0
    out = _json(capsys)
    assert set(out) == keys_cv and out["iterations"] > 1


def _err(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    return err


def test_bad_inputs_exit_2(workdir: Path, tmp_path: Path,
                           capsys: pytest.CaptureFixture[str]) -> None:
    rec = workdir / "rec0.parquet"
    out = tmp_path / "p.toml"
    # joint count that does not match the robot
    assert main(["identify", str(rec), "--robot", "panda", "--method", "ols-cv",
                 "-o", str(out)]) == 2
    assert "joint count" in _err(capsys)
    # too few samples
    r = load_recording(rec)
    save_recording(r.slice(0, 30), tmp_path / "short.parquet")
    assert main(["identify", str(tmp_path / "short.parquet"), "--robot", "er20",
                 "--method", "ols-cv", "-o", str(out)]) == 2
    assert "too few samples" in _err(capsys)
    # a joint that never moves
    q = r.q.copy()
    q[:, 2] = q[0, 2]
    save_recording(Recording(time=r.time, q=q, current=r.current, robot="er20"),
                   tmp_path / "still.parquet")
    assert main(["identify", str(tmp_path / "still.parquet"), "--robot", "er20",
                 "--method", "ols-cbrt", "-o", str(out)]) == 2
    assert "joint_3' barely moves" in _err(capsys)
    # params file for another robot
    assert main(["identify", str(rec), "--robot", "er20", "--method", "ols-cv",
                 "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["validate", str(out), str(rec), "--robot", "ur5"]) == 2
    _err(capsys)
    # a duration that is not a whole number of periods
    assert main(["excite", "--duration", "15", "-o", str(tmp_path / "t.csv")]) == 2
    assert "whole number of periods" in _err(capsys)
    assert not (tmp_path / "t.csv").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.toml", "short.parquet",
                                                          "still.parquet"]


def test_identify_consistent_json_adds_pseudo_inertia(workdir: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    import pinocchio as pin

    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "-o", str(tmp_path / "a.toml"), "--json"]) == 0
    keys_cv = set(_json(capsys))
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "consistent", "-o", str(tmp_path / "c.toml"), "--urdf-out",
                 str(tmp_path / "c.urdf"), "--json"]) == 0
    out = _json(capsys)
    assert set(out) == keys_cv | {"min_pseudo_inertia_eig"}
    assert len(out["min_pseudo_inertia_eig"]) == 6
    assert min(out["min_pseudo_inertia_eig"].values()) >= 0
    assert pin.buildModelFromUrdf(str(tmp_path / "c.urdf")).nq == 6
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "proposed", "--bound", "none", "-o", str(tmp_path / "p.toml")]) == 2
    assert "finite bounds" in capsys.readouterr().err


def test_the_simulated_robot_follows_the_params(workdir: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """record --seed → the recording → identify → the params' [meta] sim_seed → guide runs on
    that robot by default and refuses another; payload refuses a recording of another one."""
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot
    from leadthrough.session.record import load_session

    rec = workdir / "rec0.parquet"
    assert load_recording(rec).sim_seed == 1
    params = tmp_path / "p.toml"
    assert main(["identify", str(rec), "--robot", "er20", "--method", "ols-cv",
                 "-o", str(params)]) == 0
    assert load_params(params, load_robot("er20")).sim_seed == 1
    session = tmp_path / "s.parquet"
    assert main(["guide", "--params", str(params), "--operator", "rest", "--duration", "1",
                 "-o", str(session)]) == 0
    assert load_session(session).settings["seed"] == 1
    capsys.readouterr()
    other = tmp_path / "t.parquet"
    assert main(["guide", "--params", str(params), "--operator", "rest", "--duration", "1",
                 "--seed", "2", "-o", str(other)]) == 2
    err = capsys.readouterr().err
    assert "--seed" in err and "2" in err and "sim_seed" in err
    assert not other.exists()
    rec2 = tmp_path / "rec_seed2.csv"
    assert main(["record", "--robot", "er20", "--trajectory", str(workdir / "traj.csv"),
                 "--seed", "2", "-o", str(rec2)]) == 0
    assert load_recording(rec2).sim_seed == 2  # CSV keeps it too
    assert main(["payload", str(rec2), "--robot", "er20", "--params", str(params)]) == 2
    assert "sim_seed" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(params.read_text().replace("sim_seed = 1", 'sim_seed = "one"'))
    assert main(["guide", "--params", str(bad), "--operator", "rest", "-o", str(other)]) == 2
    assert "meta.sim_seed" in capsys.readouterr().err


def test_presliding_test_excite_record_identify(workdir: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """excite --presliding → record → identify --presliding-test writes each joint's z₀ into
    the params; the fit is done before the identification, so a bad test file fails first
    and writes nothing."""
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot

    pre, rec = tmp_path / "pre.csv", tmp_path / "pre.parquet"
    assert main(["excite", "--robot", "er20", "--presliding", "-o", str(pre), "--json"]) == 0
    assert _json(capsys)["trials"] == 20
    assert main(["record", "--robot", "er20", "--trajectory", str(pre), "--seed", "1",
                 "--run", "3", "-o", str(rec)]) == 0
    capsys.readouterr()
    out = tmp_path / "p.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "--presliding-test", str(rec), "-o", str(out), "--json"]) == 0
    fit = _json(capsys)["presliding"]
    assert fit["pairs"] >= 30
    z0 = [fit["joints"][f"joint_{k}"]["z0_rad"] for k in range(1, 7)]
    np.testing.assert_array_equal(load_params(out, load_robot("er20")).params.presliding, z0)
    assert all(1e-4 < z < 3e-4 for z in z0)
    # the identification recording is no presliding test: exit 2, nothing written
    bad = tmp_path / "bad.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "--presliding-test", str(workdir / "rec1.parquet"),
                 "-o", str(bad)]) == 2
    assert "too few out-and-back moves" in _err(capsys)
    assert not bad.exists()
    assert main(["excite", "--sweep", "--presliding", "-o", str(tmp_path / "x.csv")]) == 2
    assert "--sweep or --presliding" in _err(capsys)
