"""The loop's ways out on the simulator: the robot controller's own stops, driver exceptions,
a lost link, a late and a blocked exchange (the watchdog); each ends in a commanded stop at the
acceleration limit (or no command once the link is gone), latched and logged, and a fault reset
re-arms without restarting."""

from __future__ import annotations

import dataclasses
import gc
import json
import math
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.protocol import ControllerState, Driver, JointCommand, WrappedDriver
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session import servo_loop as loop_start
from leadthrough.session.loop import GIL_SWITCH_S, EndCause, LoopResult, run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.session.pacing import VirtualClock
from leadthrough.session.requests import LoopRequests
from leadthrough.session.servo_loop import ServoLoop
from leadthrough.session.session_file import SessionFileSink
from leadthrough.session.watchdog import STACK_BYTES, DriverWatchdog
from leadthrough.session_format import SessionLog, load_session
from leadthrough.sim.driver import InjectedFault, InjectedFaultKind, InputScript, SimDriver
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.session import SimSessionConfig, light_guiding, run_sim_session

LIMIT_ACC = 0.4  # m/s², Table IV
LIGHT = LoopConfig(guiding=light_guiding())


class Scripted(WrappedDriver):
    """Runs actions in the loop's thread at the first sample at or after their time."""

    def __init__(self, driver: Driver, actions: list[tuple[float, Callable[[], None]]]) -> None:
        super().__init__(driver)
        self._actions = sorted(actions, key=lambda a: a[0])

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        while self._actions and fresh and fb.t >= self._actions[0][0] - 1e-9:
            self._actions.pop(0)[1]()
        return fresh


class Real(WrappedDriver):
    """The simulated driver, presented as a real one: the loop's watchdog watches it."""

    simulated = False  # type: ignore[assignment]


class Clocked(Real):
    """A real controller on a virtual clock: each ``step`` waits one period of the clock the
    loop reads (the test scripts the controller's timing; nothing depends on the machine's
    speed)."""

    def __init__(self, driver: Driver, clock: VirtualClock) -> None:
        super().__init__(driver)
        self.clock = clock

    def step(self) -> None:
        self.clock.advance(self.dt)
        self._driver.step()


def _stops_at_the_limit(log: SessionLog) -> None:
    cycles = log.twist_cmd_base[::10, :3]
    assert (np.linalg.norm(np.diff(cycles, axis=0), axis=1) / 0.01).max() <= LIMIT_ACC + 1e-9
    assert np.all(np.abs(np.diff(log.q_cmd, axis=0)) < 1e-3)      # no position jump


def _fault_at(log: SessionLog) -> tuple[float, Fault]:
    first = int(np.argmax(log.state == int(State.FAULT)))
    return float(log.time[first]), Fault(int(log.fault[first]))


def _notes(log: SessionLog) -> list[tuple[str, str]]:
    return [(e.label, e.cause) for e in log.events if e.kind == "loop"]


def test_emergency_stop_latches_stops_and_resets_to_a_fresh_press(
        er20: Robot, calibrated_params: ParamsFile) -> None:
    """E-stop at 2 s during the push, released at 3.5 s. A reset at 3 s is refused (the
    controller still reports it), one at 4 s is made: the loop restarts at the measured
    position and tares again; the device held through the reset does not count, a fresh press
    after the tare guides again."""
    req = LoopRequests()
    actions: list[tuple[float, Callable[[], None]]] = [(3.0, req.reset_fault),
                                                       (4.0, req.reset_fault)]
    cfg = SimSessionConfig(
        operator="push-x", duration_s=7.0, loop=LIGHT,
        faults=(InjectedFault(InjectedFaultKind.ESTOP, t_start=2.0, t_end=3.5),),
        enable_held_s=((1.0, 4.5), (5.8, math.inf)))
    s = run_sim_session(er20, calibrated_params, cfg,
                        wrap_driver=lambda d: Scripted(d, actions), requests=req)
    log = s.log
    t_fault, fault = _fault_at(log)
    assert fault is Fault.CONTROLLER_STATE and 2.0 <= t_fault < 2.011
    assert np.linalg.norm(log.twist_cmd_base[np.searchsorted(log.time, 1.99), :3]) > 0.05
    notes = _notes(log)
    assert notes[0] == ("controller state", "ESTOP")
    assert notes[1][0] == "reset refused" and "ESTOP" in notes[1][1]
    assert notes[2][0] == "fault reset"
    during = (log.time >= t_fault) & (log.time < 4.0)
    assert np.all(log.state[during] == int(State.FAULT))         # latched
    moved = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1)
    assert np.all(moved[(log.time > 3.0) & (log.time < 5.8)] == 0.0)
    _stops_at_the_limit(_before(log, 4.0))
    transitions = [(round(e.t, 3), e.label, e.cause) for e in log.events
                   if e.kind == "transition"]
    assert (4.0, "FAULT->IDLE", "RESET") in transitions
    again = [t for t, label, cause in transitions if cause == "DEADMAN_PRESSED"]
    assert len(again) == 2 and 5.8 <= again[1] < 5.811
    assert s.result.end.cause is EndCause.DURATION


def _before(log: SessionLog, t: float) -> SessionLog:
    """The log's rows before ``t`` (for the checks of a stop)."""
    keep = log.time < t
    return SessionLog(robot=log.robot, time=log.time[keep], q=log.q[keep],
                      current=log.current[keep], tau_ext=log.tau_ext[keep],
                      wrench_base=log.wrench_base[keep], q_cmd=log.q_cmd[keep],
                      qd_cmd=log.qd_cmd[keep], tcp_cmd_base=log.tcp_cmd_base[keep],
                      tcp_cmd_quat=log.tcp_cmd_quat[keep], twist_cmd_base=log.twist_cmd_base[keep],
                      state=log.state[keep], fault=log.fault[keep])


@pytest.mark.parametrize(("kind", "state"), [
    (InjectedFaultKind.PROTECTIVE_STOP, ControllerState.PROTECTIVE_STOP),
    (InjectedFaultKind.REJECTED, ControllerState.COMMAND_REJECTED)])
def test_controller_states_are_fault_inputs(er20: Robot, nominal_params: ParamsFile,
                                            kind: InjectedFaultKind,
                                            state: ControllerState) -> None:
    s = run_sim_session(er20, nominal_params, SimSessionConfig(
        operator="rest", duration_s=2.0, faults=(InjectedFault(kind, 1.5, 1.52),)))
    t_fault, fault = _fault_at(s.log)
    assert fault is Fault.CONTROLLER_STATE and 1.5 <= t_fault < 1.511
    assert np.all(s.log.state[s.log.time >= t_fault] == int(State.FAULT))
    assert ("controller state", state.name) in _notes(s.log)


def test_one_driver_exception_stops_at_the_limit_and_resets(
        er20: Robot, calibrated_params: ParamsFile) -> None:
    """One read raises at 2 s, mid-push: DRIVER_ERROR, the stop at the limit is still
    commanded (the link works again), and a reset at rest clears it."""
    req = LoopRequests()
    s = run_sim_session(er20, calibrated_params, SimSessionConfig(
        operator="push-x", duration_s=5.0, loop=LIGHT,
        faults=(InjectedFault(InjectedFaultKind.RAISE, 2.0, 2.0005),)),
        wrap_driver=lambda d: Scripted(d, [(4.5, req.reset_fault)]), requests=req)
    log = s.log
    t_fault, fault = _fault_at(log)
    assert fault is Fault.DRIVER_ERROR and 2.0 <= t_fault < 2.011
    assert np.linalg.norm(log.twist_cmd_base[np.searchsorted(log.time, 1.99), :3]) > 0.05
    _stops_at_the_limit(_before(log, 4.5))
    notes = _notes(log)
    assert notes[0][0] == "driver error" and "injected link failure" in notes[0][1]
    assert notes[1][0] == "fault reset"
    assert State(int(log.state[-1])) is State.IDLE and s.result.end.cause is EndCause.DURATION


def test_a_lost_link_ends_the_loop_without_commanding(er20: Robot,
                                                      nominal_params: ParamsFile) -> None:
    """Every read raises from 2 s on: the first failure latches the fault, the second ends the
    loop (LINK_LOST) at once; nothing is written after it, and nothing escapes the loop."""
    drivers: list[SimDriver] = []

    def keep(d: Driver) -> Driver:
        assert isinstance(d, SimDriver)
        drivers.append(d)
        return d

    s = run_sim_session(er20, nominal_params, SimSessionConfig(
        operator="push-x", duration_s=5.0,
        faults=(InjectedFault(InjectedFaultKind.RAISE, 2.0),)), wrap_driver=keep)
    end = s.result.end
    assert end.cause is EndCause.LINK_LOST and 2.0 < end.t < 2.0025
    assert end.fault is Fault.DRIVER_ERROR and "injected link failure" in end.detail
    assert drivers[0].writes == len(s.log.time)       # one write per period, none after
    assert [label for label, _ in _notes(s.log)] == ["driver error", "link lost"]


def test_any_exception_of_a_driver_is_a_fault(er20: Robot, nominal_params: ParamsFile) -> None:
    """A driver with a bug (its write raises ZeroDivisionError once): a fault, not a crash."""
    class Buggy(WrappedDriver):
        calls = 0

        def write(self, cmd: JointCommand) -> None:
            self.calls += 1
            if self.calls == 1500:
                raise ZeroDivisionError("division by zero")
            super().write(cmd)

    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest", duration_s=2.0),
                        wrap_driver=Buggy)
    t_fault, fault = _fault_at(s.log)
    assert fault is Fault.DRIVER_ERROR and 1.499 <= t_fault < 1.511
    assert _notes(s.log)[0] == ("driver error", "ZeroDivisionError: division by zero")


def _real_session(robot: Robot, params: ParamsFile, fault: InjectedFault, watchdog_s: float,
                  duration_s: float) -> LoopResult:
    """A session on the simulated robot presented as a real one (the watchdog is on)."""
    sim = SimDriver(SimRobot(robot, SimConfig(seed=1), q0=guide_start_pose(robot)))
    sim.inject(fault)
    sim.script_input(InputScript(0, ((1.0, math.inf),)))
    parts = build_loop(robot, params, LoopConfig(), sim.dt)
    return run_session(Real(sim), *parts, duration_s,
                       options=LoopOptions(enable_input=0, watchdog_s=watchdog_s))


class Blocking(Clocked):
    """One exchange at ``at`` [s] that takes ``block_s`` on the clock."""

    def __init__(self, driver: Driver, clock: VirtualClock, at: float, block_s: float) -> None:
        super().__init__(driver, clock)
        self.at, self.block_s, self.t = at, block_s, 0.0

    def step(self) -> None:
        if self.t >= self.at - 1e-9 and self.block_s:
            self.clock.advance(self.block_s)
            self.block_s = 0.0
        super().step()

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        self.t = fb.t
        return fresh


def test_a_late_exchange_is_a_timeout_fault(er20: Robot, nominal_params: ParamsFile) -> None:
    """A step that takes 0.6 s at 1.5 s (watchdog 0.15 s; on a virtual clock):
    DRIVER_TIMEOUT with the time it took; the link answered, so the loop goes on to its
    end."""
    clock = VirtualClock()
    sim = SimDriver(SimRobot(er20, SimConfig(seed=1), q0=guide_start_pose(er20)))
    sim.script_input(InputScript(0, ((1.0, math.inf),)))
    parts = build_loop(er20, nominal_params, LoopConfig(), sim.dt)
    r = run_session(Blocking(sim, clock, 1.5, 0.6), *parts, 2.0,
                    options=LoopOptions(enable_input=0, watchdog_s=0.15), clock=clock)
    assert r.log is not None
    t_fault, fault = _fault_at(r.log)
    assert fault is Fault.DRIVER_TIMEOUT and 1.5 <= t_fault < 1.511, t_fault
    label, detail = _notes(r.log)[0]
    assert label == "driver timeout" and "watchdog 150 ms" in detail
    assert detail.startswith("an exchange took 601.0 ms"), detail   # the block and a period
    assert r.end.cause is EndCause.DURATION


def test_a_blocked_exchange_is_aborted_by_the_watchdog(er20: Robot,
                                                       nominal_params: ParamsFile) -> None:
    """A step that would block for ever at 1.5 s: the watchdog aborts it, and the loop ends
    (LINK_LOST, DRIVER_TIMEOUT) instead of hanging."""
    out: list[LoopResult] = []
    worker = threading.Thread(target=lambda: out.append(_real_session(
        er20, nominal_params, InjectedFault(InjectedFaultKind.BLOCK, 1.5, block_s=math.inf),
        0.15, 3.0)))
    worker.start()
    worker.join(timeout=300)
    assert not worker.is_alive() and out
    end = out[0].end
    assert end.cause is EndCause.LINK_LOST and end.fault is Fault.DRIVER_TIMEOUT
    assert 1.5 <= end.t < 1.511 and "aborted" in end.detail


class TimingOut(Clocked):
    """A real controller gone silent: while no sample comes, each step waits ``wait_s`` (a
    driver's receive timeout, several periods) on the clock before it returns empty-handed."""

    def __init__(self, driver: Driver, clock: VirtualClock, wait_s: float) -> None:
        super().__init__(driver, clock)
        self.wait_s, self.fresh = wait_s, True

    def step(self) -> None:
        if not self.fresh:
            self.clock.advance(self.wait_s - self.dt)
        super().step()

    def read(self, fb):  # type: ignore[no-untyped-def]
        self.fresh = self._driver.read(fb)
        return self.fresh


def test_feedback_silent_beyond_the_stale_limit_is_stale_on_the_wall_clock(
        er20: Robot, nominal_params: ParamsFile) -> None:
    """No sample from 1.5 s for 0.2 s, each empty step lasting 3 periods (the driver's
    timeout; on a virtual clock): STALE_FEEDBACK once 3 controller cycles and a period of
    jitter (31 ms) went by on the clock, 11 such periods, not 3 cycles of them (90 ms: the
    fault would come at 1.53 s on the loop's clock)."""
    clock = VirtualClock()
    sim = SimDriver(SimRobot(er20, SimConfig(seed=1), q0=guide_start_pose(er20)))
    sim.inject(InjectedFault(InjectedFaultKind.STALE, 1.5, 1.7))
    parts = build_loop(er20, nominal_params, LoopConfig(), sim.dt)
    r = run_session(TimingOut(sim, clock, 3 * sim.dt), *parts, 2.0,
                    options=LoopOptions(enable_input=0, watchdog_s=0.05), clock=clock)
    assert r.log is not None
    t_fault, fault = _fault_at(r.log)
    assert fault is Fault.STALE_FEEDBACK and 1.5 < t_fault < 1.52, t_fault    # 1.511-1.512
    label, detail = _notes(r.log)[0]
    assert label == "stale feedback" and "limit 31 ms" in detail
    assert int(detail.split("for ")[1].split(" ms")[0]) >= 31


class Closable(WrappedDriver):
    """The simulated robot as a real controller's driver with a ``close`` (the stream's own
    stop) that may fail; the sink's ``finish`` notes whether the driver was closed then."""

    simulated = False  # type: ignore[assignment]
    stop_method = "the test's stop"

    def __init__(self, driver: Driver, fail: bool = False, interrupt_at: float = math.inf,
                 close_s: float = 0.0) -> None:
        super().__init__(driver)
        self.fail, self.interrupt_at, self.closed, self.t = fail, interrupt_at, 0, 0.0
        self.close_s, self.aborted = close_s, 0
        self.closed_with: list[tuple[float, bool]] = []  # switch interval, collector on

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        self.t = fb.t
        if self.t >= self.interrupt_at:
            raise KeyboardInterrupt       # a second Ctrl-C: escapes the loop
        return fresh

    def close(self) -> None:
        self.closed += 1
        self.closed_with.append((sys.getswitchinterval(), gc.isenabled()))
        time.sleep(self.close_s)   # the stream's stop takes a while (RSI: the next document)
        if self.fail:
            raise OSError("the controller went away")

    def abort(self) -> None:
        self.aborted += 1


def _closing_session(robot: Robot, params: ParamsFile, path: Path, driver: Closable,
                     requests: LoopRequests | None = None, watchdog_s: float = 0.5,
                     ) -> tuple[SessionLog, list[int]]:
    """A 1 s session on ``driver`` recorded to ``path``; the file, and ``driver.closed`` when
    the sink was finished."""
    sink = SessionFileSink(path, robot.n)
    at_finish: list[int] = []
    finish = sink.finish

    def finish_after_close(*args, **kwargs):  # type: ignore[no-untyped-def]
        at_finish.append(driver.closed)
        return finish(*args, **kwargs)

    sink.finish = finish_after_close  # type: ignore[method-assign]
    parts = build_loop(robot, params, LoopConfig(), driver.dt)
    try:
        run_session(driver, *parts, 1.0,
                    options=LoopOptions(enable_input=0, watchdog_s=watchdog_s),
                    requests=requests, sink=sink)
    finally:
        out = load_session(path)
    return out, at_finish


def _sim(robot: Robot) -> SimDriver:
    return SimDriver(SimRobot(robot, SimConfig(seed=1), q0=guide_start_pose(robot)))


def test_every_way_out_stops_the_driver_before_the_file_is_finished(
        er20: Robot, nominal_params: ParamsFile, tmp_path: Path) -> None:
    """The end of the duration, a stop request, an exception escaping the loop (a second
    Ctrl-C): each closes the driver (its stream's own stop) once, before the recording is
    finished, and the file logs it with how the session ended."""
    driver = Closable(_sim(er20))
    gc_on, interval = gc.isenabled(), sys.getswitchinterval()
    log, at_finish = _closing_session(er20, nominal_params, tmp_path / "a.parquet", driver)
    assert at_finish == [1] and driver.closed == 1
    assert _notes(log)[-1] == ("driver stopped", "after duration; the test's stop")
    # the stop answers the controller's waiting packet before the loop's settings are undone
    assert driver.closed_with == [(pytest.approx(GIL_SWITCH_S), False)]
    assert (gc.isenabled(), sys.getswitchinterval()) == (gc_on, interval)

    req = LoopRequests()
    driver = Closable(Scripted(_sim(er20), [(0.5, req.stop)]))
    log, at_finish = _closing_session(er20, nominal_params, tmp_path / "b.parquet", driver,
                                      req)
    assert at_finish == [1] and _notes(log)[-1][1].startswith("after stop requested")

    driver = Closable(_sim(er20), interrupt_at=0.5)
    with pytest.raises(KeyboardInterrupt):
        _closing_session(er20, nominal_params, tmp_path / "c.parquet", driver)
    log = load_session(tmp_path / "c.parquet")
    assert driver.closed == 1 and log.time[-1] < 0.51
    assert _notes(log)[-1] == ("driver stopped", "after KeyboardInterrupt; the test's stop")
    assert driver.closed_with == [(pytest.approx(GIL_SWITCH_S), False)]
    assert (gc.isenabled(), sys.getswitchinterval()) == (gc_on, interval)


def test_the_driver_stop_after_a_second_ctrl_c_is_no_blocked_exchange(
        er20: Robot, nominal_params: ParamsFile, tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    """A second Ctrl-C escaping from the driver's ``read`` leaves no exchange open: the
    driver's stop that follows (1.2 s here, the watchdog at 50 ms, its abort after 1 s) is not
    taken for a blocked call, logged or aborted, while the watchdog still runs."""
    driver = Closable(_sim(er20), interrupt_at=0.5, close_s=1.2)
    with pytest.raises(KeyboardInterrupt):
        _closing_session(er20, nominal_params, tmp_path / "c.parquet", driver, watchdog_s=0.05)
    assert driver.closed == 1 and driver.aborted == 0
    assert "blocked" not in caplog.text


def test_a_failing_driver_stop_is_logged_and_the_file_is_complete(
        er20: Robot, nominal_params: ParamsFile, tmp_path: Path) -> None:
    driver = Closable(_sim(er20), fail=True)
    gc_on, interval = gc.isenabled(), sys.getswitchinterval()
    log, at_finish = _closing_session(er20, nominal_params, tmp_path / "s.parquet", driver)
    assert at_finish == [1] and log.time.size == 1000          # every period, then the events
    assert _notes(log)[-1] == ("driver stop failed",
                               "after duration; OSError: the controller went away")
    assert (gc.isenabled(), sys.getswitchinterval()) == (gc_on, interval)


class Stalling(Clocked):
    """A real controller whose sample of 1.5 s comes 40 ms late on the clock: the
    controller's own next sample or, ``jump``, with 39 newer ones queued behind it (the
    loop's process stalled; the newest is read)."""

    def __init__(self, driver: Driver, clock: VirtualClock, jump: bool) -> None:
        super().__init__(driver, clock)
        self.jump, self.t, self.done = jump, 0.0, False

    def step(self) -> None:
        if self.t >= 1.5 and not self.done:
            self.done = True
            self.clock.advance(0.04)
            for _ in range(39 if self.jump else 0):
                self._driver.step()
                self._driver.read(self._driver.make_feedback())
        super().step()

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        self.t = fb.t
        return fresh


@pytest.mark.parametrize("jump", [False, True])
def test_a_sample_that_comes_late_is_stale_feedback(er20: Robot, nominal_params: ParamsFile,
                                                    jump: bool) -> None:
    """The sample after 1.5 s comes 40 ms late (over the 31 ms limit) within one exchange:
    the controller's packets were late (the next in sequence): STALE_FEEDBACK when it comes.
    The same wait with newer samples queued behind it is the loop's own lateness (the
    controller sent on time; it reports missed answers its own way): no fault."""
    sim = _sim(er20)
    clock = VirtualClock()
    parts = build_loop(er20, nominal_params, LoopConfig(), sim.dt)
    r = run_session(Stalling(sim, clock, jump), *parts, 2.0,
                    options=LoopOptions(enable_input=0, watchdog_s=0.2), clock=clock)
    assert r.log is not None
    if jump:
        assert not np.any(r.log.state == int(State.FAULT)), _notes(r.log)
        return
    t_fault, fault = _fault_at(r.log)
    assert fault is Fault.STALE_FEEDBACK and 1.5 <= t_fault < 1.51, t_fault   # that sample
    label, detail = _notes(r.log)[0]
    assert label == "stale feedback" and detail.endswith("(limit 31 ms); then a late one")


class Paced(WrappedDriver):
    """A real controller's packets on the wall clock, one every 8 ms, the first 0.9 cycle
    before the loop's first step; ``step`` returns the newest one that has come, at once when
    one is waiting, else waits for the next. The robot stands still (each packet repeats the
    simulator's first sample, with its own time and sequence number). Kept: for each answer,
    whether its packet had been waiting when the step that returned it began (it may have
    come up to a cycle before: its answer may be late)."""

    simulated = False  # type: ignore[assignment]

    def __init__(self, driver: Driver) -> None:
        super().__init__(driver)
        self.sample = driver.make_feedback()
        driver.step()
        driver.read(self.sample)
        self.t0 = math.nan
        self.k, self.answered, self.new, self.waiting = -1, -1, False, False
        self.answers: list[tuple[int, bool]] = []

    @property
    def dt(self) -> float:
        return 0.008

    def step(self) -> None:
        if math.isnan(self.t0):
            self.t0 = time.perf_counter() - 0.9 * self.dt
        due = math.floor((time.perf_counter() - self.t0) / self.dt)
        self.waiting = due > self.k
        if not self.waiting:
            due = self.k + 1
            time.sleep(max(0.0, self.t0 + due * self.dt - time.perf_counter()))
        self.k, self.new = due, True

    def read(self, fb):  # type: ignore[no-untyped-def]
        if not self.new:
            return False
        self.new = False
        fb.q[:], fb.current[:] = self.sample.q, self.sample.current
        fb.t, fb.sequence = self.k * self.dt, self.k
        return True

    def write(self, cmd: JointCommand) -> None:
        if self.answered != self.k:
            self.answered = self.k
            self.answers.append((self.k, self.waiting))


def test_the_first_answers_go_out_a_whole_cycle_ahead(
        er20: Robot, nominal_params: ParamsFile, monkeypatch: pytest.MonkeyPatch) -> None:
    """A controller at 8 ms whose first packet has been waiting 0.9 cycle when the loop
    starts, and a set-up compute of 1.9 cycles: the hold answered at once and the first
    period's answer each answer a packet waited for, not one that was waiting (come up to a
    cycle before, its answer may reach the controller late: J519 refuses it and reports it,
    a CONTROLLER_STATE fault at the stream's start)."""
    monkeypatch.setattr(ServoLoop, "dry_periods", _then_sleep(ServoLoop.dry_periods))
    driver = Paced(_sim(er20))
    _paced_session(er20, nominal_params, driver)
    assert [waiting for _, waiting in driver.answers[:2]] == [False, False], driver.answers


def _then_sleep(function: Callable[..., None]) -> Callable[..., None]:
    """``function``, then 1.9 cycles of 8 ms more."""
    def slow(*args: object) -> None:
        function(*args)
        time.sleep(1.9 * 0.008)
    return slow


def _paced_session(robot: Robot, params: ParamsFile, driver: Paced) -> None:
    """0.1 s of the loop at the paced driver's 8 ms, to its end."""
    config = LoopConfig(guiding=dataclasses.replace(LoopConfig().guiding, dt=0.008))
    parts = build_loop(robot, params, config, driver.dt)
    r = run_session(driver, *parts, 0.1, options=LoopOptions(enable_input=0, watchdog_s=0.5))
    assert r.end.cause is EndCause.DURATION


class AnswerLog(WrappedDriver):
    """The simulated robot as a real controller's driver that notes which samples got an
    answer (a write before the next step)."""

    simulated = False  # type: ignore[assignment]

    def __init__(self, driver: Driver) -> None:
        super().__init__(driver)
        self.taken: list[int] = []
        self.answered: set[int] = set()

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        if fresh:
            self.taken.append(fb.sequence)
        return fresh

    def write(self, cmd: JointCommand) -> None:
        if self.taken:
            self.answered.add(self.taken[-1])
        self._driver.write(cmd)


class RsiLike(AnswerLog):
    answer_late_packets = True  # type: ignore[assignment]


@pytest.mark.parametrize("answer_late", [False, True])
def test_the_start_answers_the_packets_that_waited_only_where_the_controller_wants_it(
        answer_late: bool, er20: Robot, nominal_params: ParamsFile) -> None:
    """The start takes four samples before the first period's: the first one (it may have
    waited since the driver opened), the next (waited for: answered at once), one that came
    during the set-up's compute, and the next (the first period answers it). A controller
    that counts an unanswered packet late (RSI) gets a hold for each; otherwise (J519 refuses
    a late answer) the two that may have waited go unanswered."""
    sim = SimDriver(SimRobot(er20, SimConfig(seed=1), q0=guide_start_pose(er20)))
    driver = (RsiLike if answer_late else AnswerLog)(sim)
    parts = build_loop(er20, nominal_params, LoopConfig(), sim.dt)
    r = run_session(driver, *parts, 0.05, options=LoopOptions(enable_input=0, watchdog_s=0.05))
    assert r.end.cause is EndCause.DURATION
    first = driver.taken[:4]
    assert first == sorted(set(first)) and len(first) == 4
    unanswered = [s for s in first if s not in driver.answered]
    assert unanswered == ([] if answer_late else [first[0], first[2]]), (first, unanswered)
    assert all(s in driver.answered for s in driver.taken[4:-1])   # the periods answer each


class PacedDelays(Paced):
    """:class:`Paced`, keeping for each answer how long after its packet was read it went
    out [s]."""

    def __init__(self, driver: Driver) -> None:
        super().__init__(driver)
        self.read_at = math.nan
        self.delays: list[float] = []

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = super().read(fb)
        if fresh:
            self.read_at = time.perf_counter()
        return fresh

    def write(self, cmd: JointCommand) -> None:
        if self.answered != self.k:
            self.delays.append(time.perf_counter() - self.read_at)
        super().write(cmd)


def test_a_slow_watchdog_start_is_in_the_set_up_not_before_an_answer(
        er20: Robot, nominal_params: ParamsFile, monkeypatch: pytest.MonkeyPatch) -> None:
    """The watchdog's thread taking 1.9 cycles to start (its stack faulted in where the memory
    is locked: 3.4-5 ms measured for the default 8 MiB stack) delays no answer: it starts in
    the set-up's compute, before the start reads the packet the first period answers. (Before,
    it started after that read: the first period's answer went out 15.7 ms after its packet.)"""
    monkeypatch.setattr(DriverWatchdog, "start", _then_sleep(DriverWatchdog.start))
    driver = PacedDelays(_sim(er20))
    _paced_session(er20, nominal_params, driver)
    first = driver.delays[:5]     # the start's hold and the first periods' answers
    assert len(first) == 5 and max(first) < 0.008, first


def test_the_watchdog_thread_starts_on_its_small_stack(monkeypatch: pytest.MonkeyPatch) -> None:
    """The thread is created with a stack of STACK_BYTES, and the interpreter's setting for
    new threads is put back at once."""
    sizes: list[int] = []
    # the call that creates the thread: _start_joinable_thread from Python 3.13 on
    name = next(n for n in ("_start_joinable_thread", "_start_new_thread")
                if hasattr(threading, n))
    create = getattr(threading, name)

    def spy(*args: object, **kwargs: object) -> object:
        sizes.append(threading.stack_size())
        return create(*args, **kwargs)

    monkeypatch.setattr(threading, name, spy)
    before = threading.stack_size()
    watch = DriverWatchdog(0.05, 1.0, None)
    watch.start()
    try:
        assert sizes == [STACK_BYTES]
        assert threading.stack_size() == before
    finally:
        watch.stop()
    assert not watch._thread.is_alive()


def test_a_failed_set_up_stops_the_watchdog(er20: Robot, nominal_params: ParamsFile,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """An exception in the start's compute (after the watchdog's thread started) leaves no
    thread behind, and the interpreter as it was (the collector is paused from the start on:
    none runs between the start's last packet and the first answer)."""
    collector: list[bool] = []

    def broken(loop: ServoLoop, q0: np.ndarray, t: float) -> None:
        collector.append(gc.isenabled())
        raise RuntimeError("set-up failed")

    monkeypatch.setattr(ServoLoop, "dry_periods", broken)
    before = {t for t in threading.enumerate() if t.name == "leadthrough-watchdog"}
    sim = _sim(er20)
    parts = build_loop(er20, nominal_params, LIGHT, sim.dt)
    with pytest.raises(RuntimeError, match="set-up failed"):
        run_session(Real(sim), *parts, 0.05,
                    options=LoopOptions(enable_input=0, watchdog_s=0.05))
    after = {t for t in threading.enumerate() if t.name == "leadthrough-watchdog"}
    assert after == before
    assert collector == [False] and gc.isenabled()


def test_a_refused_stack_size_starts_the_watchdog_on_the_default_stack(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """A platform whose threads cannot take STACK_BYTES (``threading.stack_size`` raises)
    still gets its watchdog, on the default stack, with a warning."""
    def refused(size: int = 0) -> int:
        raise ValueError("size not valid")

    monkeypatch.setattr(threading, "stack_size", refused)
    fired = threading.Event()
    watch = DriverWatchdog(0.02, 0.05, fired.set)
    with caplog.at_level("WARNING", logger="leadthrough.session"):
        watch.start()
    try:
        watch.enter()
        assert fired.wait(2.0)          # it watches: a blocked exchange is aborted
    finally:
        watch.leave()
        watch.stop()
    assert "default stack (size not valid)" in caplog.text


#: Run in a fresh interpreter: the adaptive bytecode of the loop's period code when the first
#: period begins (in the test process, earlier sessions may have specialised it already).
_SPECIALISED_AT_FIRST_PERIOD = """
import dis, json
from leadthrough.robot import load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session import operator_inputs, servo_loop
from leadthrough.session.loop import run_session
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.guiding_params import shipped_guiding_params

robot = load_robot("er20")
driver = SimDriver(SimRobot(robot, SimConfig(seed=1), q0=guide_start_pose(robot)))
parts = build_loop(robot, shipped_guiding_params(robot), LoopConfig(), driver.dt)
code = {"compute": servo_loop.ServoLoop.compute, "_cycle": servo_loop.ServoLoop._cycle,
        "EnablingDevice.update": operator_inputs.EnablingDevice.update}
seen = {}
period = servo_loop.ServoLoop.period

def first_period(self, i, t, clock):
    if not seen:
        seen.update({name: sum(ins.opname not in dis.opmap
                               for ins in dis.get_instructions(f, adaptive=True))
                     for name, f in code.items()})
    return period(self, i, t, clock)

servo_loop.ServoLoop.period = first_period
run_session(driver, *parts, 0.02)
print(json.dumps(seen))
"""


def test_the_first_period_runs_code_the_interpreter_has_specialised() -> None:
    """The start's dry periods run the loop's own period code (the controller cycle, the
    enabling device) often enough that the interpreter has specialised its bytecode before the
    first period: CPython 3.11 quickens a function on its 8th call, and the first periods of
    a session ran slower before. (Before, only the parts' updates ran at the start: no
    specialised instruction in these.)"""
    out = subprocess.run([sys.executable, "-c", _SPECIALISED_AT_FIRST_PERIOD],
                         capture_output=True, text=True, timeout=300, check=True)
    specialised = json.loads(out.stdout.strip().splitlines()[-1])
    assert set(specialised) == {"compute", "_cycle", "EnablingDevice.update"}, specialised
    assert all(count > 0 for count in specialised.values()), specialised


def test_the_dry_periods_leave_nothing_of_the_session(
        er20: Robot, nominal_params: ParamsFile, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the start's dry cycles and with them, the same session: a protective stop
    reported from the first sample is the first period's fault, noted once (the dry cycles
    read no controller state); the enabling device held from the start never guides; a stop
    requested before the start ends the session at its first period (the dry cycles serve no
    request); and the logs are equal bit for bit."""
    cfg = SimSessionConfig(operator="push-x", duration_s=1.5, loop=LIGHT,
                           enable_held_s=((0.0, math.inf),),
                           faults=(InjectedFault(InjectedFaultKind.PROTECTIVE_STOP, 0.0, 0.5),))
    logs = []
    for dry_cycles in (0, loop_start.DRY_CYCLES):
        monkeypatch.setattr(loop_start, "DRY_CYCLES", dry_cycles)
        log = run_sim_session(er20, nominal_params, cfg).log
        t_fault, fault = _fault_at(log)
        assert fault is Fault.CONTROLLER_STATE and t_fault == log.time[0]
        assert [n for n in _notes(log) if n[0] != "stop"] == [("controller state",
                                                               "PROTECTIVE_STOP")]
        assert not np.any(log.state == int(State.GUIDING))
        req = LoopRequests()
        req.stop()
        stopped = run_sim_session(er20, nominal_params,
                                  dataclasses.replace(cfg, duration_s=0.5), requests=req)
        assert stopped.result.end.cause is EndCause.STOP_REQUESTED
        assert stopped.result.end.t == stopped.log.time[0]
        logs.append(log)
    a, b = logs
    for name in ("time", "q", "current", "wrench_base", "q_cmd", "twist_cmd_base", "state",
                 "fault"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.events == b.events


def test_the_rewarm_after_the_starts_answer_leaves_nothing_of_the_session(
        er20: Robot, nominal_params: ParamsFile, monkeypatch: pytest.MonkeyPatch) -> None:
    """A real controller's start answers the packet the first period used to answer at once,
    then runs the loop's period code once more (``ServoLoop.rewarm``: after the start's waits
    the first cycles ran 1.5-2x the steady state). The packet is answered before the rewarm
    runs, and the session is the same without it and with it, bit for bit (a rewarm that left
    its samples in the estimator or its transitions in the log would show)."""
    runs: list[tuple[LoopResult, RsiLike]] = []
    answered_first: list[bool] = []
    rewarm = ServoLoop.rewarm

    def noted(loop: ServoLoop, q0: np.ndarray, t0: float) -> None:
        driver = loop.driver
        assert isinstance(driver, RsiLike)
        answered_first.append(driver.taken[-1] in driver.answered)
        rewarm(loop, q0, t0)

    for variant in (lambda *_: None, noted):
        monkeypatch.setattr(ServoLoop, "rewarm", variant)
        sim = SimDriver(SimRobot(er20, SimConfig(seed=1), q0=guide_start_pose(er20)))
        driver = RsiLike(sim)
        parts = build_loop(er20, nominal_params, LoopConfig(), sim.dt)
        r = run_session(driver, *parts, 0.5,
                        options=LoopOptions(enable_input=0, watchdog_s=0.05))
        assert r.end.cause is EndCause.DURATION
        runs.append((r, driver))
    assert answered_first == [True]
    (a, da), (b, db) = runs
    assert a.log is not None and b.log is not None
    assert da.taken == db.taken and da.answered == db.answered
    for name in ("time", "q", "current", "wrench_base", "q_cmd", "twist_cmd_base", "state",
                 "fault"):
        assert np.array_equal(getattr(a.log, name), getattr(b.log, name)), name
    assert a.log.events == b.log.events
