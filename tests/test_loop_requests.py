"""Requests into a running loop and its published snapshot: marks, live settings, stop, the
software enabling device, argument checks, the sequence lock, and a real second thread."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from leadthrough.control.safety_states import State
from leadthrough.drivers.protocol import Driver, DriverFeedback, WrappedDriver
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.session.loop import EndCause
from leadthrough.session.loop_config import LoopConfig
from leadthrough.session.requests import MAX_PENDING, LoopRequests
from leadthrough.session.snapshot import LoopSnapshot, SnapshotBoard
from leadthrough.sim.session import SimSessionConfig, light_guiding, run_sim_session

LIMIT_ACC = 0.4  # m/s², Table IV
LIGHT = LoopConfig(guiding=light_guiding())


class Scripted(WrappedDriver):
    """Runs actions in the loop's own thread when the first sample at or after their time is
    read (deterministic: the same period every run)."""

    def __init__(self, driver: Driver, actions: list[tuple[float, Callable[[], None]]]) -> None:
        super().__init__(driver)
        self._actions = sorted(actions, key=lambda a: a[0])

    def read(self, fb: DriverFeedback) -> bool:
        fresh = self._driver.read(fb)
        while self._actions and fresh and fb.t >= self._actions[0][0] - 1e-9:
            self._actions.pop(0)[1]()
        return fresh


def _scripted(actions: list[tuple[float, Callable[[], None]]]) -> Callable[[Driver], Driver]:
    return lambda d: Scripted(d, actions)


def test_marks_settings_and_stop_at_rest(er20: Robot, nominal_params: ParamsFile) -> None:
    """Nobody pushes: settings apply at the next controller cycle, a friction below the
    session's floor is refused with a note, marks are taken at once (named or ``P<k>``), the
    snapshot shows it all, and a stop ends the loop at once (already at rest)."""
    req = LoopRequests()
    seen: dict[str, LoopSnapshot | None] = {}
    actions: list[tuple[float, Callable[[], None]]] = [
        (0.2, lambda: req.set_frame("tool")),
        (0.3, lambda: req.set_axes((True,) * 3 + (False,) * 3)),
        (0.4, lambda: req.set_virtual_mass((200.0,) * 3 + (500.0,) * 3)),
        (0.5, lambda: req.set_virtual_friction((5.0,) * 6)),          # below the floor (15)
        (0.6, lambda: req.set_virtual_friction((20.0,) * 6, (60.0,) * 6)),
        (0.7, lambda: req.mark("start")),
        (0.8, lambda: req.mark()),
        (0.9, lambda: seen.update(taring=req.snapshot())),
        (1.2, lambda: seen.update(guiding=req.snapshot())),
        (1.5, req.stop),
    ]
    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest",
                                                               duration_s=math.inf),
                        wrap_driver=_scripted(actions), requests=req)
    log = s.log
    assert s.result.end.cause is EndCause.STOP_REQUESTED
    assert 1.5 <= s.result.end.t < 1.502 and log.time[-1] == s.result.end.t
    loop_events = [(e.label, e.cause) for e in log.events if e.kind == "loop"]
    assert [label for label, _ in loop_events] == [
        "set_frame", "set_axes", "set_virtual_mass", "set_virtual_friction refused",
        "set_virtual_friction", "stop"]
    assert "range" in loop_events[3][1]
    assert [(m.label, round(m.t, 3)) for m in log.marks] == [("start", 0.7), ("P2", 0.8)]
    taring, guiding = seen["taring"], seen["guiding"]
    assert taring is not None and guiding is not None
    assert taring.estimator_status is EstimatorStatus.TARING and not taring.ready
    assert taring.state is State.IDLE and taring.enable_held is False
    assert guiding.state is State.GUIDING and guiding.enabled and guiding.ready
    assert guiding.frame == "tool" and guiding.axes_enabled == (True,) * 3 + (False,) * 3
    assert guiding.mass == (200.0,) * 3 + (500.0,) * 3
    assert guiding.friction == (20.0,) * 6 and guiding.stopping_friction == (60.0,) * 6
    assert [m.label for m in guiding.marks] == ["start", "P2"]
    assert guiding.q.shape == (6,) and np.all(np.isfinite(guiding.tcp_quaternion))
    assert 1.19 <= guiding.t <= 1.2 and guiding.running
    last = req.snapshot()
    assert last is not None and not last.running and last.end_cause == "stop requested"
    assert np.all(log.q_cmd == log.q_cmd[0])                       # never moved


def test_a_stop_request_while_moving_stops_at_the_limit(er20: Robot,
                                                        calibrated_params: ParamsFile) -> None:
    """Stop at 2 s during the push: STOPPING at the acceleration limit, the loop records until
    the commanded motion is at rest, then ends; a mass change asked while moving waits for rest,
    which comes with the end: it is noted as not made."""
    req = LoopRequests()
    actions: list[tuple[float, Callable[[], None]]] = [
        (1.5, lambda: req.set_virtual_mass((300.0,) * 6)), (2.0, req.stop)]
    s = run_sim_session(er20, calibrated_params, SimSessionConfig(
        operator="push-x", duration_s=math.inf, loop=LIGHT), wrap_driver=_scripted(actions),
        requests=req)
    log = s.log
    assert s.result.end.cause is EndCause.STOP_REQUESTED
    labels = [(e.label, e.cause) for e in log.events if e.kind == "transition"]
    assert ("GUIDING->STOPPING", "DEADMAN_RELEASED") in labels
    moving = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1)
    assert moving[np.searchsorted(log.time, 2.0)] > 0.05          # it was moving at the stop
    assert moving[-1] == 0.0 and np.all(log.qd_cmd[-1] == 0.0)
    cycles = log.twist_cmd_base[::10, :3]
    assert (np.linalg.norm(np.diff(cycles, axis=0), axis=1) / 0.01).max() <= LIMIT_ACC + 1e-9
    assert 2.0 < log.time[-1] < 3.0
    assert [e.label for e in log.events if e.kind == "loop"] == [
        "stop", "set_virtual_mass not made"]


def test_settings_asked_while_moving_wait_for_rest(er20: Robot,
                                                   calibrated_params: ParamsFile) -> None:
    """A mass asked at 1.5 s, during the push (1–4 s), is made at the first controller cycle
    at rest after the release, and shows in the snapshot from then on."""
    req = LoopRequests()
    snaps: list[LoopSnapshot | None] = []
    actions: list[tuple[float, Callable[[], None]]] = [
        (1.5, lambda: req.set_virtual_mass((300.0,) * 6)),
        (3.0, lambda: snaps.append(req.snapshot())), (5.9, lambda: snaps.append(req.snapshot()))]
    s = run_sim_session(er20, calibrated_params, SimSessionConfig(
        operator="push-x", duration_s=6.0, loop=LIGHT), wrap_driver=_scripted(actions),
        requests=req)
    log = s.log
    moving = np.linalg.norm(log.twist_cmd_base, axis=1) + np.abs(log.qd_cmd).sum(axis=1)
    last_move = float(log.time[np.flatnonzero(moving > 0.0)[-1]])
    mass = next(e for e in log.events if e.label == "set_virtual_mass")
    assert last_move < mass.t <= last_move + 0.011
    before, after = snaps
    assert before is not None and before.mass[0] == 100.0 and before.linear_speed > 0.1
    assert after is not None and after.mass == (300.0,) * 6


def test_software_enabling_device_on_a_simulated_robot(er20: Robot,
                                                       calibrated_params: ParamsFile) -> None:
    """A page's button held from the start does not count; released and pressed once ready, it
    starts guiding; released, the robot stops."""
    req = LoopRequests()
    req.set_enable(True)
    actions: list[tuple[float, Callable[[], None]]] = [
        (1.2, lambda: req.set_enable(False)), (1.3, lambda: req.set_enable(True)),
        (2.5, lambda: req.set_enable(False)), (4.5, req.stop)]
    s = run_sim_session(er20, calibrated_params, SimSessionConfig(
        operator="push-x", duration_s=math.inf, loop=LIGHT, software_enable=True),
        wrap_driver=_scripted(actions), requests=req)
    pressed = [e.t for e in s.log.events if e.cause == "DEADMAN_PRESSED"]
    released = [e.t for e in s.log.events if e.cause == "DEADMAN_RELEASED"]
    assert len(pressed) == 1 and 1.3 <= pressed[0] < 1.311
    assert len(released) == 1 and 2.5 <= released[0] < 2.511


def test_request_arguments_are_checked_in_the_callers_thread() -> None:
    req = LoopRequests()
    with pytest.raises(ControlError, match="frame"):
        req.set_frame("world")
    with pytest.raises(ControlError, match="axes"):
        req.set_axes((False,) * 6)
    with pytest.raises(ControlError, match="axes"):
        req.set_axes((True,) * 5)
    with pytest.raises(ControlError, match="mass"):
        req.set_virtual_mass((1.0,) * 6)                   # below MASS_RANGE
    with pytest.raises(ControlError, match="mass"):
        req.set_virtual_mass((100.0,) * 5 + (math.nan,))
    with pytest.raises(ControlError, match="stopping_friction"):
        req.set_virtual_friction((20.0,) * 6, (10.0,) * 6)
    with pytest.raises(ControlError, match="label"):
        req.mark("")
    with pytest.raises(ControlError, match="label"):
        req.mark("two\nlines")
    assert not req.pending and req.snapshot() is None
    for _ in range(MAX_PENDING):
        req.mark()
    with pytest.raises(ControlError, match="pending"):
        req.mark()


def test_software_enable_is_refused_on_a_real_robot(er20: Robot,
                                                    nominal_params: ParamsFile) -> None:
    class Real(WrappedDriver):
        simulated = False     # type: ignore[assignment]

    with pytest.raises(ControlError, match="software_enable"):
        run_sim_session(er20, nominal_params, SimSessionConfig(
            operator="rest", duration_s=math.inf, software_enable=True),
            wrap_driver=Real, requests=LoopRequests())


def test_the_board_never_hands_out_a_torn_snapshot() -> None:
    """A writer rewrites every field with one value per cycle, as fast as it can, while a reader
    copies: every snapshot read holds one cycle's values only."""
    board = SnapshotBoard()
    f = board.attach(6)
    stop = threading.Event()

    def write() -> None:
        k = 0
        while not stop.is_set():
            k += 1
            board.begin()
            f.t, f.period = float(k), k
            f.q = float(k)
            time.sleep(0)                    # let the reader in mid-write
            f.q_cmd = float(k)
            f.mark_count = 0
            board.end()
            time.sleep(0)                    # the loop waits for its next period here

    writer = threading.Thread(target=write)
    writer.start()
    try:
        reads = 0
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            snap = board.read()
            if snap is None:
                continue
            reads += 1
            assert np.all(snap.q == snap.t) and np.all(snap.q_cmd == snap.t)
            assert snap.period == int(snap.t)
    finally:
        stop.set()
        writer.join()
    assert reads > 100


def test_a_pendant_thread_talks_to_a_running_loop(er20: Robot,
                                                  nominal_params: ParamsFile) -> None:
    """The loop in one thread, a pendant in this one: it watches the snapshots, marks three
    points and stops the loop; every mark is recorded once, in order, and the loop ends on the
    stop."""
    req = LoopRequests()
    out: dict[str, object] = {}

    def run() -> None:
        out["session"] = run_sim_session(er20, nominal_params, SimSessionConfig(
            operator="rest", duration_s=math.inf), requests=req)

    loop = threading.Thread(target=run)
    loop.start()
    times = []
    try:
        while (snap := req.snapshot()) is None or snap.t < 0.2:
            time.sleep(0.01)
        for label in ("A", "B", "C"):
            req.mark(label)
            time.sleep(0.05)
            snap = req.snapshot()
            assert snap is not None
            times.append(snap.t)
        req.stop()
    finally:
        req.stop()
        loop.join(timeout=120)
    assert not loop.is_alive()
    assert times == sorted(times)
    session = out["session"]
    log = session.log               # type: ignore[attr-defined]
    assert [m.label for m in log.marks] == ["A", "B", "C"]
    assert session.result.end.cause is EndCause.STOP_REQUESTED   # type: ignore[attr-defined]
