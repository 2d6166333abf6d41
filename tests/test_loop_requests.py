"""Requests into a running loop: a stop (at rest and while moving), a fault reset served by the
loop, the bound on waiting requests, and a real second thread."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from leadthrough.drivers.protocol import Driver, DriverFeedback, WrappedDriver
from leadthrough.errors import ControlError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.session.loop import EndCause
from leadthrough.session.loop_config import LoopConfig
from leadthrough.session.requests import MAX_PENDING, ClearFault, LoopRequests
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


def test_a_stop_at_rest_ends_the_loop_at_once(er20: Robot, nominal_params: ParamsFile) -> None:
    """Nobody pushes: a stop asked at 1.5 s ends the loop in that controller cycle (already at
    rest), noted once, and the robot never moved."""
    req = LoopRequests()
    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest",
                                                               duration_s=math.inf),
                        wrap_driver=_scripted([(1.5, req.stop)]), requests=req)
    log = s.log
    assert s.result.end.cause is EndCause.STOP_REQUESTED
    assert 1.5 <= s.result.end.t < 1.502 and log.time[-1] == s.result.end.t
    assert [e.label for e in log.events if e.kind == "loop"] == ["stop"]
    assert np.all(log.q_cmd == log.q_cmd[0])                       # never moved


def test_a_reset_request_without_a_fault_is_refused_with_a_note(
        er20: Robot, nominal_params: ParamsFile) -> None:
    """The loop serves a queued reset at its next period: with no fault latched it is refused,
    and the recording says why; the session goes on to its stop."""
    req = LoopRequests()
    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest",
                                                               duration_s=math.inf),
                        wrap_driver=_scripted([(0.5, req.reset_fault), (0.8, req.stop)]),
                        requests=req)
    notes = [(round(e.t, 3), e.label, e.cause) for e in s.log.events if e.kind == "loop"]
    assert notes[0] == (0.5, "reset refused", "no fault is latched")
    assert [label for _, label, _ in notes] == ["reset refused", "stop"]
    assert s.result.end.cause is EndCause.STOP_REQUESTED


def test_a_stop_request_while_moving_stops_at_the_limit(er20: Robot,
                                                        calibrated_params: ParamsFile) -> None:
    """Stop at 2 s during the push: STOPPING at the acceleration limit, the loop records until
    the commanded motion is at rest, then ends."""
    req = LoopRequests()
    actions: list[tuple[float, Callable[[], None]]] = [(2.0, req.stop)]
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
    assert [e.label for e in log.events if e.kind == "loop"] == ["stop"]


def test_waiting_requests_are_bounded_and_taken_in_order() -> None:
    """Requests wait in order until the loop takes them; beyond :data:`MAX_PENDING` the caller
    is told (the loop is not running)."""
    req = LoopRequests()
    assert not req.pending and req.poll() is None and not req.stop_requested
    for _ in range(MAX_PENDING):
        req.reset_fault()
    with pytest.raises(ControlError, match="pending"):
        req.reset_fault()
    assert req.pending
    taken = [req.poll() for _ in range(MAX_PENDING)]
    assert taken == [ClearFault()] * MAX_PENDING
    assert not req.pending and req.poll() is None
    req.stop()
    assert req.stop_requested


def test_another_thread_stops_a_running_loop(er20: Robot, nominal_params: ParamsFile) -> None:
    """The loop in one thread, a caller in this one: its stop ends the session, which had no
    end of its own."""
    req = LoopRequests()
    out: dict[str, object] = {}

    def run() -> None:
        out["session"] = run_sim_session(er20, nominal_params, SimSessionConfig(
            operator="rest", duration_s=math.inf), requests=req)

    loop = threading.Thread(target=run)
    loop.start()
    try:
        time.sleep(0.3)
    finally:
        req.stop()
        loop.join(timeout=120)
    assert not loop.is_alive()
    session = out["session"]
    assert session.result.end.cause is EndCause.STOP_REQUESTED   # type: ignore[attr-defined]
