"""Every fault, injected: a stop at no more than the acceleration limit to exactly zero, no
position jump, latched until cleared; and ``update`` never raises."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.control import (
    AutoFrictionConfig,
    CartesianLimits,
    Cause,
    DifferentialIK,
    Event,
    Fault,
    GuidingConfig,
    GuidingController,
    GuidingInput,
    GuidingOutput,
    SafetyConfig,
    SafetySupervisor,
    State,
    VirtualFrictionConfig,
)
from leadthrough.control import GuidingStatus as Status
from leadthrough.robot import Robot, load_robot
from test_control_guiding import (
    DT,
    Q_WORK,
    ROUND,
    SUB,
    Inject,
    Trace,
    fk_positions,
    run,
)

K = 100                       # injection cycle: cruising at 0.2 m/s by then
LIGHT = VirtualFrictionConfig(mass=(100.0,) * 6)


def _once(k0: int, action: Inject) -> Inject:
    def inject(k: int, inp: GuidingInput) -> None:
        if k == k0:
            action(k, inp)
    return inject


def _stale(k: int, inp: GuidingInput) -> None:
    if K <= k < K + 5:
        inp.sequence = K


def _set(attr: str, index: int, value: float) -> Inject:
    def action(k: int, inp: GuidingInput) -> None:
        getattr(inp, attr)[index] = value
    return action


def _shift_q(k: int, inp: GuidingInput) -> None:
    inp.q += 0.1


ROBOT = load_robot("er20")

#: name: (config, wrench along which axis, injection, expected fault, first fault cycle or None)
CASES: dict[str, tuple[GuidingConfig, int, Inject | None, Fault, int | None]] = {
    "nonfinite-q": (GuidingConfig(virtual_friction=LIGHT), 1,
                    _once(K, _set("q", 2, math.nan)), Fault.NONFINITE_INPUT, K),
    "nonfinite-current": (GuidingConfig(virtual_friction=LIGHT), 1,
                          _once(K, _set("current", 0, math.inf)), Fault.NONFINITE_INPUT, K),
    "nonfinite-wrench": (GuidingConfig(virtual_friction=LIGHT), 1,
                         _once(K, _set("wrench_base", 3, math.nan)), Fault.NONFINITE_INPUT, K),
    "position-range": (GuidingConfig(virtual_friction=LIGHT), 1,
                       _once(K, _set("q", 0, float(ROBOT.upper_limits[0]) + 0.05)),
                       Fault.POSITION_RANGE, K),
    "current-range": (GuidingConfig(virtual_friction=LIGHT), 1,
                      _once(K, _set("current", 1, 2.0 * float(ROBOT.max_current[1]))),
                      Fault.CURRENT_RANGE, K),
    "stale-feedback": (GuidingConfig(virtual_friction=LIGHT), 1, _stale,
                       Fault.STALE_FEEDBACK, K + 3),
    "following-error": (GuidingConfig(virtual_friction=LIGHT), 1, _once(K, _shift_q),
                        Fault.FOLLOWING_ERROR, K),
    "collision": (GuidingConfig(virtual_friction=LIGHT), 1,
                  _once(K, _set("wrench_base", 0, 300.0)), Fault.COLLISION, K),
    "joint-limit": (GuidingConfig(virtual_friction=LIGHT), 0, None, Fault.JOINT_LIMIT, None),
    "workspace": (GuidingConfig(virtual_friction=LIGHT, safety=SafetyConfig(
        workspace_min=(0.0, -0.5, 0.0), workspace_max=(1.0, 0.15, 1.0))), 1, None,
        Fault.WORKSPACE, None),
    # the IK leaves ≈ 2.6e-6 per cycle at 0.2 m/s: a limit of 2e-6 trips while accelerating
    "tracking": (GuidingConfig(virtual_friction=LIGHT,
                               safety=SafetyConfig(tracking_error_limit=2e-6)), 1, None,
                 Fault.TRACKING, None),
}


def _check_stop_and_latch(robot: Robot, tr: Trace, fault: Fault, moving: float = 0.05) -> int:
    """The common must-show (the TCP moved faster than ``moving`` [m/s or rad/s] just before
    the fault); returns the first FAULT cycle."""
    is_fault = tr.state == State.FAULT
    f = int(np.argmax(is_fault))
    assert is_fault[f], "no fault"
    assert np.all(tr.fault[:f] == Fault.NONE) and np.all(tr.fault[f:] == fault)
    assert np.all(is_fault[f:]) and np.all(tr.status[f:] == Status.FAULT)   # latched
    speed = np.maximum(np.linalg.norm(tr.twist_base[:, :3], axis=1),
                       np.linalg.norm(tr.twist_base[:, 3:], axis=1))
    assert speed[f - 1] > moving                                # it was moving
    # deceleration at no more than the limit, in both parts of the twist
    dv = np.linalg.norm(np.diff(tr.twist_base[:, :3], axis=0), axis=1) / DT
    dw = np.linalg.norm(np.diff(tr.twist_base[:, 3:], axis=0), axis=1) / DT
    assert dv.max() <= 0.4 * (1 + ROUND) and dw.max() <= 0.4 * (1 + ROUND)
    # to exactly zero, in the time the limit needs, then held bit for bit
    rest = f + int(np.argmax(~tr.twist_base[f:].any(axis=1)))
    assert not tr.twist_base[rest].any()
    assert rest - f <= math.ceil(speed[f - 1] / (0.4 * DT)) + 1
    assert not tr.twist_base[rest:].any() and np.all(tr.qd[rest:] == 0.0)
    assert np.all(tr.q[rest:] == tr.q[rest]) and np.all(tr.q_ms[(rest + 1) * SUB:] == tr.q[rest])
    assert tr.state.size - rest > 100                           # latched long after
    # no position jump: joint commands move no faster than the joint speed limits
    assert np.all(np.abs(np.diff(tr.q_ms, axis=0)) <= robot.velocity_limit * DT / SUB)
    assert np.all(tr.q_ms >= robot.lower_limits) and np.all(tr.q_ms <= robot.upper_limits)
    return f


@pytest.mark.parametrize("name", list(CASES))
def test_fault_stops_at_the_limit_and_latches(er20: Robot, name: str) -> None:
    cfg, axis, inject, fault, first = CASES[name]
    ctl = GuidingController(er20, cfg)
    k_n = 900 if name == "joint-limit" else 400
    w = np.zeros((k_n, 6))
    w[:, axis] = 60.0                                           # keeps pushing throughout
    tr = run(ctl, Q_WORK, w, inject=inject)
    f = _check_stop_and_latch(er20, tr, fault)
    if first is not None:
        assert f == first
    events = [e for e in ctl.events if e.cause == Cause.FAULT]
    assert len(events) == 1 and events[0].fault == fault and events[0].t == pytest.approx(f * DT)
    assert events[0].from_state == State.GUIDING and events[0].to_state == State.FAULT
    if name == "workspace":
        # never outside the box: the commanded pose, nor the 1 ms joint commands
        assert tr.position[:, 1].max() <= 0.15
        assert fk_positions(er20, tr.q_ms)[:, 1].max() <= 0.15 + 1e-6
        assert tr.position[:, 1].max() > 0.10                  # it did get close
    if name == "joint-limit":
        j = events[0].index
        margin = cfg.safety.joint_limit_margin
        assert abs(events[0].value - er20.lower_limits[j]) <= margin + 1e-12 or \
            abs(events[0].value - er20.upper_limits[j]) <= margin + 1e-12


def test_singularity_fault_stops_and_latches(er20: Robot) -> None:
    cfg = GuidingConfig(frame="tool", virtual_friction=LIGHT)
    q0 = np.array([0.0, -0.6, 0.9, 0.0, 0.35, 0.0])
    ik = DifferentialIK(er20)
    ik.compute_kinematics(q0)
    w = np.zeros((500, 6))
    w[:, 3:] = ik.transform_tool_to_base.rotation @ np.array([0.0, -30.0, 0.0])
    tr = run(GuidingController(er20, cfg), q0, w)
    # slowed down to min_speed_scale (0.1 × 0.2 rad/s) before the stop threshold
    _check_stop_and_latch(er20, tr, Fault.SINGULARITY, moving=0.019)


def test_no_collision_in_idle_but_at_the_press(er20: Robot) -> None:
    """An estimate of 300 N (the drives' drift at rest) while the enabling device is released
    latches nothing; pressed with it still there, COLLISION trips in the press's cycle instead
    of guiding, and the tool never moves: with the virtual-friction law and with the velocity
    law [14], which has no dead band."""
    w = np.zeros((70, 6))
    w[:, 0] = np.minimum(np.arange(70) * 15.0, 300.0)
    held = np.zeros(70, dtype=bool)
    held[50:] = True
    for law in ("virtual-friction", "velocity"):
        cfg = GuidingConfig(virtual_friction=LIGHT, controller=law)
        tr = run(GuidingController(er20, cfg), Q_WORK, w, deadman=held, interpolate=False)
        assert np.all(tr.state[:50] == State.IDLE) and np.all(tr.fault[:50] == Fault.NONE)
        assert np.all(tr.state[50:] == State.FAULT) and np.all(tr.fault[50:] == Fault.COLLISION)
        assert np.all(tr.twist_base == 0.0) and np.all(tr.q == Q_WORK)


def test_clear_fault_only_at_rest_then_idle(er20: Robot) -> None:
    ctl = GuidingController(er20, GuidingConfig(virtual_friction=LIGHT))
    inp, out = ctl.make_input(), ctl.make_output()
    ctl.reset(Q_WORK)
    inp.q[:] = Q_WORK
    cleared: list[tuple[int, bool]] = []
    for k in range(300):
        inp.t, inp.sequence, inp.deadman = k * DT, k, k > 0
        inp.wrench_base[:] = [0.0, 60.0, 0.0, 0.0, 0.0, 0.0]
        if k == K:
            inp.wrench_base[0] = 500.0                          # collision
        ctl.update(inp, out)
        inp.q[:] = out.q
        if k in (K + 1, K + 40, K + 150):
            cleared.append((k, ctl.clear_fault(k * DT)))
    assert cleared[0] == (K + 1, False) and cleared[1] == (K + 40, False)   # still moving
    assert cleared[2] == (K + 150, True)
    assert ctl.state == State.IDLE
    ev = ctl.events
    fault_ev = next(e for e in ev if e.cause == Cause.FAULT)
    assert fault_ev.fault == Fault.COLLISION and fault_ev.value == pytest.approx(
        math.hypot(500.0, 60.0)) and fault_ev.index == 0
    assert ev[-1].cause == Cause.FAULT_CLEARED and ev[-1].to_state == State.IDLE
    # after clearing: the deadman must be pressed anew (it is held) → stays IDLE, at rest
    q_hold = out.q.copy()
    for k in range(300, 320):
        inp.t, inp.sequence = k * DT, k
        assert ctl.update(inp, out) == Status.OK
        assert out.state == State.IDLE and np.all(out.q == q_hold)


def test_update_before_reset_holds_the_measured_position(er20: Robot) -> None:
    ctl = GuidingController(er20)
    inp, out = ctl.make_input(), ctl.make_output()
    inp.q[:] = Q_WORK
    assert ctl.update(inp, out) == Status.FAULT
    assert out.fault == Fault.NOT_STARTED and np.all(out.q == Q_WORK) and np.all(out.qd == 0.0)


def test_update_before_reset_never_commands_a_position_it_was_not_given(er20: Robot) -> None:
    """Before the first reset a non-finite measurement keeps the last finite one as the
    output; with none seen yet the output is NaN (no position to command), never zeros."""
    ctl = GuidingController(er20)
    inp, out = ctl.make_input(), ctl.make_output()
    inp.q[:] = math.nan
    assert ctl.update(inp, out) == Status.FAULT and np.all(np.isnan(out.q))
    inp.q[:] = Q_WORK
    ctl.update(inp, out)
    inp.q[3] = math.nan
    assert ctl.update(inp, out) == Status.FAULT
    assert out.fault == Fault.NOT_STARTED and np.all(out.q == Q_WORK)


@pytest.mark.parametrize("joints", [5, 7])
def test_an_input_for_another_robot_faults(er20: Robot, joints: int) -> None:
    """The input's arrays cannot be resized (they are its record's), but an input made for
    another robot can be passed: the cycle then runs on a non-finite input (a stop)."""
    ctl = GuidingController(er20)
    ctl.reset(Q_WORK)
    inp, out = ctl.make_input(), ctl.make_output()
    inp.q[:] = Q_WORK
    assert ctl.update(inp, out) == Status.OK
    other = GuidingInput(joints)
    other.sequence = 1
    assert ctl.update(other, out) == Status.FAULT and out.fault == Fault.NONFINITE_INPUT
    assert np.all(out.q == Q_WORK) and np.all(out.qd == 0.0)
    assert ctl.update(inp, GuidingOutput(joints)) == Status.FAULT   # an output of another


def test_an_estimator_fault_trips_the_controller(er20: Robot) -> None:
    tr = run(GuidingController(er20, GuidingConfig(virtual_friction=LIGHT)), Q_WORK,
             np.tile([0.0, 60.0, 0, 0, 0, 0], (300, 1)),
             inject=_once(K, lambda k, inp: setattr(inp, "estimator_status", -1)))
    f = _check_stop_and_latch(er20, tr, Fault.ESTIMATOR)
    assert f == K


_finite = st.floats(-10.0, 10.0)
_any = st.one_of(_finite, st.sampled_from([math.nan, math.inf, -math.inf, 1e300]))


_CONFIGS = [
    GuidingConfig(),
    GuidingConfig(frame="tool", controller="velocity"),
    GuidingConfig(friction_mode="auto", virtual_friction=LIGHT,
                  auto_friction=AutoFrictionConfig(basis="mean+std")),
]


@settings(max_examples=200, deadline=None)
@given(config=st.integers(0, len(_CONFIGS) - 1),
       data=st.lists(st.tuples(st.lists(_any, min_size=6, max_size=6),
                               st.lists(_any, min_size=6, max_size=6),
                               st.lists(_any, min_size=6, max_size=6),
                               st.integers(-5, 5), st.booleans()),
                     min_size=1, max_size=30))
def test_update_never_raises_and_commands_stay_finite(
        config: int, data: list[tuple[list[float], list[float], list[float], int, bool]]) -> None:
    ctl = GuidingController(ROBOT, _CONFIGS[config], noise_mean=np.full(6, 0.5),
                            noise_std=np.full(6, 2.0))
    inp, out = ctl.make_input(), ctl.make_output()
    ctl.reset(Q_WORK)
    seq = 0
    for k, (dq, cur, wrench, dseq, deadman) in enumerate(data):
        seq += dseq
        inp.t, inp.sequence, inp.deadman = k * DT, seq, deadman
        inp.q[:] = out.q + 0.001 * np.asarray(dq) if k else Q_WORK + 0.001 * np.asarray(dq)
        inp.current[:] = cur
        inp.wrench_base[:] = 20.0 * np.asarray(wrench)
        status = ctl.update(inp, out)
        assert status in (Status.OK, Status.FAULT)
        assert np.isfinite(out.q).all() and np.isfinite(out.qd).all()
        assert np.isfinite(out.twist_base).all() and np.isfinite(out.transform_tool_to_base).all()
        assert np.all(out.q >= ROBOT.lower_limits) and np.all(out.q <= ROBOT.upper_limits)


def test_event_log_is_bounded(er20: Robot) -> None:
    sup = SafetySupervisor(er20, SafetyConfig(max_events=3, require_deadman_edge=False),
                           CartesianLimits())
    sup.reset(0.0)
    for k in range(1, 4):                                   # press, release, stop: 3 more
        sup.deadman(k * 0.1, True)
        sup.deadman(k * 0.1 + 0.01, False)
        sup.stopped(k * 0.1 + 0.02, True)
    assert len(sup.events) == 3 and sup.events_dropped == 7
    assert [e.cause for e in sup.events] == [Cause.DEADMAN_PRESSED, Cause.DEADMAN_RELEASED,
                                             Cause.STOPPED]
    assert sup.events[-1].t == pytest.approx(0.32)


def test_event_ring_keeps_each_transitions_details(er20: Robot) -> None:
    """The compiled ring gives back every field of a transition: states, cause, fault, value
    and index, oldest first, and the latched fault's details."""
    sup = SafetySupervisor(er20, SafetyConfig(max_events=4), CartesianLimits())
    sup.reset(1.0)
    sup.deadman(1.1, False)                                 # arms, no transition
    sup.deadman(1.2, True)
    sup.trip(1.3, Fault.JOINT_LIMIT, 2.5, 3)
    sup.trip(1.4, Fault.COLLISION, 200.0, 0)                # already latched: ignored
    want = [Event(1.0, State.IDLE, State.IDLE, Cause.RESET),
            Event(1.2, State.IDLE, State.GUIDING, Cause.DEADMAN_PRESSED),
            Event(1.3, State.GUIDING, State.FAULT, Cause.FAULT, Fault.JOINT_LIMIT, 2.5, 3)]
    assert [_fields(e) for e in sup.events] == [_fields(e) for e in want]
    assert (sup.fault, sup.fault_value, sup.fault_index) == (Fault.JOINT_LIMIT, 2.5, 3)
    assert sup.clear_fault(1.5, at_rest=True) and sup.fault == Fault.NONE
    assert _fields(sup.events[-1]) == _fields(Event(1.5, State.FAULT, State.IDLE,
                                                    Cause.FAULT_CLEARED))
    assert sup.events_dropped == 0 and len(sup.events) == 4


def _fields(e: Event) -> tuple[object, ...]:
    """An event's fields, NaN as None (NaN != NaN)."""
    return tuple(None if isinstance(v, float) and math.isnan(v) else v
                 for v in dataclasses.astuple(e))


def test_output_fields_are_the_records_own_memory(er20: Robot) -> None:
    """GuidingOutput's arrays are its record's memory: filled in place by the compiled cycle,
    refused if rebound (so a caller can never detach them), updated in place by ``+=``; its
    codes read back as their enums."""
    ctl = GuidingController(er20, GuidingConfig())
    out = ctl.make_output()
    assert out.q.shape == (6,) and out.transform_tool_to_base[3, 3] == 1.0
    with pytest.raises(AttributeError, match="in place"):
        out.q = np.zeros(6)  # type: ignore[misc]
    out.q += 1.0
    assert np.all(out.record["q"] == 1.0) and np.shares_memory(out.q, out.record)
    inp = ctl.make_input()
    inp.q[:] = Q_WORK
    ctl.reset(Q_WORK)
    assert ctl.update(inp, out) == Status.OK
    assert out.state is State.IDLE and out.fault is Fault.NONE and out.status is Status.OK
    assert np.array_equal(out.q, Q_WORK)
