"""The guiding loop on the simulated robot: rest, the enabling device's fresh press, faults
through the whole chain, session files, the ``guide`` CLI."""

from __future__ import annotations

import gc
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leadthrough.cli import main
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.control.safety import Fault as ControlFault
from leadthrough.control.safety import State
from leadthrough.drivers.replay import ReplayDriver
from leadthrough.dynamics import nominal_drive_parameters
from leadthrough.errors import ControlError, DataError
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import ParamsFile, load_params, save_params
from leadthrough.robot import Robot
from leadthrough.session.loop import run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, LoopParts, build_loop
from leadthrough.session.metrics import (
    faults_without_hand,
    force_error_in_motion,
    phantom_forces,
    release_motion_times,
    release_overruns,
)
from leadthrough.session_format import SessionEvent, SessionLog, load_session, save_session
from leadthrough.sim.driver import InjectedFault as Fault
from leadthrough.sim.driver import InjectedFaultKind as FaultKind
from leadthrough.sim.guiding_params import shipped_guiding_params
from leadthrough.sim.session import (
    SimSessionConfig,
    light_guiding,
    replay_session,
    run_sim_session,
)

LIMIT_ACC = 0.4  # m/s², Table IV


def test_rest_session_commands_exactly_zero(er20: Robot, nominal_params: ParamsFile) -> None:
    """The paper's claim, on the closed loop: nobody pushes, the commands never change."""
    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest", duration_s=4.0))
    log = s.result.log
    assert np.all(log.twist_cmd_base == 0.0)
    assert np.all(log.qd_cmd == 0.0)
    assert np.all(log.q_cmd == log.q_cmd[0])
    assert s.summary.rest_drift_m == 0.0
    assert s.summary.faults == []
    # it was guiding, not idle, when the 4 s ran out (then the session's stop releases it)
    end = int(np.searchsorted(log.time, 4.0 - 1e-9))
    assert State(int(log.state[end - 1])) is State.GUIDING
    assert State(int(log.state[-1])) is State.IDLE
    # on the scripted operator's press of the enabling device once the loop is ready (1 s)
    pressed = [e for e in log.events if e.cause == "DEADMAN_PRESSED"]
    assert len(pressed) == 1 and 1.0 <= pressed[0].t < 1.01


def test_inspect_loop_sees_the_parts_that_run(er20: Robot, nominal_params: ParamsFile) -> None:
    """``inspect_loop`` is called once, before the first sample, with the estimator,
    controller and interpolator the session then runs (a probe can read their state)."""
    seen: list[tuple[int, LoopParts]] = []

    def inspect(parts: LoopParts) -> None:
        seen.append((int(parts.estimator.record["samples"][0]), parts))

    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="rest", duration_s=0.5),
                        inspect_loop=inspect)
    assert len(seen) == 1
    samples_before, parts = seen[0]
    assert samples_before == 0
    # the same estimator produced the log: its last output is the log's last estimate (the
    # nominal model reads a force at rest, so that estimate is not zero)
    assert np.any(s.result.log.wrench_base[-1] != 0.0)
    assert np.array_equal(parts.estimator.record["last_wrench"][0], s.result.log.wrench_base[-1])
    assert int(parts.estimator.record["samples"][0]) >= s.result.log.n


#: push-x (40 N from 1 s to 4 s) with a light virtual mass and the estimator ready at 0.5 s
#: (0.2 s warm-up, 0.3 s tare): room for a release and a new press before the push.
PUSH = {"operator": "push-x", "duration_s": 5.0,
        "loop": LoopConfig(estimator=replace(LoopConfig().estimator, warm_up_s=0.2, tare_s=0.3),
                           guiding=light_guiding())}


@pytest.mark.parametrize(("held", "starts"), [
    ((), None),                                  # no enabling input: never
    (((0.0, math.inf),), None),                  # held from the start: never
    (((0.3, math.inf),), None),                  # pressed during the warm-up: not armed by it
    (((0.0, 0.6), (0.8, math.inf)), 0.8),        # held at the start, released, pressed again
], ids=["none", "held-at-start", "pressed-in-warm-up", "released-and-pressed"])
def test_guiding_starts_only_on_a_fresh_press(er20: Robot, nominal_params: ParamsFile,
                                              held: tuple[tuple[float, float], ...],
                                              starts: float | None) -> None:
    """The hand pushes with 40 N from 1 s to 4 s: the robot moves only after a press of the
    enabling device seen once the loop is ready (estimator warmed up and tared at 0.5 s)."""
    s = run_sim_session(er20, nominal_params, SimSessionConfig(**PUSH, enable_held_s=held))
    log = s.result.log
    guiding = log.state == int(State.GUIDING)
    if starts is None:
        assert not guiding.any()
        assert np.all(log.q_cmd == log.q_cmd[0]) and np.all(log.twist_cmd_base == 0.0)
        return
    first = float(log.time[np.argmax(guiding)])
    assert starts <= first < starts + 0.011
    before = log.time < starts
    assert np.all(log.q_cmd[before] == log.q_cmd[0])
    assert np.abs(log.twist_cmd_base[:, 0]).max() > 0.005      # then it follows the push


def test_releasing_the_enabling_device_stops_at_the_limit(er20: Robot,
                                                          nominal_params: ParamsFile) -> None:
    """Released at 2.5 s while the hand still pushes: STOPPING at the acceleration limit, then
    IDLE at rest; no restart without a new press."""
    s = run_sim_session(er20, nominal_params,
                        SimSessionConfig(**PUSH, enable_held_s=((0.6, 2.5),)))
    log = s.result.log
    labels = [(e.label, e.cause) for e in log.events if e.kind == "transition"]
    assert labels[1:] == [("IDLE->GUIDING", "DEADMAN_PRESSED"),
                          ("GUIDING->STOPPING", "DEADMAN_RELEASED"), ("STOPPING->IDLE", "STOPPED")]
    released = next(e.t for e in log.events if e.cause == "DEADMAN_RELEASED")
    assert 2.5 <= released < 2.511
    cycles = log.twist_cmd_base[::10, :3]
    assert (np.linalg.norm(np.diff(cycles, axis=0), axis=1) / 0.01).max() <= LIMIT_ACC + 1e-9
    assert np.all(log.twist_cmd_base[log.time > 3.5] == 0.0)
    assert np.all(log.state[log.time > 3.5] == int(State.IDLE))


def test_a_new_press_after_a_pause_does_not_move_on_the_drives_drift(er20: Robot) -> None:
    """Calibrated robot instance 1: a push-x session, the enabling device released at 6 s and
    pressed again at 18 s with no hand on the tool. Over the pause the estimate drifts (the
    drives' torque settling against the gears' friction): far past δ with params that lack
    the friction's relaxation at rest (``presliding_relaxation``, before 2026-11-28; 52 N over
    11 s), less than half as far with it (18 N). Either way the press must not take the drift
    for a push: the command stays exactly where it was (before the fix of 2026-11-27 the tool
    moved by itself at the press)."""
    shipped = shipped_guiding_params(er20)
    cfg = SimSessionConfig(operator="push-x", seed=1, duration_s=21.0,
                           enable_held_s=((1.0, 6.0), (18.0, math.inf)),
                           loop=LoopConfig(guiding=light_guiding(100.0)))
    drift = []
    for relaxation in (False, True):
        params = shipped if relaxation else replace(shipped, params=replace(
            shipped.params, presliding_relaxation=np.zeros(0)))
        log = run_sim_session(er20, params, cfg).result.log
        presses = [e.t for e in log.events if e.cause == "DEADMAN_PRESSED"]
        assert presses == pytest.approx([1.0, 18.0], abs=0.011)
        after = log.time >= presses[1]
        force = np.linalg.norm(log.wrench_base[:, :3], axis=1)
        if not relaxation:
            assert force[np.argmax(after)] > 3 * 15.0       # the drift the press must ignore
        pause = log.wrench_base[(log.time >= 7.0) & (log.time < 18.0), :3]
        drift.append(float(np.linalg.norm(pause[-1] - pause[0])))      # over 11 s [N]
        assert np.all(log.state[after & (log.time < 20.9)] == int(State.GUIDING))
        assert np.all(log.twist_cmd_base[after] == 0.0)
        assert np.all(log.q_cmd[after] == log.q_cmd[np.argmax(after)])
        assert np.abs(log.twist_cmd_base[log.time < 6.0, 0]).max() > 0.1   # it did move
    assert drift[1] < 0.5 * drift[0], drift


def test_no_enabling_input_means_no_guiding(er20: Robot, nominal_params: ParamsFile) -> None:
    """``run_session`` with neither an enabling input nor a ``deadman`` function never guides
    (it used to take that for "always held"); two enabling inputs are refused."""
    cfg = SimSessionConfig(**PUSH)
    s = run_sim_session(er20, nominal_params, cfg, record_feedback=True)
    assert s.feedback is not None and np.any(s.result.log.state == int(State.GUIDING))
    parts = build_loop(er20, nominal_params, cfg.loop, 1e-3)
    replayed = run_session(ReplayDriver(s.feedback), *parts, 5.0).log
    assert not np.any(replayed.state == int(State.GUIDING))
    assert np.all(replayed.q_cmd == replayed.q_cmd[0])
    with pytest.raises(ControlError, match="two enabling inputs"):
        run_session(ReplayDriver(s.feedback), *parts, 5.0, options=LoopOptions(enable_input=0),
                    deadman=lambda t: True)


@pytest.mark.parametrize("kind, cause", [
    (FaultKind.STALE, ControlFault.STALE_FEEDBACK),
    (FaultKind.NAN_CURRENT, ControlFault.NONFINITE_INPUT),
    (FaultKind.Q_OFFSET, ControlFault.FOLLOWING_ERROR)])
def test_injected_feedback_fault_stops_the_push_and_latches(er20: Robot,
                                                            nominal_params: ParamsFile,
                                                            kind: FaultKind,
                                                            cause: ControlFault) -> None:
    """The fault injected at 3 s is latched for its own cause within the stale-feedback
    limit (about 30 ms; the others at the next sample), reported with it, and the command
    stops at the acceleration limit without a position jump."""
    fault = Fault(kind, t_start=3.0, offset=0.2)
    s = run_sim_session(er20, nominal_params,
                        SimSessionConfig(operator="push-x", duration_s=5.5, faults=(fault,)))
    log = s.result.log
    state = log.state
    first = int(np.argmax(state == int(State.FAULT)))
    assert first > 0 and 3.0 <= log.time[first] < 3.05
    assert np.all(state[first:] == int(State.FAULT))  # latched
    assert log.fault[first] == int(cause) and s.summary.faults == [cause.name]
    v = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1)
    assert v[-1] == 0.0
    cycles = log.twist_cmd_base[::10, :3]
    acc = np.linalg.norm(np.diff(cycles, axis=0), axis=1) / 0.01
    assert acc.max() <= LIMIT_ACC + 1e-9
    assert np.all(np.abs(np.diff(log.q_cmd, axis=0)) < 1e-3)  # no position jump at 1 ms


@pytest.mark.parametrize("kind", [FaultKind.NAN_CURRENT, FaultKind.NAN_Q])
def test_a_bad_sample_between_controller_cycles_faults_the_controller(
        er20: Robot, nominal_params: ParamsFile, kind: FaultKind) -> None:
    """A non-finite sample lasting one servo period between two controller cycles: the
    controller never sees it, the estimator does and latches; the controller then faults
    (ESTIMATOR), stops at the limit and latches, instead of taking the estimator's fault for
    a released deadman."""
    fault = Fault(kind, t_start=3.0035, t_end=3.0045, joint=2)
    s = run_sim_session(er20, nominal_params, SimSessionConfig(
        operator="push-x", duration_s=5.0, loop=LoopConfig(guiding=light_guiding()),
        faults=(fault,)))
    log = s.result.log
    first = int(np.argmax(log.state == int(State.FAULT)))
    assert first > 0 and 3.004 <= log.time[first] <= 3.02
    assert np.all(log.state[first:] == int(State.FAULT))
    assert np.all(log.fault[first:] == int(ControlFault.ESTIMATOR))
    assert s.summary.faults and "ESTIMATOR" in s.summary.faults[0]
    assert log.state[first - 1] == int(State.GUIDING)          # not taken for a release
    assert np.all(log.twist_cmd_base[-1] == 0.0)
    cycles = log.twist_cmd_base[::10, :3]
    assert (np.linalg.norm(np.diff(cycles, axis=0), axis=1) / 0.01).max() <= LIMIT_ACC + 1e-9


def test_the_first_read_must_bring_feedback(er20: Robot, nominal_params: ParamsFile) -> None:
    with pytest.raises(ControlError, match="no feedback on the first read"):
        run_sim_session(er20, nominal_params, SimSessionConfig(
            operator="rest", duration_s=1.0, faults=(Fault(FaultKind.STALE, 0.0, 0.01),)))


def test_replayed_feedback_repeats_the_session_bit_for_bit(er20: Robot,
                                                           nominal_params: ParamsFile) -> None:
    """The loop is deterministic: its recorded reads (stale ones included) give the same
    estimates, states and commands without the simulator."""
    # the paper's law alone: with the nominal model the estimate swings by more than δ under
    # the push, which the stop after letting go takes for a release (and then the push, held
    # steady, never rises again); this test is about the loop's determinism
    guiding = replace(light_guiding(), hand_release=HandReleaseConfig(enabled=False))
    cfg = SimSessionConfig(operator="push-x", duration_s=4.0, loop=LoopConfig(guiding=guiding),
                           faults=(Fault(FaultKind.STALE, t_start=3.5, t_end=3.503),))
    s = run_sim_session(er20, nominal_params, cfg, record_feedback=True)
    assert s.feedback is not None
    assert s.feedback.reads == len(s.result.log.time) + 1
    assert 0 < np.count_nonzero(~s.feedback.fresh) < 10
    replayed = replay_session(er20, nominal_params, cfg, s.feedback).log
    log = s.result.log
    assert np.abs(log.twist_cmd_base[:, 0]).max() > 0.01  # it moved
    for name in ("q_cmd", "qd_cmd", "tau_ext", "wrench_base", "twist_cmd_base", "state",
                 "fault"):
        np.testing.assert_array_equal(getattr(replayed, name), getattr(log, name), name)


def test_the_loop_pauses_the_garbage_collector_and_leaves_no_cycles(
        er20: Robot, nominal_params: ParamsFile) -> None:
    """The cyclic collector is off while the loop runs (a collection would stall a cycle) and
    back on after; pausing it is free because the loop creates no reference cycles."""
    cfg = SimSessionConfig(operator="push-x", duration_s=2.0,
                           loop=LoopConfig(guiding=light_guiding()))
    s = run_sim_session(er20, nominal_params, cfg, record_feedback=True)
    assert s.feedback is not None
    duration = (s.feedback.reads - 1) * 1e-3
    seen: list[bool] = []
    parts = build_loop(er20, nominal_params, cfg.loop, 1e-3)
    assert gc.isenabled()
    run_session(ReplayDriver(s.feedback), *parts, duration,
                deadman=lambda t: seen.append(gc.isenabled()) or True)
    assert len(seen) == math.ceil((s.feedback.reads - 1) / 10) and not any(seen)
    assert gc.isenabled()
    parts = build_loop(er20, nominal_params, cfg.loop, 1e-3)
    driver = ReplayDriver(s.feedback)
    gc.collect()
    gc.disable()
    try:
        run_session(driver, *parts, duration)
        assert not gc.isenabled()          # left as it was
        assert gc.collect() == 0           # nothing for a collection to find
    finally:
        gc.enable()


def test_session_file_round_trip(er20: Robot, nominal_params: ParamsFile,
                                 tmp_path: Path) -> None:
    s = run_sim_session(er20, nominal_params, SimSessionConfig(operator="diagonal",
                                                               duration_s=1.5))
    path = save_session(s.result.log, tmp_path / "s.parquet")
    back = load_session(path)
    log = s.result.log
    assert back.robot == "er20" and back.n == 6
    np.testing.assert_array_equal(back.q, log.q)
    np.testing.assert_array_equal(back.twist_cmd_base, log.twist_cmd_base)
    np.testing.assert_array_equal(back.state, log.state)
    assert back.wrench_applied_base is not None
    assert [m.label for m in back.marks] == ["P1"]  # P2 comes after 1.5 s
    assert back.events == log.events
    assert back.settings["operator"] == "diagonal"


def test_operator_seed_varies_the_pushes_not_the_robot(er20: Robot,
                                                        nominal_params: ParamsFile) -> None:
    """``operator_seed`` draws other random pushes on the same simulated robot: until the first
    push (1 s) the two recordings are bit-identical, then the applied wrenches differ."""
    a, b = (run_sim_session(er20, nominal_params,
                            SimSessionConfig(operator="random", duration_s=2.0, operator_seed=s))
            for s in (0, 5))
    la, lb = a.result.log, b.result.log
    # (the sessions end with a stop, which takes its own time after each one's last push)
    np.testing.assert_array_equal(la.current[la.time < 1.0], lb.current[lb.time < 1.0])
    assert la.wrench_applied_base is not None and lb.wrench_applied_base is not None
    k = min(la.time.size, lb.time.size)
    assert not np.allclose(la.wrench_applied_base[:k], lb.wrench_applied_base[:k])
    assert la.settings["seed"] == lb.settings["seed"] == 1
    assert (la.settings["operator_seed"], lb.settings["operator_seed"]) == (0, 5)
    with pytest.raises(ControlError, match="operator_seed"):
        SimSessionConfig(operator_seed=-1)


def test_release_overruns_measure_travel_beyond_the_shortest_stop() -> None:
    """A push to 0.2 m/s, released at t = 1 s: a stop at 0.4 m/s² covers 50 mm. A log that
    coasts 0.5 s at 0.2 m/s before that stop overran by 100 mm; one that stops at once, by 0.
    No truth, no figure."""
    dt, a, v0 = 1e-3, 0.4, 0.2
    t = np.arange(0.0, 3.0, dt)
    pushed = t < 1.0

    def log_with(speed: np.ndarray) -> SessionLog:
        n, z6 = t.size, np.zeros((t.size, 6))
        twist = z6.copy()
        twist[:, 0] = speed
        tcp = np.zeros((n, 3))
        tcp[1:, 0] = np.cumsum(speed[:-1]) * dt
        applied = z6.copy()
        applied[pushed, 0] = 40.0
        return SessionLog(robot="er20", time=t, q=z6, current=z6, tau_ext=z6, wrench_base=z6,
                          q_cmd=z6, qd_cmd=z6, tcp_cmd_base=tcp,
                          tcp_cmd_quat=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
                          twist_cmd_base=twist, state=np.zeros(n, np.int64),
                          fault=np.zeros(n, np.int64), wrench_applied_base=applied)

    after = np.clip(t - 1.0, 0.0, None)
    stop = np.where(pushed, v0, np.clip(v0 - a * after, 0.0, None))
    coast = np.where(after < 0.5, v0, np.clip(v0 - a * (after - 0.5), 0.0, None))
    coast[pushed] = v0
    over = release_overruns(log_with(stop), a)
    assert over is not None and over.shape == (1,)
    assert over[0] == pytest.approx(0.0, abs=5e-4)   # v·dt = 0.2 mm per end of the sum
    over = release_overruns(log_with(coast), a)
    assert over is not None and over[0] == pytest.approx(0.1, abs=5e-4)
    bare = replace(log_with(stop), wrench_applied_base=None)
    assert release_overruns(bare, a) is None
    # moving beyond the stop's v/a = 0.5 s: 0 for the stop, the 0.5 s coast for the other
    late = release_motion_times(log_with(stop), a)
    assert late is not None and late[0] == pytest.approx(0.0, abs=2 * dt)
    late = release_motion_times(log_with(coast), a)
    assert late is not None and late[0] == pytest.approx(0.5, abs=2 * dt)
    assert release_motion_times(bare, a) is None
    # a fault 1 s after the hand let go is no hand's; one while it pushes is
    events = [SessionEvent(t=0.5, kind="transition", label="GUIDING->FAULT",
                           cause="FAULT:COLLISION"),
              SessionEvent(t=2.0, kind="transition", label="GUIDING->FAULT",
                           cause="FAULT:JOINT_LIMIT"),
              SessionEvent(t=2.5, kind="transition", label="FAULT->IDLE", cause="RESET")]
    assert faults_without_hand(replace(log_with(stop), events=events), 0.5) == ["JOINT_LIMIT"]
    assert faults_without_hand(replace(log_with(stop), events=events), 1.5) == []
    assert faults_without_hand(bare, 0.5) is None


def test_force_error_in_motion_and_phantom_forces() -> None:
    """A 40 N push along x for 1 s at 0.1 m/s (slow start: 0.01 m/s for the first 0.2 s),
    estimated 3 N too high along y throughout, and 12 N along x for 0.3 s after the release,
    then 0: the RMS in motion counts only the samples at >= 0.02 m/s (3 N), the phantom is
    12 N (the 0.5 s window). No truth, no figures."""
    dt = 1e-3
    t = np.arange(0.0, 2.0, dt)
    n, z6 = t.size, np.zeros((t.size, 6))
    pushed = t < 1.0
    twist, applied, est = z6.copy(), z6.copy(), z6.copy()
    twist[pushed, 0] = np.where(t[pushed] < 0.2, 0.01, 0.1)
    applied[pushed, 0] = 40.0
    est[:, 1] = 3.0
    est[pushed, 0] = 40.0
    est[(t >= 1.0) & (t < 1.3), 0] = 12.0
    est[(t >= 1.0) & (t < 1.3), 1] = 0.0
    est[t >= 1.3, 1] = 0.0
    est[(t < 0.2), 1] = 50.0            # slow: not counted
    log = SessionLog(robot="er20", time=t, q=z6, current=z6, tau_ext=z6, wrench_base=est,
                     q_cmd=z6, qd_cmd=z6, tcp_cmd_base=np.zeros((n, 3)),
                     tcp_cmd_quat=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), twist_cmd_base=twist,
                     state=np.zeros(n, np.int64), fault=np.zeros(n, np.int64),
                     wrench_applied_base=applied)
    assert force_error_in_motion(log) == pytest.approx(3.0)
    phantom = phantom_forces(log)
    assert phantom is not None and phantom.shape == (1,) and phantom[0] == pytest.approx(12.0)
    bare = replace(log, wrench_applied_base=None)
    assert force_error_in_motion(bare) is None and phantom_forces(bare) is None


def test_corrupt_or_foreign_session_files_are_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(b"not parquet at all")
    with pytest.raises(DataError, match=r"bad\.parquet"):
        load_session(bad)
    with pytest.raises(DataError, match="file not found"):
        load_session(tmp_path / "missing.parquet")


def test_guide_cli(er20: Robot, nominal_params: ParamsFile, tmp_path: Path,
                   capsys: pytest.CaptureFixture[str]) -> None:
    params = tmp_path / "params.toml"
    n = er20.n
    stats = ResidualStats(mean=np.zeros(n), std=np.ones(n), std_pct_max=np.ones(n),
                          rms=np.ones(n), rel_error_pct=1.0, J=float(n), k_omega=1.0,
                          samples=np.full(n, 100))
    save_params(params, er20, "nominal", nominal_params.params, stats)
    assert load_params(params, er20).method == "nominal"
    out = tmp_path / "s.parquet"
    code = main(["guide", "--params", str(params), "--operator", "rest", "--duration", "2",
                 "--operator-seed", "3", "--allow-no-sweep", "-o", str(out), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert {"max_linear_speed", "max_angular_speed", "max_linear_acc", "rest_drift_m",
            "faults", "cycle_time_us"} <= summary.keys()
    assert summary["rest_drift_m"] == 0.0 and summary["max_linear_speed"] == 0.0
    assert set(summary["cycle_time_us"]) == {"median", "p99"}
    assert out.is_file()
    assert load_session(out).settings["operator_seed"] == 3
    # bad input: one line, exit 2, nothing written
    missing = tmp_path / "nowhere" / "s.parquet"
    assert main(["guide", "--params", str(params), "--allow-no-sweep", "-o", str(missing)]) == 2
    assert main(["guide", "--params", str(tmp_path / "none.toml"), "-o",
                 str(tmp_path / "x.parquet")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("leadthrough: error:") for line in err)
    assert not (tmp_path / "x.parquet").exists()


def test_guide_refuses_params_without_a_friction_sweep(
        er20: Robot, nominal_params: ParamsFile, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Parameters identified without a friction sweep cannot guide (their friction is low at
    guiding speeds): ``guide`` names the params file and what is missing, exits 2 and writes
    nothing, unless told ``--allow-no-sweep``; the same parameters with ``friction_sweep``
    guide."""
    n = er20.n
    stats = ResidualStats(mean=np.zeros(n), std=np.ones(n), std_pct_max=np.ones(n),
                          rms=np.ones(n), rel_error_pct=1.0, J=float(n), k_omega=1.0,
                          samples=np.full(n, 100))
    bare = save_params(tmp_path / "bare.toml", er20, "proposed", nominal_params.params, stats)
    assert load_params(bare, er20).friction_sweep is False
    out = tmp_path / "s.parquet"
    args = ["guide", "--operator", "rest", "--duration", "0.5", "-o", str(out)]
    assert main([*args, "--params", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bare.toml" in err[0] and "meta.friction_sweep" in err[0]
    assert "--friction-sweep" in err[0] and "--allow-no-sweep" in err[0]
    assert not out.exists()
    assert main([*args, "--params", str(bare), "--allow-no-sweep"]) == 0
    out.unlink()
    swept = save_params(tmp_path / "swept.toml", er20, "consistent", nominal_params.params,
                        stats, friction_sweep=True)
    assert load_params(swept, er20).friction_sweep is True
    assert main([*args, "--params", str(swept)]) == 0 and out.is_file()
    swept.write_text(swept.read_text().replace("friction_sweep = true", 'friction_sweep = "y"'))
    with pytest.raises(DataError, match=r"meta\.friction_sweep"):
        load_params(swept, er20)


def test_guide_rejects_params_of_another_robot(er20: Robot, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from leadthrough.robot import load_robot

    ur5 = load_robot("ur5")
    n = ur5.n
    stats = ResidualStats(mean=np.zeros(n), std=np.ones(n), std_pct_max=np.ones(n),
                          rms=np.ones(n), rel_error_pct=1.0, J=float(n), k_omega=1.0,
                          samples=np.full(n, 100))
    params = save_params(tmp_path / "ur5.toml", ur5, "nominal", nominal_drive_parameters(ur5),
                         stats)
    out = tmp_path / "s.parquet"
    assert main(["guide", "--robot", "er20", "--params", str(params), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ur5" in err[0] and "Traceback" not in err[0]
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_every_loop_shares_the_record_layouts_of_the_first(er20: Robot,
                                                          nominal_params: ParamsFile) -> None:
    """Each record layout is built once per robot size: a second loop's records have the very
    dtype objects of the first. (Numba's dispatcher caches the type of a structured array by
    its dtype; an equal but new dtype is compared field by field on every call, which made
    every compiled call of a second session in one process about 5 µs slower.)"""
    first = build_loop(er20, nominal_params, LoopConfig(), 1e-3)
    second = build_loop(er20, nominal_params, LoopConfig(), 1e-3)
    pairs = [(first.estimator.record, second.estimator.record),
             (first.controller.record, second.controller.record),
             (first.interpolator.record, second.interpolator.record)]
    for a, b in pairs:
        assert a.dtype is b.dtype
        assert a is not b and not np.shares_memory(a, b)
