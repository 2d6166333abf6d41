"""The loop's logic on a virtual clock (:class:`~leadthrough.session.pacing.VirtualClock`):
late periods and skipped slots, the operator's enabling device through requests (a fresh
press, a lease that lapses), a lost operator and a stop request. The test owns the clock: a
driver's step advances it one period, a period's work advances it as far as the test says, so
nothing here depends on the machine's speed (wall-clock figures are in ``benchmarks/``)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from leadthrough.control.safety_states import State
from leadthrough.drivers.protocol import Driver, DriverFeedback, WrappedDriver
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import EndCause, run, run_session
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.session.pacing import PeriodClock, VirtualClock
from leadthrough.session.requests import (
    LoopRequests,
    OperatorLost,
    SetEnable,
    Stop,
)
from leadthrough.session_format import SessionLog
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.session import light_guiding
from loop_helpers import bare_loop

Action = tuple[float, Callable[[], None]]


class OnClock(WrappedDriver):
    """The simulator, each step one period of ``clock``; ``actions`` run in the loop's thread
    at the first sample at or after their time (the same period every run)."""

    def __init__(self, driver: Driver, clock: VirtualClock, actions: list[Action]) -> None:
        super().__init__(driver)
        self.clock, self._actions = clock, sorted(actions, key=lambda a: a[0])

    def step(self) -> None:
        self.clock.advance(self.dt)
        self._driver.step()

    def read(self, fb: DriverFeedback) -> bool:
        fresh = self._driver.read(fb)
        while self._actions and fresh and fb.t >= self._actions[0][0] - 1e-9:
            self._actions.pop(0)[1]()
        return fresh


def _session(robot: Robot, params: ParamsFile, actions: list[Action], duration_s: float,
             requests: LoopRequests) -> SessionLog:
    """A session at rest on the simulated robot, the operator's side by requests only."""
    clock = VirtualClock()
    sim = SimDriver(SimRobot(robot, SimConfig(seed=1), q0=guide_start_pose(robot)))
    parts = build_loop(robot, params, LoopConfig(guiding=light_guiding()), sim.dt)
    r = run_session(OnClock(sim, clock, actions), *parts, duration_s, requests=requests,
                    clock=clock)
    assert r.log is not None
    return r.log


def _guiding_times(log: SessionLog) -> np.ndarray:
    return log.time[log.state == int(State.GUIDING)]


def test_late_periods_are_counted_on_the_loops_clock(er20: Robot,
                                                     nominal_params: ParamsFile) -> None:
    """A real controller's period is late when its work after the exchange outlasts a
    period: 1.5 periods of work in period 50, 0.9 in period 60: one late period, none
    skipped (the controller paces, nothing is caught up)."""
    clock = VirtualClock()
    requests = LoopRequests()
    loop = bare_loop(er20, nominal_params, clock=clock, requests=requests)
    dt = loop.driver.dt
    pacing = PeriodClock(dt, paced=False, real_time=True, clock=clock)
    work = {50: 1.5 * dt, 60: 0.9 * dt}
    run(loop, pacing, steps=100, observe=lambda i, _us: clock.advance(work.get(i, 0.0)))
    assert (pacing.late, pacing.skipped) == (1, 0)
    assert loop.end is not None and loop.end.cause is EndCause.DURATION


def test_a_paced_loop_skips_the_slots_of_an_overrun(er20: Robot,
                                                    nominal_params: ParamsFile) -> None:
    """Paced (a simulator in real time): a period whose work takes 2.5 periods is late, and
    the next starts at the first boundary after it, the two slots in between skipped, never
    run back to back; the periods after it keep the boundaries."""
    clock = VirtualClock()
    loop = bare_loop(er20, nominal_params, clock=clock, requests=LoopRequests())
    dt = loop.driver.dt
    pacing = PeriodClock(dt, paced=True, real_time=False, clock=clock)
    starts: list[float] = []

    def observe(i: int, _us: float) -> None:
        starts.append(pacing.next_start)
        if i == 50:
            clock.advance(2.5 * dt)

    run(loop, pacing, steps=100, observe=observe)
    assert (pacing.late, pacing.skipped) == (1, 2)
    gaps = np.round(np.diff(starts) / dt, 9)
    assert gaps[50] == 3.0 and np.all(np.delete(gaps, 50) == 1.0)


def test_a_press_held_from_the_start_guides_only_after_a_fresh_press(
        er20: Robot, nominal_params: ParamsFile) -> None:
    """The operator's enabling device (requests): held from 0.1 s, while the estimator still
    warms up and tares, it never guides; released at 2.5 s and pressed again at 3 s, it
    guides from that press on."""
    req = LoopRequests()
    actions: list[Action] = [(0.1, lambda: req.send(SetEnable(True))),
                             (2.5, lambda: req.send(SetEnable(False))),
                             (3.0, lambda: req.send(SetEnable(True)))]
    log = _session(er20, nominal_params, actions, 3.5, req)
    guiding = _guiding_times(log)
    assert guiding.size and 3.0 <= guiding[0] < 3.011, guiding[:3]
    assert np.all(guiding >= 3.0)


def test_a_hold_whose_lease_lapses_is_released_by_the_loop(er20: Robot,
                                                           nominal_params: ParamsFile) -> None:
    """A hold-to-run press at 3 s with a 0.2 s lease and no heartbeat after it: guiding from
    3 s, released by the loop itself at the first controller cycle after 3.2 s on its clock
    (the controller's commanded stop), whatever the sender does."""
    req = LoopRequests()
    clock_box: list[VirtualClock] = []

    def press() -> None:
        req.send(SetEnable(True, until=clock_box[0].now() + 0.2))

    clock = VirtualClock()
    clock_box.append(clock)
    sim = SimDriver(SimRobot(er20, SimConfig(seed=1), q0=guide_start_pose(er20)))
    parts = build_loop(er20, nominal_params, LoopConfig(guiding=light_guiding()), sim.dt)
    r = run_session(OnClock(sim, clock, [(3.0, press)]), *parts, 3.6, requests=req,
                    clock=clock)
    assert r.log is not None
    guiding = _guiding_times(r.log)
    assert guiding.size and 3.0 <= guiding[0] < 3.011
    release = [e for e in r.log.events if (e.kind == "transition"
               and e.label == "GUIDING->IDLE") or e.label == "GUIDING->STOPPING"]
    assert release and 3.2 <= release[0].t < 3.211, [(e.t, e.label) for e in release]
    assert release[0].cause == "DEADMAN_RELEASED"


class _LosesTheOperator:
    """A request source that is lost at ``at`` [s] of the loop's clock."""

    stop_requested = False

    def __init__(self, clock: VirtualClock, at: float) -> None:
        self.clock, self.at, self.told = clock, at, False

    def poll(self) -> object | None:
        if not self.told and self.clock.now() >= self.at:
            self.told = True
            return OperatorLost("the pendant's link closed")
        return None


def test_a_lost_operator_ends_the_loop_at_rest(er20: Robot, nominal_params: ParamsFile) -> None:
    """The operator's channel lost at 1 s of the clock: noted, the enabling device released,
    the loop ends at rest (``OPERATOR_LOST``) without a duration of its own."""
    clock = VirtualClock()
    loop = bare_loop(er20, nominal_params, clock=clock, requests=_LosesTheOperator(clock, 1.0))
    pacing = PeriodClock(loop.driver.dt, paced=True, real_time=False, clock=clock)
    run(loop, pacing)
    assert loop.end is not None and loop.end.cause is EndCause.OPERATOR_LOST
    assert loop.operator_lost == "the pendant's link closed"
    notes = [(e.label, e.cause) for e in loop.session_events() if e.kind == "loop"]
    assert ("operator lost", "the pendant's link closed: enabling device released") in notes
    assert math.isclose(loop.end.t, loop.t) and loop.end.t < loop.fb.t + 0.02


def test_a_stop_request_ends_the_loop_like_the_stop_flag(er20: Robot,
                                                         nominal_params: ParamsFile) -> None:
    """The vocabulary's ``Stop`` through the queue ends the session at rest at once, as
    ``LoopRequests.stop()`` does."""
    req = LoopRequests()
    log = _session(er20, nominal_params, [(1.5, lambda: req.send(Stop()))], 10.0, req)
    assert 1.5 <= log.time[-1] < 1.502
    assert [e.label for e in log.events if e.kind == "loop"] == ["stop"]
