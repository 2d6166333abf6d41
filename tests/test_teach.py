"""Teach-in: welding line fit, RDP simplification, limit check, export and the ``teach`` CLI.

The synthetic seam session: the ER20's TCP goes from a start pose to P1, dwells (mark P1), moves
0.4 m along a straight seam with a known sideways wobble of 2 mm, dwells at P2 (mark P2) and
leaves. Joint positions come from exact inverse kinematics (Pinocchio, Newton on log6) of that
TCP path plus encoder-like noise, so the fit on FK(measured q) is checked against the known line.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from leadthrough.cli import main
from leadthrough.errors import LeadthroughError, TeachError
from leadthrough.fileio import read_comment_header
from leadthrough.robot import Robot
from leadthrough.session_format import SessionEvent, SessionLog, load_session, save_session
from leadthrough.teach import (
    check_limits,
    fit_line,
    forward_tcp,
    limit_report,
    program_to_dict,
    rdp_indices,
    segment_distances,
    teach_session,
    write_program_csv,
    write_program_json,
)

Array = NDArray[np.float64]

Q0 = np.array([0.0, -0.3, 0.6, 0.0, 0.9, 0.0])  # ER20 start pose, TCP at (0.95, 0, 0.62) m
SEAM_DIR = np.array([0.2, 1.0, -0.1]) / np.linalg.norm([0.2, 1.0, -0.1])
SEAM_LEN = 0.4  # [m]
WOBBLE = 0.002  # [m] amplitude of the sideways wobble along the seam
DT = 0.002  # [s]


# ----------------------------------------------------------------------------- synthetic data
def _ik(robot: Robot, q: Array, target: pin.SE3) -> Array:
    """Joint positions reaching ``target`` (Newton on log6, warm-started at ``q``)."""
    model, data, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    q = q.copy()
    for _ in range(50):
        pin.forwardKinematics(model, data, q)
        err = pin.log6(pin.updateFramePlacement(model, data, fid).actInv(target)).vector
        if np.linalg.norm(err) < 1e-12:
            return q
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        q = q + np.linalg.lstsq(J, err, rcond=None)[0]
    raise RuntimeError("IK did not converge")


def _smooth(a: Array, b: Array, s: Array) -> Array:
    """Points from a to b with a raised-cosine profile, s in [0, 1]."""
    w = 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0.0, 1.0))
    return a + np.multiply.outer(w, b - a)


def _seam_points(p1: Array, t: Array, wobble: float) -> tuple[Array, float, float]:
    """Target TCP positions [m] of the seam script and the mark times [s]."""
    side = np.cross(SEAM_DIR, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    p2 = p1 + SEAM_LEN * SEAM_DIR
    up = np.array([0.0, 0.0, 0.08])
    start, leave = p1 + up - 0.1 * SEAM_DIR, p2 + up
    pts = np.empty((t.size, 3))
    phases = [(0.0, 0.3), (0.3, 1.3), (1.3, 1.8), (1.8, 5.8), (5.8, 6.3), (6.3, 7.0)]
    for k, (a, b) in enumerate(phases):
        sel = (t >= a) & (t < b + 1e-12)
        s = (t[sel] - a) / (b - a)
        if k == 0:
            pts[sel] = start
        elif k == 1:
            pts[sel] = _smooth(start, p1, s)
        elif k == 2:
            pts[sel] = p1
        elif k == 3:  # along the seam, raised-cosine speed profile, sideways wobble
            u = 0.5 - 0.5 * np.cos(np.pi * s)
            pts[sel] = (p1 + np.multiply.outer(SEAM_LEN * u, SEAM_DIR)
                        + np.multiply.outer(wobble * np.sin(6 * np.pi * u), side))
        elif k == 4:
            pts[sel] = p2
        else:
            pts[sel] = _smooth(p2, leave, s)
    return pts, 1.55, 6.05


def _log(robot: Robot, t: Array, q: Array, marks: list[tuple[float, str]]) -> SessionLog:
    pos, quat = forward_tcp(robot, q)
    n, z = robot.n, np.zeros((t.size, robot.n))
    return SessionLog(robot=robot.name, time=t, q=q, current=z, tau_ext=z.copy(),
                      wrench_base=np.zeros((t.size, 6)), q_cmd=q.copy(), qd_cmd=z.copy(),
                      tcp_cmd_base=pos, tcp_cmd_quat=quat, twist_cmd_base=np.zeros((t.size, 6)),
                      state=np.ones(t.size, dtype=np.int64), fault=np.zeros(t.size, dtype=np.int64),
                      events=[SessionEvent(t=tm, kind="mark", label=lb) for tm, lb in marks]
                      + [SessionEvent(t=0.1, kind="transition", label="IDLE->GUIDING")],
                      settings={"dt": DT, "joints": n})


def _make_seam(robot: Robot, wobble: float) -> tuple[SessionLog, Array, Array]:
    """The seam session with encoder noise, and the true P1, P2 [m]."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, Q0)
    T0 = pin.updateFramePlacement(model, data, robot.tcp_frame_id).copy()
    p1 = T0.translation + np.array([0.0, -0.2, 0.0])
    t = np.arange(0.0, 7.0 + DT / 2, DT)
    pts, t_p1, t_p2 = _seam_points(p1, t, wobble)
    q = np.empty((t.size, robot.n))
    qk = Q0.copy()
    for i, p in enumerate(pts):
        qk = _ik(robot, qk, pin.SE3(T0.rotation, p))
        q[i] = qk
    q_meas = q + np.random.default_rng(3).normal(0.0, 2e-5, q.shape)  # encoder noise [rad]
    log = _log(robot, t, q_meas, [(t_p1, "P1"), (t_p2, "P2")])
    return log, p1, p1 + SEAM_LEN * SEAM_DIR


@pytest.fixture(scope="module")
def seam(er20: Robot) -> tuple[SessionLog, Array, Array]:
    """Seam with a 2 mm sideways wobble."""
    return _make_seam(er20, WOBBLE)


# ---------------------------------------------------------------------------- welding line
def test_seam_line_endpoints_within_5mm_and_deviation(
        er20: Robot, seam: tuple[SessionLog, Array, Array]) -> None:
    log, p1, p2 = seam
    prog = teach_session(log, er20, tolerance_mm=1.0, speed_m_s=0.1)
    line = prog.welding_line
    assert line is not None
    e1 = np.linalg.norm(line.p1_base - p1) * 1e3
    e2 = np.linalg.norm(line.p2_base - p2) * 1e3
    print(f"endpoint errors P1 {e1:.3f} mm, P2 {e2:.3f} mm; deviation max "
          f"{line.max_deviation_mm:.3f} mm rms {line.rms_deviation_mm:.3f} mm; "
          f"{len(prog.waypoints)} waypoints of {prog.path_samples} samples")
    assert e1 < 5.0 and e2 < 5.0
    # the wobble's time average is not zero (slow start and end), which shifts the fitted line
    # by ~0.6 mm: what the fit achieves on these data
    assert e1 < 1.0 and e2 < 1.0
    assert abs(line.length_m - SEAM_LEN) < 1e-3
    assert float(line.direction_base @ SEAM_DIR) > 1 - 1e-5
    # sideways wobble of 2 mm about the true line, measured from the (shifted) fitted line
    assert 1.8 < line.max_deviation_mm < 2.8
    assert 1.0 < line.rms_deviation_mm < 1.45


def test_straight_seam_line_is_the_true_line(er20: Robot) -> None:
    log, p1, p2 = _make_seam(er20, 0.0)
    line = teach_session(log, er20).welding_line
    assert line is not None
    e1 = np.linalg.norm(line.p1_base - p1) * 1e3
    e2 = np.linalg.norm(line.p2_base - p2) * 1e3
    print(f"straight seam: endpoint errors P1 {e1:.3f} mm, P2 {e2:.3f} mm; deviation max "
          f"{line.max_deviation_mm:.3f} mm rms {line.rms_deviation_mm:.3f} mm")
    assert e1 < 0.1 and e2 < 0.1  # only the encoder noise (2e-5 rad) is left
    assert line.max_deviation_mm < 0.2 and line.rms_deviation_mm < 0.05
    assert line.samples == int(np.sum((log.time >= 1.55) & (log.time <= 6.05)))


def test_line_uses_measured_joints_not_command(
        er20: Robot, seam: tuple[SessionLog, Array, Array]) -> None:
    log, _, _ = seam
    ref = teach_session(log, er20)
    garbage = replace(log, tcp_cmd_base=np.zeros_like(log.tcp_cmd_base))
    other = teach_session(garbage, er20)
    assert ref.welding_line is not None and other.welding_line is not None
    np.testing.assert_array_equal(ref.welding_line.p1_base, other.welding_line.p1_base)
    pos, _ = forward_tcp(er20, log.q[ref.waypoints.sample])
    np.testing.assert_allclose(ref.waypoints.tcp_position_base, pos, atol=1e-12)


def test_path_runs_mark_to_mark_and_keeps_marks(
        er20: Robot, seam: tuple[SessionLog, Array, Array]) -> None:
    log, _, _ = seam
    prog = teach_session(log, er20, tolerance_mm=0.5)
    w = prog.waypoints
    assert w.labels[0] == "P1" and w.labels[-1] == "P2"
    assert set(w.labels[1:-1]) == {""}
    assert w.time[0] == pytest.approx(1.55, abs=DT) and w.time[-1] == pytest.approx(6.05, abs=DT)
    assert 10 < len(w) < 200 < prog.path_samples
    # every recorded position between the marks is within the tolerance of the waypoint path
    rows = np.flatnonzero((log.time >= w.time[0]) & (log.time <= w.time[-1]))
    pos, _ = forward_tcp(er20, log.q[rows])
    for a, b in itertools.pairwise(w.sample):
        piece = pos[(rows >= a) & (rows <= b)]
        d = segment_distances(piece, piece[0], piece[-1])
        assert d.max() <= 0.5e-3 + 1e-12


def test_no_line_and_wrong_marks(er20: Robot, seam: tuple[SessionLog, Array, Array]) -> None:
    log, _, _ = seam
    assert teach_session(log, er20, line=None).welding_line is None
    with pytest.raises(TeachError, match=r"mark not found.*marks present: P1, P2"):
        teach_session(log, er20, line=("P1", "P3"))
    twice = replace(log, events=[*log.events, SessionEvent(3.0, "mark", "P1")])
    with pytest.raises(TeachError, match="pressed 2 times"):
        teach_session(twice, er20)
    none = replace(log, events=[e for e in log.events if e.kind != "mark"])
    with pytest.raises(TeachError, match="no marks"):
        teach_session(none, er20)


def test_transitions_between_marks_are_reported(
        er20: Robot, seam: tuple[SessionLog, Array, Array]) -> None:
    log, _, _ = seam
    assert teach_session(log, er20).transitions == ()  # the one at 0.1 s is before P1
    fault = SessionEvent(3.0, "transition", "GUIDING->FAULT", "FAULT:COLLISION")
    prog = teach_session(replace(log, events=[*log.events, fault]), er20)
    assert prog.transitions == (fault,)


def test_fit_line_exact_and_degenerate() -> None:
    d = np.array([1.0, 2.0, 2.0]) / 3.0
    pts = np.array([0.1, -0.2, 0.3]) + np.multiply.outer(np.linspace(-1, 2, 30), d)
    line = fit_line(pts)
    assert abs(float(line.direction_base @ d)) == pytest.approx(1.0, abs=1e-12)
    assert line.distance(pts).max() < 1e-12
    with pytest.raises(TeachError, match="coincide"):
        fit_line(np.ones((5, 3)))
    with pytest.raises(TeachError, match="too few"):
        fit_line(np.ones((1, 3)))


# ----------------------------------------------------------------------------------- RDP
def _rdp_recursive(p: Array, tol: float, i: int, j: int) -> list[int]:
    if j - i < 2:
        return [i, j]
    d = segment_distances(p[i + 1:j], p[i], p[j])
    k = int(np.argmax(d))
    if d[k] <= tol:
        return [i, j]
    m = i + 1 + k
    return _rdp_recursive(p, tol, i, m)[:-1] + _rdp_recursive(p, tol, m, j)


def test_rdp_known_polylines() -> None:
    line = np.column_stack([np.linspace(0, 1, 100), np.zeros(100), np.zeros(100)])
    assert rdp_indices(line, 1e-9).tolist() == [0, 99]
    ell = np.array([[x, 0.0, 0.0] for x in range(11)] + [[10.0, y, 0.0] for y in range(1, 11)])
    assert rdp_indices(ell, 0.01).tolist() == [0, 10, 20]
    bump = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0], [2.0, 0.0, 0.0]])
    assert rdp_indices(bump, 0.49).tolist() == [0, 1, 2]
    assert rdp_indices(bump, 0.51).tolist() == [0, 2]
    back = np.array([[0.0, 0, 0], [10.0, 0, 0], [5.0, 0, 0]])  # turns back: keep the turn
    assert rdp_indices(back, 1.0).tolist() == [0, 1, 2]
    assert rdp_indices(line, 1.0, keep=[40, 7]).tolist() == [0, 7, 40, 99]
    assert rdp_indices(line[:1], 1.0).tolist() == [0]
    assert rdp_indices(np.zeros((0, 3)), 1.0).tolist() == []


def test_rdp_rejects_bad_input() -> None:
    pts = np.zeros((4, 3))
    for tol in (-1.0, math.nan, math.inf):
        with pytest.raises(TeachError, match="tolerance"):
            rdp_indices(pts, tol)
    with pytest.raises(TeachError, match="keep"):
        rdp_indices(pts, 1.0, keep=[4])
    with pytest.raises(TeachError, match="non-finite"):
        rdp_indices(np.array([[0.0, 0, 0], [math.nan, 0, 0]]), 1.0)


def test_rdp_long_path_is_iterative() -> None:
    rng = np.random.default_rng(0)
    n = 200_000
    t = np.linspace(0.0, 20.0 * np.pi, n)
    pts = np.column_stack([t, np.sin(t), 0.01 * rng.standard_normal(n)])
    kept = rdp_indices(pts, 0.05)
    assert kept[0] == 0 and kept[-1] == n - 1 and 50 < kept.size < 5000


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 60), st.floats(0.0, 2.0), st.integers(0, 2**31 - 1))
def test_rdp_matches_recursive_and_bounds_error(n: int, tol: float, seed: int) -> None:
    p = np.cumsum(np.random.default_rng(seed).standard_normal((n, 3)), axis=0)
    kept = rdp_indices(p, tol)
    assert kept.tolist() == _rdp_recursive(p, tol, 0, n - 1)
    for a, b in itertools.pairwise(kept):
        assert segment_distances(p[a:b + 1], p[a], p[b]).max() <= tol + 1e-12


# ---------------------------------------------------------------------------- limit check
def _dq(joint: int, value: float) -> Array:
    dq = np.zeros(6)
    dq[joint] = value
    return dq


def _waypoints(robot: Robot, q: Array) -> tuple[Array, Array, Array]:
    pos, quat = forward_tcp(robot, q)
    return q, pos, quat


def test_limits_pass_and_timing(er20: Robot) -> None:
    q = np.array([Q0, Q0 + _dq(0, 0.1)])
    rep = check_limits(*_waypoints(er20, q), er20, 0.1)
    length = float(np.linalg.norm(np.diff(forward_tcp(er20, q)[0], axis=0)))
    assert rep.ok and rep.segment_time_s[0] == pytest.approx(length / 0.1)
    assert rep.joint_speed_rad_s[0, 0] == pytest.approx(0.1 / (length / 0.1))
    ratio = rep.joint_speed_rad_s[0, 0] / er20.velocity_limit[0]
    assert rep.max_speed_ratio == pytest.approx(ratio)


def test_speed_limit_error_names_waypoint_joint_value_limit(er20: Robot) -> None:
    # joint 1 sweeps 1 rad (0.92 m of TCP chord) between waypoints 1 and 2 at 5 m/s; the
    # orientation speed is set high so that the linear speed sets the segment time; waypoints 0
    # and 1 are the same (a segment without motion needs no speed)
    q = np.array([Q0, Q0, Q0 + _dq(0, 1.0)])
    args = _waypoints(er20, q)
    labels = ["P1", "", "P2"]
    rep = limit_report(*args, er20, 5.0, orientation_speed_rad_s=100.0, labels=labels)
    need = rep.joint_speed_rad_s[1, 0]
    assert need > er20.velocity_limit[0]
    assert [(v.waypoint, v.joint) for v in rep.violations] == [(2, 0)]
    assert rep.segment_time_s[0] == 0.0 and not rep.joint_speed_rad_s[0].any()
    assert limit_report(*args, er20, 5.0).ok  # at 0.5 rad/s the 1 rad turn takes 2 s
    with pytest.raises(TeachError) as e:
        check_limits(*args, er20, 5.0, orientation_speed_rad_s=100.0, labels=labels,
                     source="s.parquet")
    msg = str(e.value)
    assert "waypoint 2 (P2)" in msg and "joint 1 (joint_1)" in msg and "\n" not in msg
    assert e.value.field == "waypoints[2].qd1"
    assert e.value.value == pytest.approx(need, rel=1e-5)
    assert f"{er20.velocity_limit[0]:.4f} rad/s" in msg
    v_ok = rep.violations[0].max_speed_m_s
    assert v_ok is not None and f"program at most {v_ok:.4f} m/s" in msg
    assert check_limits(*args, er20, 0.999 * v_ok, orientation_speed_rad_s=100.0).ok
    assert not limit_report(*args, er20, 1.001 * v_ok, orientation_speed_rad_s=100.0).ok


def test_position_limit_error_names_waypoint(er20: Robot) -> None:
    q = np.array([Q0, Q0, Q0])
    q[1, 1] = er20.upper_limits[1] + 0.01
    with pytest.raises(TeachError) as e:
        check_limits(*_waypoints(er20, q), er20, 0.1)
    assert "waypoint 1" in str(e.value) and "joint 2 (joint_2)" in str(e.value)
    assert f"≤ {er20.upper_limits[1]:.4f} rad" in str(e.value)
    with pytest.raises(TeachError, match="speed_m_s"):
        check_limits(*_waypoints(er20, q), er20, 0.0)


def test_same_pose_configuration_change_is_an_error(er20: Robot) -> None:
    q = np.array([Q0, Q0 + _dq(3, 0.3)])
    pos, quat = forward_tcp(er20, q)
    with pytest.raises(TeachError, match="TCP pose unchanged"):
        check_limits(q, pos[[0, 0]], quat[[0, 0]], er20, 0.1)


# -------------------------------------------------------------------------------- export
def test_json_and_csv_round_trip(er20: Robot, seam: tuple[SessionLog, Array, Array],
                                 tmp_path: Path) -> None:
    log, _, _ = seam
    prog = teach_session(log, er20, tolerance_mm=1.0, speed_m_s=0.08)
    doc = json.loads(write_program_json(prog, tmp_path / "p.json").read_text())
    assert doc == json.loads(json.dumps(program_to_dict(prog)))
    assert doc["robot"] == "er20" and doc["programmed_speed_m_s"] == 0.08
    assert doc["units"]["tcp_position_m"].startswith("m") and doc["units"]["q_rad"] == "rad"
    wl = doc["welding_line"]
    assert set(wl) >= {"p1_m", "p2_m", "length_m", "max_deviation_mm", "rms_deviation_mm"}
    assert wl["max_deviation_mm"] == prog.welding_line.max_deviation_mm  # type: ignore[union-attr]
    w0 = doc["waypoints"][0]
    assert set(w0) >= {"index", "t_s", "q_rad", "tcp_position_m", "tcp_quat_xyzw"}
    assert w0["label"] == "P1" and len(w0["q_rad"]) == 6
    np.testing.assert_array_equal([w["q_rad"] for w in doc["waypoints"]], prog.waypoints.q)

    path = write_program_csv(prog, tmp_path / "p.csv")
    skip, meta = read_comment_header(path)
    assert meta["robot"] == "er20" and meta["programmed_speed_m_s"] == "0.08"
    with path.open(encoding="utf-8") as f:
        rows = list(csv.reader(f.readlines()[skip:]))
    assert rows[0][:4] == ["index", "label", "sample", "t [s]"]
    assert "q1 [rad]" in rows[0] and "x [m]" in rows[0] and rows[0][-1] == "qw [-]"
    body = rows[1:]
    assert len(body) == len(prog.waypoints) and body[-1][1] == "P2"
    data = np.array([[float(v) for v in r[4:]] for r in body])
    np.testing.assert_array_equal(data[:, :6], prog.waypoints.q)
    np.testing.assert_array_equal(data[:, 6:9], prog.waypoints.tcp_position_base)
    np.testing.assert_array_equal(data[:, 9:], prog.waypoints.tcp_quat_xyzw)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


# ----------------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def seam_file(seam: tuple[SessionLog, Array, Array],
              tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_session(seam[0], tmp_path_factory.mktemp("teach") / "seam.parquet")


def test_cli_teach_writes_json_csv_and_summary(seam_file: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    out, out_csv = tmp_path / "seam.json", tmp_path / "seam.csv"
    assert main(["teach", str(seam_file), "--tolerance-mm", "1", "--speed", "0.1",
                 "-o", str(out), "--csv", str(out_csv), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    doc = json.loads(out.read_text())
    assert info["waypoints"] == len(doc["waypoints"]) and info["marks"] == ["P1", "P2"]
    assert info["welding_line"]["max_deviation_mm"] == doc["welding_line"]["max_deviation_mm"]
    assert load_session(seam_file).robot == doc["robot"] == "er20"
    assert out_csv.read_text().startswith("# leadthrough waypoints\n# robot: er20\n")
    assert main(["teach", str(seam_file), "-o", str(tmp_path / "b.json")]) == 0
    assert "welding line P1->P2 400.0 mm" in capsys.readouterr().out


def _assert_fails_cleanly(argv: list[str], folder: Path, capsys: pytest.CaptureFixture[str],
                          match: str) -> None:
    before = set(folder.iterdir())
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    err = cap.err.strip()
    assert "\n" not in err and "Traceback" not in err and match in err, err
    assert set(folder.iterdir()) == before  # no output, no temp file


def test_cli_errors_one_line_exit_2_no_output(seam: tuple[SessionLog, Array, Array],
                                              seam_file: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "out.json")
    extra = ["-o", out, "--csv", str(tmp_path / "out.csv")]
    _assert_fails_cleanly(["teach", str(tmp_path / "missing.parquet"), *extra], tmp_path,
                          capsys, "file not found")
    bad = tmp_path / "corrupt.parquet"
    bad.write_bytes(b"PAR1 this is not a parquet file \x00\x01\x02")
    _assert_fails_cleanly(["teach", str(bad), *extra], tmp_path, capsys,
                          "not a readable Parquet file")
    log = seam[0]
    no_marks = save_session(replace(log, events=[]), tmp_path / "nomarks.parquet")
    _assert_fails_cleanly(["teach", str(no_marks), *extra], tmp_path, capsys,
                          "session has no marks")
    _assert_fails_cleanly(["teach", str(seam_file), "--robot", "ur5", *extra], tmp_path, capsys,
                          "recorded on another robot")
    custom = save_session(replace(log, robot="my_arm"), tmp_path / "custom.parquet")
    _assert_fails_cleanly(["teach", str(custom), *extra], tmp_path, capsys,
                          "session robot is not a built-in robot")
    _assert_fails_cleanly(["teach", str(seam_file), "--speed", "50", *extra], tmp_path, capsys,
                          "joint velocity limit")
    _assert_fails_cleanly(["teach", str(seam_file), "--line", "P1", *extra], tmp_path, capsys,
                          "two different mark labels")
    _assert_fails_cleanly(["teach", str(seam_file), "-o", str(tmp_path / "x.txt")], tmp_path,
                          capsys, "unsupported output file type")
    _assert_fails_cleanly(["teach", str(seam_file), "-o", str(tmp_path / "nope" / "x.json")],
                          tmp_path, capsys, "output folder does not exist")


def test_cli_console_script_corrupt_file_no_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "x.parquet"
    bad.write_bytes(b"garbage" * 10)
    proc = subprocess.run([sys.executable, "-m", "leadthrough", "teach", str(bad), "-o",
                           str(tmp_path / "x.json")], capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
    assert not (tmp_path / "x.json").exists()


def test_teach_error_is_a_leadthrough_error() -> None:
    assert issubclass(TeachError, LeadthroughError)
