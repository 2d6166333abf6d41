"""The pendant's link to the loop (``leadthrough.pendant.backend``) on the simulated robot, the
loop in a process of its own: requests at cycle boundaries (enable, mark, adjust, clear a
fault, the simulator's push and fault), notices, marks, the live recording and its export, the
loop's process ending (why it stopped; a crash shows a lost link), the taught point list, and
the shipped parameters that the simulated sessions run with. The lifetime of the two processes
and the shared memory's consistency are in ``test_pendant_process.py``."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.guiding_types import GuidingOutput
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.control.safety import Fault, State
from leadthrough.drivers.protocol import DriverFeedback, JointCommand
from leadthrough.errors import ControlError, TeachError
from leadthrough.estimation.estimator import EstimatorOutput
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.backend import (
    Adjust,
    ClearFault,
    LiveSession,
    LoopSnapshot,
    MarkedPoint,
    MarkPoint,
    SetEnable,
)
from leadthrough.pendant.export import POINTS_FORMAT, export_taught
from leadthrough.pendant.live_recording import LiveRecording
from leadthrough.pendant.simulated import InjectFault, SimulatedPendantSession, simulated_session
from leadthrough.pendant.status_view import StatusExtras, status_html
from leadthrough.pendant.taught_points import TaughtPoints
from leadthrough.pendant.transitions import describe
from leadthrough.robot import Robot
from leadthrough.session.loop_config import LoopConfig
from leadthrough.session.recorder import SessionRecorder
from leadthrough.session_format import SessionEvent, load_session
from leadthrough.sim.driver import InjectedFaultKind
from leadthrough.sim.guiding_params import shipped_guiding_params
from leadthrough.sim.operator_scripts import push_x
from leadthrough.sim.session import SimSessionConfig, light_guiding, run_sim_session
from leadthrough.teach import teach_session


def until(live: LiveSession, condition: Callable[[LoopSnapshot], bool], loop_s: float,
          what: str) -> LoopSnapshot:
    """The first snapshot meeting ``condition`` within ``loop_s`` of loop time."""
    first = live.snapshot()
    assert first is not None
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        snap = live.snapshot()
        assert snap is not None
        if snap.error is not None:
            pytest.fail(f"the loop stopped: {snap.error}")
        if condition(snap):
            return snap
        if snap.time - first.time > loop_s:
            break
        time.sleep(0.002)
    pytest.fail(f"no {what} within {loop_s} s of loop time")


@pytest.fixture
def sim(er20: Robot) -> Iterator[SimulatedPendantSession]:
    """A live session on the simulator, running as fast as the machine allows."""
    s = simulated_session(er20, paced=False, record_s=60.0)
    s.live.start()
    until(s.live, lambda snap: snap.estimator.name == "OK", 5.0, "tared estimator")
    try:
        yield s
    finally:
        s.live.stop()
        s.live.close()


def test_guiding_a_push_marking_and_stopping(sim: SimulatedPendantSession,
                                             er20: Robot, tmp_path: Path) -> None:
    live, hand = sim.live, sim.hand
    live.send(SetEnable(True))
    until(live, lambda s: s.state == State.GUIDING, 0.1, "GUIDING")
    live.send(MarkPoint("P1"))
    p1 = until(live, lambda s: len(s.marks) == 1, 0.05, "the mark")
    hand.push([0.0, 40.0, 0.0])
    moving = until(live, lambda s: s.speed > 0.05, 3.0, "motion")
    assert moving.state == State.GUIDING
    assert moving.twist_base[1] > 0.9 * moving.speed       # along the push
    until(live, lambda s: s.transform_tool_to_base[1, 3] > 0.06, 3.0, "6 cm along y")
    hand.release()
    until(live, lambda s: s.speed == 0.0, 5.0, "rest after the release")
    live.send(MarkPoint("P2"))
    live.send(SetEnable(False))
    done = until(live, lambda s: s.state == State.IDLE and len(s.marks) == 2, 2.0, "IDLE")
    assert done.cause == "STOPPED"
    p1_mark, p2_mark = done.marks
    assert (p1_mark.label, p2_mark.label) == ("P1", "P2")
    assert np.array_equal(p1_mark.q, p1.q)                # the measured q of its cycle
    assert [n.text for n in done.notices if n.text.startswith("marked")] == [
        f"marked P1 at {p1_mark.t:.2f} s", f"marked P2 at {p2_mark.t:.2f} s"]

    points = list(done.marks)
    exported = export_taught(live.session_log(points), points, er20, tmp_path)
    assert exported.folder == tmp_path / "export-001" and exported.note == ""
    log = load_session(exported.files["session"])
    assert [(m.label, m.t) for m in log.marks] == [("P1", p1_mark.t), ("P2", p2_mark.t)]
    program = teach_session(log, er20, tolerance_mm=1.0)
    assert program.welding_line is not None
    assert program.welding_line.length_m > 0.06
    data = json.loads(exported.files["points"].read_text())
    assert data["format"] == POINTS_FORMAT and [p["label"] for p in data["points"]] == [
        "P1", "P2"]
    assert json.loads(exported.files["path"].read_text())["welding_line"]["length_m"] == \
        pytest.approx(program.welding_line.length_m, abs=1e-12)


def test_settings_change_at_rest_only_and_are_reported(sim: SimulatedPendantSession) -> None:
    live = sim.live
    live.send(Adjust(frame="tool", mass=(10.0, 300.0), friction=(25.0, 5.0)))
    snap = until(live, lambda s: s.settings.frame == "tool", 0.05, "the new frame")
    vf = snap.settings.virtual_friction
    assert (vf.mass[0], vf.mass[3], vf.friction[0], vf.friction[3]) == (50.0, 300.0, 25.0, 5.0)
    assert snap.notices[-1].text == "virtual mass clamped to 50 kg, 300 kg·m²"
    live.send(SetEnable(True))
    until(live, lambda s: s.state == State.GUIDING, 0.1, "GUIDING")
    live.send(Adjust(frame="base"))
    refused = until(live, lambda s: s.notices[-1].text.startswith("not changed"), 0.05,
                    "the refusal")
    assert refused.settings.frame == "tool" and "IDLE or FAULT" in refused.notices[-1].text
    live.send(ClearFault())
    warned = until(live, lambda s: s.notices[-1].text == "reset refused: no fault is latched",
                   0.05, "notice")
    assert [n.number for n in warned.notices] == sorted({n.number for n in warned.notices})


def test_a_fault_latches_until_cleared_at_rest(sim: SimulatedPendantSession) -> None:
    live = sim.live
    live.send(SetEnable(True))
    guiding = until(live, lambda s: s.state == State.GUIDING, 0.1, "GUIDING")
    live.send(InjectFault(InjectedFaultKind.STALE, after_s=0.05, duration_s=0.15))
    fault = until(live, lambda s: s.state == State.FAULT, 0.5, "FAULT")
    assert fault.time > guiding.time + 0.05
    assert fault.fault == Fault.STALE_FEEDBACK and fault.cause.startswith("STALE_FEEDBACK")
    time.sleep(0.05)
    assert live.snapshot().state == State.FAULT            # latched (stale feedback is over)
    live.send(SetEnable(False))
    live.send(ClearFault())
    cleared = until(live, lambda s: s.state == State.IDLE, 0.5, "IDLE after the clear")
    assert cleared.cause == "RESET"        # restarted at the measured position
    assert cleared.notices[-1].text.startswith("fault reset: restarted at the measured")


def test_the_loop_reports_why_it_did_not_start(er20: Robot) -> None:
    s = simulated_session(er20, paced=False, guiding=GuidingConfig(dt=0.0015))
    try:
        with pytest.raises(ControlError, match="multiple of the servo period"):
            s.live.start()
        assert not s.live.running
    finally:
        s.live.close()


def test_a_crashed_loop_shows_a_lost_link(sim: SimulatedPendantSession) -> None:
    live = sim.live
    live.send(SetEnable(True))
    until(live, lambda s: s.state == State.GUIDING, 0.1, "GUIDING")
    assert live.pid is not None
    os.kill(live.pid, signal.SIGKILL)
    deadline = time.monotonic() + 10
    while live.running and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not live.running
    snap = live.snapshot()
    assert snap is not None and snap.state == State.FAULT
    assert snap.error == f"lost link to the loop (its process ended, exit code {-signal.SIGKILL})"
    live.send(SetEnable(False))                  # no error, no wait: nobody listens
    page = status_html(snap, StatusExtras(armed=True, device=True, push_n=None,
                                          period_us=(0.0, 0.0), params=""))
    assert 'data-state="STOPPED"' in page and "lost link to the loop" in page


def test_snapshots_are_copies(sim: SimulatedPendantSession) -> None:
    snap = sim.live.snapshot()
    q = snap.q.copy()
    sim.hand.push([30.0, 0.0, 0.0])
    sim.live.send(SetEnable(True))
    until(sim.live, lambda s: s.speed > 0.0, 3.0, "motion")
    assert np.array_equal(snap.q, q)
    times = sim.live.period_times(50)
    assert times.work_us.size == 50 and times.controller_cycle.sum() == 5
    assert np.isnan(times.done_us).all()          # not paced


# --------------------------------------------------------------------- the recording ring
class _Cycle:
    """Stands in for the loop's state of a controller cycle (the loop's own record types):
    :meth:`store` records a row that holds its time in every number but the state codes."""

    def __init__(self, n: int) -> None:
        self.fb = DriverFeedback(t=0.0, q=np.zeros(n), current=np.zeros(n), sequence=0)
        self.cmd = JointCommand.zeros(n)
        self.e_out, self.c_out = EstimatorOutput(n), GuidingOutput(n)
        self.applied = np.zeros(6)

    def store(self, ring: LiveRecording, t: float) -> None:
        for array in (self.fb.q, self.fb.current, self.cmd.q, self.cmd.qd, self.e_out.tau_ext,
                      self.e_out.wrench, self.c_out.transform_tool_to_base,
                      self.c_out.twist_base, self.applied):
            array[...] = t
        ring.store(t, self.fb, self.cmd, self.e_out, self.c_out, self.applied)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 40), st.integers(0, 120))
def test_the_ring_keeps_the_last_rows_in_order(capacity: int, written: int) -> None:
    ring, loop = LiveRecording(capacity, 2, True), _Cycle(2)
    for k in range(written):
        loop.store(ring, float(k))
    rows, first = ring.rows()
    ring.block.close()
    kept = min(written, capacity - 1) if written >= capacity else written
    assert first == written - kept
    assert np.array_equal(rows.time, np.arange(first, written, dtype=float))
    assert np.array_equal(rows.q[:, 1], rows.time)


def test_the_ring_never_returns_a_row_being_written() -> None:
    ring, loop = LiveRecording(50, 6, True), _Cycle(6)
    stop = threading.Event()

    def writer() -> None:
        k = 0
        while not stop.is_set():
            loop.store(ring, float(k))
            k += 1

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        complete = 0
        for _ in range(300):
            rows, first = ring.rows()
            expected = np.arange(first, first + rows.time.size, dtype=float)
            assert np.array_equal(rows.time, expected)
            for column in (rows.q, rows.current, rows.rot.reshape(len(rows.rot), 9),
                           rows.applied):
                assert np.all(column == expected[:, None])
            complete += rows.time.size > 0
    finally:
        stop.set()
        thread.join()
        ring.block.close()
    assert complete > 0     # (a writer that laps the ring during a copy leaves no rows)


def test_the_rings_session_is_the_loop_recorders_session_of_the_kept_cycles() -> None:
    """The export's session is the loop's recording of the same cycles (one row layout, one
    conversion): every column, the orientation as a quaternion, the state codes, the events."""
    n, capacity, written = 3, 8, 13
    ring, loop = LiveRecording(capacity, n, True), _Cycle(n)
    recorder = SessionRecorder(n, True, chunk_rows=4)
    rng = np.random.default_rng(7)
    for k in range(written):
        t = 0.01 * k
        for array in (loop.fb.q, loop.fb.current, loop.cmd.q, loop.cmd.qd, loop.e_out.tau_ext,
                      loop.e_out.wrench, loop.c_out.twist_base, loop.applied):
            array[:] = rng.normal(size=array.shape)
        loop.c_out.transform_tool_to_base[:3, :3] = Rotation.from_rotvec(
            rng.normal(size=3)).as_matrix()
        loop.c_out.transform_tool_to_base[:3, 3] = rng.normal(size=3)
        loop.c_out.state, loop.c_out.fault = State(k % 4), Fault(k % 3)
        ring.store(t, loop.fb, loop.cmd, loop.e_out, loop.c_out, loop.applied)
        c = loop.c_out
        recorder.store(t, loop.fb.q, loop.fb.current, loop.e_out.tau_ext, loop.e_out.wrench,
                       loop.cmd.q, loop.cmd.qd, c.transform_tool_to_base, c.twist_base,
                       int(c.state), int(c.fault), loop.applied)
    full = recorder.finish("er20", [], {})
    assert full is not None
    live = ring.session_log("er20", [], [(0.1, "P1")], {"seed": 7})
    ring.block.close()
    kept = slice(written - (capacity - 1), written)   # the oldest slot is the one being written
    for name in ("time", "q", "current", "tau_ext", "wrench_base", "q_cmd", "qd_cmd",
                 "tcp_cmd_base", "tcp_cmd_quat", "twist_cmd_base", "state", "fault",
                 "wrench_applied_base"):
        assert np.array_equal(getattr(live, name), getattr(full, name)[kept]), name
    assert live.events == [SessionEvent(t=0.1, kind="mark", label="P1")]
    assert live.settings == {"seed": 7} and live.robot == "er20"


# --------------------------------------------------------------------- the point list
def _point(label: str, t: float) -> MarkedPoint:
    return MarkedPoint(label, t, np.full(6, t))


def test_taught_points_replace_delete_and_reorder() -> None:
    points = TaughtPoints()
    assert points.sync([_point("P1", 1.0), _point("W1", 2.0)])
    assert points.next_waypoint() == "W2"
    assert points.sync([_point("P1", 1.0), _point("W1", 2.0), _point("P1", 3.0)])
    assert [(p.label, p.t) for p in points.points] == [("P1", 3.0), ("W1", 2.0)]
    assert not points.sync([_point("P1", 1.0), _point("W1", 2.0), _point("P1", 3.0)])
    points.move("W1", -1)
    points.move("W1", -5)                    # stays first
    assert [p.label for p in points.points] == ["W1", "P1"]
    points.delete("W1")
    assert [p.label for p in points.points] == ["P1"]
    with pytest.raises(TeachError, match="W7"):
        points.delete("W7")


def test_export_with_one_point_says_why_there_is_no_path(sim: SimulatedPendantSession,
                                                         er20: Robot, tmp_path: Path) -> None:
    sim.live.send(MarkPoint("P1"))
    snap = until(sim.live, lambda s: len(s.marks) == 1, 0.05, "the mark")
    first = export_taught(sim.live.session_log(snap.marks), list(snap.marks), er20, tmp_path)
    second = export_taught(sim.live.session_log(snap.marks), list(snap.marks), er20, tmp_path)
    assert first.program is None and "only one mark" in first.note
    assert sorted(first.files) == ["points", "session"]
    assert second.folder.name == "export-002"


def test_describe_names_the_fault_and_its_value() -> None:
    from leadthrough.control.safety import Cause, Event
    ev = Event(1.0, State.GUIDING, State.FAULT, Cause.FAULT, Fault.FOLLOWING_ERROR, 0.0512, 2)
    assert describe(ev) == "FOLLOWING_ERROR: joint 3, 0.0512 rad"
    ev = Event(1.0, State.GUIDING, State.FAULT, Cause.FAULT, Fault.COLLISION, 163.2, 0)
    assert describe(ev) == "COLLISION: force 163 N"
    assert describe(Event(1.0, State.IDLE, State.GUIDING, Cause.DEADMAN_PRESSED)) == \
        "DEADMAN_PRESSED"


# --------------------------------------------------------------------- shipped parameters
def test_the_shipped_parameters_guide_the_simulated_er20(er20: Robot) -> None:
    """The parameters shipped for the pendant still fit the simulator: a 40 N push moves the
    arm to the speed limit, the release stops it, and at rest nothing moves."""
    params = shipped_guiding_params(er20)
    assert params.sim_seed == 1 and params.method == "consistent"
    loop = LoopConfig(guiding=light_guiding())
    push = run_sim_session(er20, params, SimSessionConfig(operator="push-x", loop=loop))
    assert push.summary.faults == []
    assert push.summary.max_linear_speed > 0.19
    assert push.summary.release_overrun_m is not None and push.summary.release_overrun_m < 5e-3
    rest = run_sim_session(er20, params, SimSessionConfig(operator="rest", duration_s=4.0,
                                                          loop=loop))
    assert np.all(rest.result.log.twist_cmd_base == 0.0)


def _moves_again_at_rest(er20: Robot, guiding: GuidingConfig, run: int) -> float | None:
    """A 17 s push-x session with the shipped parameters (sensor noise ``run``): from the settle
    time (the first cycle at rest after the release, plus ``settle_s``) to the end, None if the
    commanded twist stays exactly 0 and the commanded TCP within 1 mm, else how far it moved
    [m]."""
    push = run_sim_session(er20, shipped_guiding_params(er20), SimSessionConfig(
        operator="push-x", duration_s=17.0, run=run, loop=LoopConfig(guiding=guiding)))
    log = push.log
    release = push_x().pushes[0].t_end
    moving = np.any(log.twist_cmd_base != 0.0, axis=1)
    stopped = np.flatnonzero((log.time >= release) & ~moving)[0]
    settled = log.time >= log.time[stopped] + guiding.settle_s
    assert log.time[-1] - log.time[settled][0] > 10.0       # 10 s and more of rest to check
    travel = np.linalg.norm(log.tcp_cmd_base[settled] - log.tcp_cmd_base[stopped], axis=1)
    if moving[settled].any() or travel.max() >= 1e-3:
        return float(travel.max())
    return None


#: Sessions (sensor noise) of the rest-after-release checks.
REST_RUNS = (500, 501, 502, 503)


def test_after_a_release_the_tool_stays_at_rest(er20: Robot) -> None:
    """Issue 24: with the shipped parameters (identified on the realistic plant) the estimate
    drifts at rest after the release (the servo's integral against the gears' static friction,
    3-8 N/s on this instance); before rest_drift.py the tool moved again from 11-14 s on. With
    the stop after letting go it stays at rest in every session (sensor noise draws 500-503):
    the commanded twist exactly 0, the commanded TCP within 1 mm."""
    guiding = replace(light_guiding(), hand_release=HandReleaseConfig(enabled=True))
    assert [_moves_again_at_rest(er20, guiding, run) for run in REST_RUNS] == [None] * 4


@pytest.mark.xfail(strict=True,
                   reason="issue 24: with the law alone (no stop after letting go) the tool "
                          "moves again at rest in 3 of 8 sensor-noise draws (runs 500-507: up "
                          "to 29 mm before 2026-11-28's force fit, up to 11 mm after; README, "
                          "Limitations, run-on)")
def test_after_a_release_the_law_alone_stays_at_rest(er20: Robot) -> None:
    assert [_moves_again_at_rest(er20, light_guiding(), run) for run in REST_RUNS] == [None] * 4


def test_marks_stop_at_the_limit_with_a_notice(er20: Robot,
                                               nominal_params: ParamsFile) -> None:
    """The loop's one request handler: marks up to :data:`MAX_MARKS`, then a notice; a
    simulator's request on a loop without a simulator is refused with a notice."""
    from leadthrough.session.servo_loop import MAX_MARKS
    from loop_helpers import bare_loop
    loop = bare_loop(er20, nominal_params)
    loop.fb.q[:] = 0.0
    for k in range(MAX_MARKS + 1):
        loop.serve(MarkPoint(f"W{k + 1}"), float(k))
    assert len(loop.marks) == MAX_MARKS and loop.marks[-1].label == f"W{MAX_MARKS}"
    assert loop.notices[-1].text.startswith(f"not marked: {MAX_MARKS} marks")
    assert sum(e.kind == "mark" for e in loop.events) == MAX_MARKS
    loop.serve(InjectFault(InjectedFaultKind.STALE, 0.0, 1.0), 0.0)      # not a simulator
    assert loop.notices[-1].text == "not a simulator: InjectFault refused"
