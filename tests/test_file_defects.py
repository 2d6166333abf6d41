"""File handling, each defect reproduced through the CLI or the file APIs:

* a params file with a negative link mass (or a negative friction, or a ``consistent`` file
  whose link is no physical body) was accepted by ``validate``, ``guide`` and
  ``refresh-friction``: now exit 2 naming the file, the field, the value and the range;
* a trajectory CSV whose ``q1 [rad]`` column was renamed still recorded: now refused, naming
  the file and the column;
* an output over a symbolic link replaced the link: now refused, link and target untouched;
* outputs through ``atomic_write`` were mode 0600, session files 0644: now both ``0o666`` less
  the umask;
* a SIGKILLed session left ``<session>.parquet.partial`` that ``teach`` could not read: its
  rows, metadata and marks now recover (``leadthrough recover``) into a session file that
  ``teach`` reads, nothing written when the partial file cannot be.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from leadthrough.cli import main
from leadthrough.dynamics.model import FrictionModel
from leadthrough.errors import DataError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.trajectory_file import load_trajectory, save_trajectory
from leadthrough.fileio import atomic_write_text
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import load_params, save_params
from leadthrough.robot.description import Robot, load_robot
from leadthrough.session.session_file import SessionFileSink
from leadthrough.session_format import SessionEvent, SessionLog, load_session, save_session
from leadthrough.sim.guiding_params import shipped_params_path
from leadthrough.teach.path import forward_tcp

PARAMS = shipped_params_path("er20")


@pytest.fixture(scope="module")
def er20() -> Robot:
    return load_robot("er20")


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.fixture
def umask() -> Iterator[int]:
    old = os.umask(0o022)
    try:
        yield 0o022
    finally:
        os.umask(old)


# ------------------------------------------------------------------------------ params
def _edited(tmp_path: Path, table: str, key: str, value: str, source: Path = PARAMS) -> Path:
    """A copy of ``source`` with ``key`` of ``[table]`` set to ``value``."""
    text = source.read_text()
    head, sep, rest = text.partition(f"[{table}]\n")
    assert sep, table
    rest, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = {value}", rest, count=1)
    assert n == 1, key
    out = tmp_path / f"{table}_{key}.toml"
    out.write_text(head + sep + rest)
    return out


def test_a_negative_link_mass_is_refused_by_validate_guide_and_refresh_friction(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = _edited(tmp_path, "links.joint_1", "m", "-66.0")
    rec = tmp_path / "rec.parquet"         # never read: the params are refused first
    commands = [
        ["validate", str(bad), str(rec), "--robot", "er20"],
        ["guide", "--robot", "er20", "--params", str(bad), "--operator", "rest",
         "--duration", "1", "-o", str(tmp_path / "s.parquet")],
        ["refresh-friction", str(bad), str(rec), "--robot", "er20", "-o",
         str(tmp_path / "now.toml")],
    ]
    for argv in commands:
        assert main(argv) == 2, argv
        err = _error(capsys)
        assert str(bad) in err and "field 'links.joint_1.m' = -66.0" in err, err
        assert "> 0 kg" in err, err
    assert not (tmp_path / "s.parquet").exists() and not (tmp_path / "now.toml").exists()
    for value in ("0.0", "nan"):
        with pytest.raises(DataError) as e:
            load_params(_edited(tmp_path, "links.joint_3", "m", value), load_robot("er20"))
        assert e.value.field == "links.joint_3.m"


def test_an_unphysical_link_and_negative_friction_are_refused(
        tmp_path: Path, er20: Robot) -> None:
    # the consistent method's file claims physical bodies: an inertia no body has
    with pytest.raises(DataError, match="pseudo-inertia") as e:
        load_params(_edited(tmp_path, "links.joint_2", "Ixx", "-50.0"), er20)
    assert e.value.field == "links.joint_2.Ixx..Izz" and e.value.source == str(
        tmp_path / "links.joint_2_Ixx.toml")
    with pytest.raises(DataError, match="out of range") as e:
        load_params(_edited(tmp_path, "joints.joint_4", "rotor_inertia", "-0.1"), er20)
    assert e.value.field == "joints.joint_4.rotor_inertia"
    # a Coulomb-viscous file (ols-cv): its links need not be physical, its friction must be
    pf = load_params(PARAMS, er20)
    params = pf.params
    cv = replace(params, friction_model=FrictionModel.COULOMB_VISCOUS, stribeck=None,
                 coulomb=np.full(6, 5.0), viscous=np.full(6, 2.0))
    stats = ResidualStats(mean=pf.noise_mean, std=pf.noise_std, std_pct_max=pf.noise_std,
                          rms=pf.noise_std, rel_error_pct=1.0, J=1.0, k_omega=1.0,
                          samples=np.zeros(6, dtype=np.int64))
    good = save_params(tmp_path / "cv.toml", er20, "ols-cv", cv, stats)
    load_params(good, er20)
    with pytest.raises(DataError) as e:
        load_params(_edited(tmp_path, "joints.joint_5", "viscous", "-3.0", good), er20)
    assert e.value.field == "joints.joint_5.viscous" and e.value.value == -3.0
    assert "N·m·s" in str(e.value)


# --------------------------------------------------------------------------- trajectory
def _traj(path: Path) -> Path:
    t = np.arange(0.0, 0.5 + 1e-9, 1e-3)
    q = np.tile([0.0, -0.3, 0.6, 0.0, 0.9, 0.0], (t.size, 1))
    z = np.zeros_like(q)
    return save_trajectory(path, TrajectorySamples(time=t, q=q, qd=z, qdd=z), robot="er20")


def test_a_renamed_trajectory_column_is_refused(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    good = _traj(tmp_path / "traj.csv")
    load_trajectory(good)
    out = tmp_path / "rec.parquet"
    cases = [("q1 [rad]", "joint1 [rad]", "column 2", "unknown column"),
             ("qd3 [rad/s]", "qd3 [deg/s]", "column 10", "another unit"),
             ("q2 [rad],q3 [rad]", "q3 [rad],q2 [rad]", "column 3", "out of order")]
    for old, new, column, what in cases:
        bad = tmp_path / "renamed.csv"
        bad.write_text(good.read_text().replace(old, new, 1))
        assert main(["record", "--robot", "er20", "--trajectory", str(bad), "-o",
                     str(out)]) == 2
        err = _error(capsys)
        assert str(bad) in err and f"field '{column}'" in err and what in err, err
        assert not out.exists()
    bad.write_text(good.read_text().replace(",qdd6 [rad/s²]", "", 1))
    with pytest.raises(DataError, match="number of columns"):
        load_trajectory(bad)


# ---------------------------------------------------------------------- symlinks, modes
def test_an_output_over_a_symlink_is_refused(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "precious.parquet"
    target.write_bytes(b"keep me")
    link = tmp_path / "rec.parquet"
    link.symlink_to(target)
    traj = _traj(tmp_path / "traj.csv")
    assert main(["record", "--robot", "er20", "--trajectory", str(traj), "-o",
                 str(link)]) == 2
    err = _error(capsys)
    assert "symbolic link" in err and str(link) in err, err
    assert link.is_symlink() and target.read_bytes() == b"keep me"
    dangling = tmp_path / "out.txt"
    dangling.symlink_to(tmp_path / "elsewhere.txt")
    with pytest.raises(DataError, match="symbolic link"):
        atomic_write_text(dangling, "x")
    assert dangling.is_symlink() and not (tmp_path / "elsewhere.txt").exists()
    # a session file, and a partial file planted where the session's rows go
    with pytest.raises(DataError, match="symbolic link"):
        SessionFileSink(link, 6)
    planted = tmp_path / "s.parquet.partial"
    planted.symlink_to(target)
    with pytest.raises(DataError, match="in the way") as e:
        SessionFileSink(tmp_path / "s.parquet", 6)
    assert e.value.source == str(planted) and target.read_bytes() == b"keep me"
    assert list(tmp_path.glob(".*")) == []            # no temporary file left


def test_outputs_get_a_normal_file_mode(tmp_path: Path, umask: int) -> None:
    expected = 0o666 & ~umask
    written = atomic_write_text(tmp_path / "a.txt", "x")
    traj = _traj(tmp_path / "traj.csv")
    rows = _seam_log(load_robot("er20"), duration=0.2)
    session = save_session(rows, tmp_path / "s.parquet")
    with SessionFileSink(tmp_path / "streamed.parquet", 6, chunk_rows=50) as sink:
        chunk = sink.empty()
        chunk.rot[:] = np.eye(3)
        chunk.rows = 50
        sink.take(chunk)
        sink.finish("er20", [], {})
    for path in (written, traj, session, tmp_path / "streamed.parquet"):
        assert (path.stat().st_mode & 0o777) == expected, (path, oct(path.stat().st_mode))
    os.umask(0o077)
    private = atomic_write_text(tmp_path / "b.txt", "x")
    assert (private.stat().st_mode & 0o777) == 0o600


# ------------------------------------------------------------------------------ recover
def _seam_log(robot: Robot, duration: float = 4.0, dt: float = 0.002) -> SessionLog:
    """A session whose TCP dwells (mark P1 at 0.5 s), moves 0.3 m along a straight line and
    dwells (mark P2 at duration - 0.5 s), in the guiding start orientation."""
    q0 = np.array([0.0, -0.3, 0.6, 0.0, 0.9, 0.0])
    model, data, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    pin.forwardKinematics(model, data, q0)
    start = pin.updateFramePlacement(model, data, fid).copy()
    t = np.arange(0.0, duration + dt / 2, dt)
    s = np.clip((t - 1.0) / (duration - 2.0), 0.0, 1.0)
    u = 0.5 - 0.5 * np.cos(np.pi * s)
    q = np.empty((t.size, robot.n))
    qk = q0.copy()
    for i, ui in enumerate(u):
        target = pin.SE3(start.rotation, start.translation + np.array([0.0, 0.3 * ui, 0.0]))
        for _ in range(20):
            pin.forwardKinematics(model, data, qk)
            err = pin.log6(pin.updateFramePlacement(model, data, fid).actInv(target)).vector
            if np.linalg.norm(err) < 1e-12:
                break
            jac = pin.computeFrameJacobian(model, data, qk, fid, pin.LOCAL)
            qk = qk + np.linalg.lstsq(jac, err, rcond=None)[0]
        q[i] = qk
    pos, quat = forward_tcp(robot, q)
    z = np.zeros_like(q)
    return SessionLog(robot=robot.name, time=t, q=q, current=z, tau_ext=z.copy(),
                      wrench_base=np.zeros((t.size, 6)), q_cmd=q.copy(), qd_cmd=z.copy(),
                      tcp_cmd_base=pos, tcp_cmd_quat=quat, twist_cmd_base=np.zeros((t.size, 6)),
                      state=np.ones(t.size, dtype=np.int64),
                      fault=np.zeros(t.size, dtype=np.int64),
                      events=[SessionEvent(0.1, "transition", "IDLE->GUIDING", "ENABLE"),
                              SessionEvent(0.5, "mark", "P1"),
                              SessionEvent(duration - 0.5, "mark", "P2")],
                      settings={"driver": "ur-rtde"})


#: Streams a saved session's rows through the session file's writer as the loop does (its
#: events noted as they come), waits until the writer has them, then is SIGKILLed.
_KILLED_SESSION = """
import os, signal, sys, time
import numpy as np
from scipy.spatial.transform import Rotation
from leadthrough.session_format import load_session
from leadthrough.session.recorder import SessionRecorder
from leadthrough.session.session_file import SessionFileSink

source, out, kill_writer = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
log = load_session(source)
sink = SessionFileSink(out, log.n, chunk_rows=250, robot=log.robot,
                       settings=dict(log.settings))
events = []
rec = SessionRecorder(log.n, False, sink, events=events)
rot = Rotation.from_quat(log.tcp_cmd_quat).as_matrix()
pending = sorted(log.events, key=lambda e: e.t)
for i in range(log.time.size):
    while pending and pending[0].t <= log.time[i]:
        events.append(pending.pop(0))
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = rot[i], log.tcp_cmd_base[i]
    rec.store(log.time[i], log.q[i], log.current[i], log.tau_ext[i], log.wrench_base[i],
              log.q_cmd[i], log.qd_cmd[i], transform, log.twist_cmd_base[i],
              int(log.state[i]), int(log.fault[i]), None)
    end = time.monotonic() + 30      # at the loop's pace the writer keeps up: wait for it
    while rec.rows % 250 == 0 and sink.pending() and time.monotonic() < end:
        time.sleep(0.005)
print(sink.writer_pid, sink.rows_written, flush=True)
if kill_writer:
    os.kill(sink.writer_pid, signal.SIGKILL)
    time.sleep(0.2)
os.kill(os.getpid(), signal.SIGKILL)
"""


def _killed_session(source: Path, out: Path, kill_writer: bool = False) -> int:
    """Run :data:`_KILLED_SESSION`; the rows its writer had written."""
    done = subprocess.run([sys.executable, "-c", _KILLED_SESSION, str(source), str(out),
                           "1" if kill_writer else "0"], capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == -signal.SIGKILL, done.stderr
    pid, rows = (int(x) for x in done.stdout.split())
    for _ in range(200):           # the writer closes the rows and exits
        if not Path(f"/proc/{pid}").exists():
            break
        subprocess.run(["sleep", "0.05"], check=True)
    assert not Path(f"/proc/{pid}").exists()
    return rows


def test_a_killed_session_is_recovered_and_teach_reads_it(
        tmp_path: Path, er20: Robot, capsys: pytest.CaptureFixture[str]) -> None:
    source = save_session(_seam_log(er20), tmp_path / "source.parquet")
    original = load_session(source)
    out = tmp_path / "session.parquet"
    partial = tmp_path / "session.parquet.partial"
    rows = _killed_session(source, out)
    assert rows == 2000 and partial.exists() and not out.exists()
    # the defect: teach cannot read what a killed session leaves
    assert main(["teach", str(partial), "-o", str(tmp_path / "p.json")]) == 2
    capsys.readouterr()
    assert main(["recover", str(partial), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == rows and summary["marks"] == 2 and summary["robot"] == "er20"
    assert not partial.exists() and not Path(str(partial) + ".jsonl").exists()
    got = load_session(out)
    np.testing.assert_array_equal(got.q, original.q[:rows])
    np.testing.assert_array_equal(got.time, original.time[:rows])
    np.testing.assert_allclose(got.tcp_cmd_base, original.tcp_cmd_base[:rows])
    assert [(e.t, e.kind, e.label) for e in got.events] == [
        (e.t, e.kind, e.label) for e in original.events if e.t <= original.time[rows - 1]]
    assert got.settings["driver"] == "ur-rtde" and got.settings["recovered_rows"] == rows
    assert main(["teach", str(out), "-o", str(tmp_path / "path.json")]) == 0
    taught = capsys.readouterr().out
    assert "marks P1, P2" in taught, taught


def test_a_partial_file_that_cannot_be_recovered_writes_nothing(
        tmp_path: Path, er20: Robot, capsys: pytest.CaptureFixture[str]) -> None:
    source = save_session(_seam_log(er20, duration=1.5), tmp_path / "source.parquet")
    # the writer process killed too: the rows were never closed (no Parquet footer)
    out = tmp_path / "lost.parquet"
    _killed_session(source, out, kill_writer=True)
    partial = tmp_path / "lost.parquet.partial"
    assert main(["recover", str(partial), "-o", str(out)]) == 2
    err = _error(capsys)
    assert "never closed" in err and str(partial) in err, err
    assert not out.exists() and partial.exists()
    # a crafted mark label in the sidecar: refused, nothing written, the partial kept
    out = tmp_path / "crafted.parquet"
    _killed_session(source, out)
    partial = tmp_path / "crafted.parquet.partial"
    sidecar = Path(str(partial) + ".jsonl")
    lines = sidecar.read_text().splitlines()
    lines.append(json.dumps({"t": 1.0, "kind": "mark", "label": "W1\n  SetDO do1, 1;",
                             "cause": ""}))
    sidecar.write_text("\n".join(lines) + "\n")
    assert main(["recover", str(partial), "-o", str(out)]) == 2
    err = _error(capsys)
    assert str(sidecar) in err and "label" in err, err
    assert not out.exists() and partial.exists()
    # a last line cut off mid-write is dropped, and a mark after the last row recovered (in
    # the chunk being filled, lost with the process: 1.5 s is row 751, the rows end at 750);
    # the rest recovers
    late = json.dumps({"t": 1.5, "kind": "mark", "label": "P3", "cause": ""})
    sidecar.write_text("\n".join([*lines[:-1], late]) + '\n{"t": 1.2, "kind": "ma')
    assert main(["recover", str(partial), "-o", str(out), "--json"]) == 0
    got = capsys.readouterr()
    summary = json.loads(got.out)
    assert summary["dropped_last_line"] is True and summary["dropped_events"] == ["P3"]
    assert "P3" in got.err and summary["rows"] == 750
    assert [e.label for e in load_session(out).marks] == ["P1", "P2"]
    # without its sidecar: only with --robot, and no events
    out2 = tmp_path / "bare.parquet"
    _killed_session(source, out2)
    partial2 = tmp_path / "bare.parquet.partial"
    Path(str(partial2) + ".jsonl").unlink()
    assert main(["recover", str(partial2), "-o", str(out2)]) == 2
    assert "--robot" in _error(capsys) and not out2.exists()
    assert main(["recover", str(partial2), "-o", str(out2), "--robot", "er20"]) == 0
    assert load_session(out2).events == [] and "no events" in capsys.readouterr().err
