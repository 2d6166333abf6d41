"""CLI: excite → record → identify → validate, JSON keys, and bad input (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
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


def test_more_bad_inputs_exit_2_and_write_nothing(workdir: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The CLI audit's cases: each exits 2 with one line naming the field and leaves no file."""
    rec, traj = workdir / "rec0.parquet", workdir / "traj.csv"
    good = tmp_path / "good.toml"
    assert main(["identify", str(rec), "--robot", "er20", "--method", "consistent",
                 "-o", str(good)]) == 0
    capsys.readouterr()
    text = good.read_text()

    def params_with(old: str, new: str, name: str) -> Path:
        assert old in text
        path = tmp_path / name
        path.write_text(text.replace(old, new, 1))
        return path

    line = {key: next(x for x in text.splitlines() if x.startswith(key))
            for key in ("qd_sg ", "f1 ", "std = [")}
    std0 = "std = [0.0, " + line["std = ["].split(", ", 1)[1]
    cases = {
        "qd_sg": params_with(line["qd_sg "], "qd_sg = 0.0", "sg0.toml"),
        "f1": params_with(line["f1 "], "f1 = -1.0", "f1neg.toml"),
        "noise.std[0]": params_with(line["std = ["], std0, "std0.toml"),
        "joint_1.frobnicate": params_with("[joints.joint_1]", "[joints.joint_1]\nfrobnicate = 1",
                                          "unknown.toml"),
        "joints.joint_7": params_with("[joints.joint_1]", "[joints.joint_7]\nf1 = 1\n\n"
                                      "[joints.joint_1]", "extra.toml"),
    }
    for field, path in cases.items():
        assert main(["validate", str(path), str(rec), "--robot", "er20"]) == 2, field
        assert field in _err(capsys), field
    # a folder where a file is expected
    assert main(["validate", str(tmp_path), str(rec), "--robot", "er20"]) == 2
    assert "params file is a folder" in _err(capsys)
    assert main(["identify", str(tmp_path), "--robot", "er20", "-o", str(good)]) == 2
    assert "recording is a folder" in _err(capsys)
    # recorded positions far outside the joint limits (a corrupt file)
    r = load_recording(rec)
    q = r.q.copy()
    q[100, 3] = 2.26e6
    bad_rec = tmp_path / "corrupt.parquet"
    save_recording(Recording(time=r.time, q=q, current=r.current, robot="er20"), bad_rec)
    out = tmp_path / "p.toml"
    assert main(["identify", str(bad_rec), "--robot", "er20", "--method", "ols-cv",
                 "-o", str(out)]) == 2
    assert "'q4'" in (e := _err(capsys)) and "row 100" in e
    assert main(["payload", str(bad_rec), "--robot", "er20", "--params", str(good)]) == 2
    _err(capsys)
    # no rows at all
    table = pq.read_table(rec)
    pq.write_table(table.slice(0, 0), tmp_path / "empty.parquet")
    assert main(["identify", str(tmp_path / "empty.parquet"), "--robot", "er20",
                 "--method", "ols-cv", "-o", str(out)]) == 2
    assert "no rows" in _err(capsys)
    # a trajectory too fast for the robot (time squeezed by hand)
    t = traj.read_text().splitlines()
    fast = tmp_path / "fast.csv"
    head = [x for x in t if x.startswith("#") or x.startswith("time")]
    body = [x.split(",") for x in t if not (x.startswith("#") or x.startswith("time"))]
    fast.write_text("\n".join(head + [",".join([str(float(b[0]) / 10.0), *b[1:]])
                                      for b in body]) + "\n")
    assert main(["record", "--robot", "er20", "--trajectory", str(fast), "-o",
                 str(tmp_path / "fast.parquet")]) == 2
    assert "(from q and time)" in _err(capsys)
    # a CoM without a mass, or far from the tool; a mass the simulator cannot carry
    for extra, text in ((["--payload-com", "0", "0", "0.1"], "a CoM without a mass"),
                        (["--payload-mass", "5", "--payload-com", "0", "0", "100"],
                         "--payload-com"),
                        (["--payload-mass", "200"], "'--payload-mass' = 200.0: the robot "
                         "cannot carry this payload")):
        assert main(["record", "--robot", "er20", "--trajectory", str(traj), *extra,
                     "-o", str(tmp_path / "r.parquet")]) == 2
        assert text in _err(capsys)
        assert not (tmp_path / "r.parquet").exists()
    # options out of range, irrelevant, or an output of the wrong type
    assert main(["excite", "--start", "0", "0", "0", "0", "0", "0", "-o",
                 str(tmp_path / "x.csv")]) == 2
    assert "--start" in _err(capsys)
    assert main(["excite", "-o", str(tmp_path / "x.parquet")]) == 2
    assert "unsupported output file type" in _err(capsys)
    assert main(["identify", str(rec), "--robot", "er20", "-o", str(tmp_path / "p.json")]) == 2
    assert ".toml" in _err(capsys)
    for argv, field in ((["excite", "--seed", "-1"], "excitation.seed"),
                        (["excite", "--duration", "inf"], "--duration"),
                        (["excite", "--floor", "nan"], "excitation.floor_height")):
        assert main([*argv, "-o", str(tmp_path / "x.csv")]) == 2, argv
        assert field in _err(capsys), argv
    # outputs that cannot be written: a folder as the file, a URDF path that fails or
    # would overwrite the params; nothing is written, not even the params
    (tmp_path / "folder.csv").mkdir()
    assert main(["excite", "--duration", "20", "--starts", "1", "-o",
                 str(tmp_path / "folder.csv")]) == 2
    assert "is a folder" in _err(capsys)
    for urdf in (tmp_path / "missing" / "x.urdf", out):
        assert main(["identify", str(rec), "--robot", "er20", "--method", "ols-cv",
                     "-o", str(out), "--urdf-out", str(urdf)]) == 2
        _err(capsys)
        assert not out.exists()
    assert not list(tmp_path.glob("x.csv")) and not list(tmp_path.glob(".*"))


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
    from leadthrough.session_format import load_session

    rec = workdir / "rec0.parquet"
    assert load_recording(rec).sim_seed == 1
    params = tmp_path / "p.toml"
    assert main(["identify", str(rec), "--robot", "er20", "--method", "ols-cv",
                 "-o", str(params)]) == 0
    assert load_params(params, load_robot("er20")).sim_seed == 1
    session = tmp_path / "s.parquet"
    assert main(["guide", "--params", str(params), "--operator", "rest", "--duration", "1",
                 "--allow-no-sweep", "-o", str(session)]) == 0
    assert load_session(session).settings["seed"] == 1
    capsys.readouterr()
    other = tmp_path / "t.parquet"
    assert main(["guide", "--params", str(params), "--operator", "rest", "--duration", "1",
                 "--seed", "2", "--allow-no-sweep", "-o", str(other)]) == 2
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


def test_payload_against_an_unloaded_run(workdir: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """record the same trajectory with a 10 kg payload → payload --reference (the unloaded
    run) prints the library's estimate against that run, aligned with no shift; a reference
    of another simulated robot is refused (exit 2, nothing printed on stdout)."""
    from leadthrough.estimation.payload import estimate_payload
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot

    params = tmp_path / "p.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "-o", str(params)]) == 0
    loaded = tmp_path / "loaded.parquet"
    assert main(["record", "--robot", "er20", "--trajectory", str(workdir / "traj.csv"),
                 "--seed", "1", "--run", "2", "--payload-mass", "10", "--payload-com", "0", "0",
                 "0.1", "-o", str(loaded)]) == 0
    capsys.readouterr()
    base = ["payload", str(loaded), "--robot", "er20", "--params", str(params), "--json"]
    assert main(base) == 0
    alone = _json(capsys)
    assert main([*base, "--reference", str(workdir / "rec1.parquet")]) == 0
    against = _json(capsys)
    assert against["reference"] == str(workdir / "rec1.parquet") and alone["reference"] is None
    assert alone["reference_shift_s"] is None
    assert against["reference_shift_s"] == pytest.approx(0.0, abs=1e-9)
    robot = load_robot("er20")
    est = estimate_payload(load_recording(loaded), robot, load_params(params, robot).params,
                           reference=load_recording(workdir / "rec1.parquet"))
    assert against["mass_kg"] == est.mass_kg != alone["mass_kg"]
    assert abs(against["mass_kg"] - 10.0) < 0.5
    other = tmp_path / "seed2.parquet"
    assert main(["record", "--robot", "er20", "--trajectory", str(workdir / "traj.csv"),
                 "--seed", "2", "-o", str(other)]) == 0
    capsys.readouterr()
    assert main([*base, "--reference", str(other)]) == 2
    out = capsys.readouterr()
    assert out.out == "" and "sim_seed" in out.err and str(other) in out.err


def test_drive_gains_with_a_known_mass(workdir: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """record the trajectory with a known 12 kg → drive-gains against the unloaded run writes
    the gains file (as the library measures them: over 20 s some joint's gain to 1 %);
    payload --drive-gains prints the library's estimate through the file's gains. A bad mass,
    a gains file out of range or of another simulated robot: exit 2, naming the field, nothing
    written or printed."""
    from leadthrough.estimation.drive_gains import KnownPayload, estimate_drive_gains
    from leadthrough.estimation.drive_gains_file import load_drive_gains
    from leadthrough.estimation.payload import estimate_payload
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot

    params = tmp_path / "p.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "-o", str(params)]) == 0
    known, loaded = tmp_path / "known.parquet", tmp_path / "loaded.parquet"
    for path, run, mass, com in ((known, "3", "12", ("0.03", "0", "0.12")),
                                 (loaded, "2", "10", ("0", "0", "0.1"))):
        assert main(["record", "--robot", "er20", "--trajectory", str(workdir / "traj.csv"),
                     "--seed", "1", "--run", run, "--payload-mass", mass, "--payload-com",
                     *com, "-o", str(path)]) == 0
    capsys.readouterr()
    unloaded, gains_file = workdir / "rec1.parquet", tmp_path / "gains.toml"
    base = ["drive-gains", str(known), "--reference", str(unloaded), "--robot", "er20",
            "--params", str(params), "--com", "0.03", "0", "0.12"]
    assert main([*base, "--mass", "0", "-o", str(gains_file)]) == 2
    assert "--mass" in capsys.readouterr().err and not gains_file.exists()
    assert main([*base, "--mass", "12", "--inertia", "0.1", "-0.1", "0.1",
                 "-o", str(gains_file)]) == 2
    err = capsys.readouterr().err
    assert "--inertia" in err and "-0.1" in err and not gains_file.exists()
    assert main([*base, "--mass", "12", "-o", str(gains_file), "--json"]) == 0
    out = _json(capsys)
    robot = load_robot("er20")
    model = load_params(params, robot).params
    lib = estimate_drive_gains(load_recording(known), load_recording(unloaded), robot, model,
                               KnownPayload(12.0, (0.03, 0.0, 0.12)))
    assert out["gain"] == lib.gain.tolist() and out["applied"] == lib.applied.tolist()
    assert any(out["applied"]) and out["output"] == str(gains_file)
    read, seed = load_drive_gains(gains_file, robot)
    assert seed == 1
    np.testing.assert_array_equal(read.gain, lib.gain)
    np.testing.assert_array_equal(read.gain_std, lib.gain_std)
    np.testing.assert_array_equal(read.load_friction, lib.load_friction)
    pay = ["payload", str(loaded), "--robot", "er20", "--params", str(params), "--reference",
           str(unloaded), "--json"]
    assert main([*pay, "--drive-gains", str(gains_file)]) == 0
    through = _json(capsys)
    est = estimate_payload(load_recording(loaded), robot, model,
                           reference=load_recording(unloaded), drive_gains=read)
    assert through["mass_kg"] == est.mass_kg and through["drive_gains"] == str(gains_file)
    assert abs(est.mass_kg - 10.0) < 0.5
    name = robot.joint_names[1]
    text = gains_file.read_text()
    bad = tmp_path / "bad.toml"
    start = text.index(f"[joints.{name}]")
    gain_at = text.index("gain = ", start)
    bad.write_text(text[:gain_at] + "gain = 2.5" + text[text.index("\n", gain_at):])
    assert main([*pay, "--drive-gains", str(bad)]) == 2
    err = capsys.readouterr()
    assert err.out == "" and f"joints.{name}.gain" in err.err and "2.5" in err.err
    bad.write_text(text.replace("sim_seed = 1", "sim_seed = 2"))
    assert main([*pay, "--drive-gains", str(bad)]) == 2
    err = capsys.readouterr()
    assert err.out == "" and "meta.sim_seed" in err.err


def test_presliding_test_excite_record_identify(workdir: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """excite --presliding → record → identify --presliding-test writes each joint's z₀ and
    relaxation rate into the params; the fit is done before the identification, so a bad
    test file fails first and writes nothing."""
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot

    pre, rec = tmp_path / "pre.csv", tmp_path / "pre.parquet"
    assert main(["excite", "--robot", "er20", "--presliding", "-o", str(pre), "--json"]) == 0
    assert _json(capsys)["trials"] == 20
    # the ideal plant: the z₀ range below is its gears' (the CLI's plumbing is under test here;
    # the fit itself on the realistic plant: tests/test_presliding.py)
    assert main(["record", "--robot", "er20", "--trajectory", str(pre), "--seed", "1",
                 "--run", "3", "--plant", "ideal", "-o", str(rec)]) == 0
    capsys.readouterr()
    out = tmp_path / "p.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "--presliding-test", str(rec), "-o", str(out), "--json"]) == 0
    fit = _json(capsys)["presliding"]
    assert fit["pairs"] >= 30
    z0 = [fit["joints"][f"joint_{k}"]["z0_rad"] for k in range(1, 7)]
    rate = [fit["joints"][f"joint_{k}"]["relaxation_per_s"] for k in range(1, 7)]
    written = load_params(out, load_robot("er20")).params
    np.testing.assert_array_equal(written.presliding, z0)
    np.testing.assert_array_equal(written.presliding_relaxation, rate)
    assert all(1e-4 < z < 3e-4 for z in z0)
    # the ideal plant's wrists relax at rest too (its servo dithers them the same way)
    assert all(0.03 < r < 0.3 for r in rate[3:])
    # the identification recording is no presliding test: exit 2, nothing written
    bad = tmp_path / "bad.toml"
    assert main(["identify", str(workdir / "rec0.parquet"), "--robot", "er20", "--method",
                 "ols-cv", "--presliding-test", str(workdir / "rec1.parquet"),
                 "-o", str(bad)]) == 2
    assert "too few out-and-back moves" in _err(capsys)
    assert not bad.exists()
    assert main(["excite", "--sweep", "--presliding", "-o", str(tmp_path / "x.csv")]) == 2
    assert "--sweep or --presliding" in _err(capsys)


def test_guide_notes_params_without_a_presliding_test(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """Guiding params with no presliding test still guide, with a note that a creeping joint
    keeps the command's friction; params whose test lacks the relaxation at rest get a note
    of their own; the shipped params (which carry both) get none."""
    from leadthrough.sim.guiding_params import shipped_params_path

    shipped = shipped_params_path("er20")
    stripped = tmp_path / "no_z0.toml"
    stripped.write_text("".join(line for line in shipped.read_text().splitlines(True)
                                if not line.startswith("presliding")))
    older = tmp_path / "no_relaxation.toml"
    older.write_text("".join(line for line in shipped.read_text().splitlines(True)
                             if not line.startswith("presliding_relaxation")))
    for params, note in ((shipped, ""), (stripped, "carries no presliding test"),
                         (older, "carries no relaxation of the friction at rest")):
        capsys.readouterr()
        assert main(["guide", "--params", str(params), "--operator", "rest", "--duration", "1",
                     "-o", str(tmp_path / f"{params.stem}.parquet")]) == 0
        err = capsys.readouterr().err
        assert ("leadthrough: note:" in err) is bool(note)
        if note:
            assert note in err and str(params) in err and "--presliding-test" in err
