"""Drivers: the SimDriver round trip and fault injection (stale, NaN, position offset)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from leadthrough.drivers import Driver
from leadthrough.errors import SimulationError
from leadthrough.robot import Robot
from leadthrough.sim import SimConfig, SimRobot
from leadthrough.sim.driver import InjectedFault as Fault
from leadthrough.sim.driver import InjectedFaultKind as FaultKind
from leadthrough.sim.driver import SimDriver

POSE = np.array([0.3, -0.6, 0.4, 0.5, 0.8, 0.2])


def _driver(robot: Robot, seed: int = 1) -> SimDriver:
    return SimDriver(SimRobot(robot, SimConfig(seed=seed), q0=POSE))


def _run(drv: SimDriver, steps: int) -> list[bool]:
    """Step and read ``steps`` times holding the current command; what read returned."""
    fb = drv.make_feedback()
    out = []
    for _ in range(steps):
        drv.step()
        out.append(drv.read(fb))
    return out


def test_sim_driver_is_a_driver(er20: Robot) -> None:
    drv = _driver(er20)
    assert isinstance(drv, Driver)
    assert (drv.n, drv.dt, drv.simulated) == (6, 1e-3, True)
    fb, cmd = drv.make_feedback(), drv.make_command()
    assert fb.q.shape == fb.current.shape == cmd.q.shape == cmd.qd.shape == (6,)
    assert fb.sequence == -1 and math.isnan(fb.t) and np.all(np.isnan(fb.q))


def test_round_trip_follows_a_joint_move(er20: Robot) -> None:
    drv = _driver(er20)
    fb, cmd = drv.make_feedback(), drv.make_command()
    assert not drv.read(fb) and fb.sequence == -1  # no sample before the first step
    drv.step()
    assert drv.read(fb) and (fb.t, fb.sequence) == (0.0, 1)
    assert not drv.read(fb)  # nothing new without a step
    res = er20.encoder_resolution
    assert np.all(np.abs(fb.q - POSE) <= 0.51 * res)  # the reset pose, quantised
    assert np.all(np.isfinite(fb.current)) and np.abs(fb.current).max() > 0.1  # gravity load
    # a 50 mrad minimum-jerk move of every joint in 0.5 s, then hold 1 s
    dq = 0.05 * np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    T, n_move, n_hold = 0.5, 500, 1000
    err = np.empty((n_move + n_hold, 6))
    for k in range(n_move + n_hold):
        s = min(k * drv.dt / T, 1.0)
        cmd.q[:] = POSE + (10 * s**3 - 15 * s**4 + 6 * s**5) * dq
        cmd.qd[:] = (30 * s**2 - 60 * s**3 + 30 * s**4) / T * dq
        drv.write(cmd)
        drv.step()
        assert drv.read(fb)
        assert fb.sequence == k + 2 and fb.t == pytest.approx((k + 1) * drv.dt, abs=1e-12)
        err[k] = fb.q - cmd.q
    np.testing.assert_allclose(drv.sim.q_command, POSE + dq)
    assert np.abs(err[:n_move]).max() < 5e-3  # follows within 10 % of the move
    assert np.abs(err[-1]).max() < 1e-3  # and settles on the target (2 % of the move)
    np.testing.assert_allclose(fb.q, POSE + dq, atol=1e-3)
    on_grid = fb.q / res
    np.testing.assert_allclose(on_grid, np.rint(on_grid), atol=1e-6)  # encoder counts


def test_write_rejects_bad_commands(er20: Robot) -> None:
    drv = _driver(er20)
    cmd = drv.make_command()
    cmd.q[:] = POSE
    drv.write(cmd)
    cmd.qd[3] = math.nan
    with pytest.raises(SimulationError, match="not finite"):
        drv.write(cmd)
    cmd.qd[3] = math.inf
    with pytest.raises(SimulationError, match="not finite"):
        drv.write(cmd)
    np.testing.assert_array_equal(drv.sim.q_command, POSE)  # nothing was sent
    with pytest.raises(SimulationError, match="shape"):
        drv.write(type(cmd)(q=np.zeros(5), qd=np.zeros(6)))


def test_stale_feedback_freezes_the_sequence(er20: Robot) -> None:
    drv = _driver(er20)
    drv.inject(Fault(FaultKind.STALE, t_start=0.010, t_end=0.020))
    fb = drv.make_feedback()
    got = []
    for _ in range(30):
        drv.step()
        got.append((drv.read(fb), fb.sequence, fb.t))
    fresh = [g[0] for g in got]
    # samples taken at 10..19 ms never arrive; read says so and fb keeps the 9 ms sample
    assert fresh == [True] * 10 + [False] * 10 + [True] * 10
    assert all(seq == 10 and t == pytest.approx(0.009) for _, seq, t in got[10:20])
    assert got[20][1] == 21  # the sequence jumps by the missed samples
    assert drv.sim.time == pytest.approx(0.030)  # the simulation kept running


def test_nan_and_offset_faults_show_in_read(er20: Robot) -> None:
    drv = _driver(er20)
    drv.inject(Fault(FaultKind.NAN_Q, t_start=0.005, t_end=0.007, joint=2))
    drv.inject(Fault(FaultKind.NAN_CURRENT, t_start=0.010, t_end=0.011))
    drv.inject(Fault("q_offset", t_start=0.015, joint=1, offset=0.01))  # type: ignore[arg-type]
    fb = drv.make_feedback()
    for k in range(20):
        drv.step()
        assert drv.read(fb)  # a corrupt sample is still a new sample
        true = drv.sim.read()
        nan_q = np.isnan(fb.q)
        if k in (5, 6):
            assert nan_q.tolist() == [False, False, True, False, False, False]
        else:
            assert not nan_q.any()
        nan_i = np.isnan(fb.current)
        assert nan_i.all() if k == 10 else not nan_i.any()
        offset = np.zeros(6)
        if k >= 15:
            offset[1] = 0.01
        ok = ~nan_q
        np.testing.assert_allclose(fb.q[ok], true.q[ok] + offset[ok], atol=1e-15)
    drv.clear_faults()
    drv.step()
    assert drv.read(fb) and np.array_equal(fb.q, drv.sim.read().q)


def test_bad_faults_raise(er20: Robot) -> None:
    drv = _driver(er20)
    with pytest.raises(SimulationError, match="joint"):
        drv.inject(Fault(FaultKind.NAN_Q, joint=6))
    with pytest.raises(SimulationError, match=r"fault\.kind"):
        Fault("frozen")  # type: ignore[arg-type]
    with pytest.raises(SimulationError, match="t_start"):
        Fault(FaultKind.STALE, t_start=1.0, t_end=1.0)
    with pytest.raises(SimulationError, match="offset"):
        Fault(FaultKind.Q_OFFSET, offset=math.nan)
    assert drv.faults == ()


def test_recording_and_replay_drivers_deliver_the_same_reads(er20: Robot) -> None:
    from leadthrough.drivers.replay import FeedbackTrace, RecordingDriver, ReplayDriver
    from leadthrough.errors import DataError

    sim = _driver(er20)
    sim.inject(Fault(FaultKind.STALE, t_start=0.003, t_end=0.005))
    rec = RecordingDriver(sim, capacity=4)
    assert isinstance(rec, Driver)
    fb = rec.make_feedback()
    got = []
    for _ in range(6):  # two reads more than kept: passed through, not recorded
        rec.step()
        got.append((rec.read(fb), fb.t, fb.q.copy()))
    tr = rec.trace()
    assert tr.reads == 4 and tr.fresh.tolist() == [True, True, True, False]  # t = 3 ms stale
    rep = ReplayDriver(tr)
    assert isinstance(rep, Driver) and rep.n == 6 and rep.dt == sim.dt
    fb2 = rep.make_feedback()
    for fresh, t, q in got[:4]:
        assert rep.read(fb2) is fresh
        if fresh:
            assert fb2.t == t
            np.testing.assert_array_equal(fb2.q, q)
    assert rep.read(fb2) is False  # the trace is over: stale
    cmd = rep.make_command()
    cmd.q[:] = 1.0
    rep.write(cmd)
    np.testing.assert_array_equal(rep.last_command.q, 1.0)
    with pytest.raises(DataError, match="trace"):
        ReplayDriver(FeedbackTrace(dt=1e-3, t=np.zeros(2), q=np.zeros((3, 6)),
                                   current=np.zeros((3, 6)), sequence=np.zeros(2, np.int64),
                                   fresh=np.ones(2, bool)))
    with pytest.raises(DataError, match="capacity"):
        RecordingDriver(sim, capacity=0)


def test_scripted_digital_inputs_are_read_recorded_and_replayed(er20: Robot) -> None:
    """Bit 0 held from 2 ms to 5 ms, bit 1 from 4 ms on: ``read`` reports them at the sample's
    time, and a recorded trace replays them with the controller state."""
    from leadthrough.drivers.replay import RecordingDriver, ReplayDriver
    from leadthrough.sim.driver import InputScript

    sim = _driver(er20)
    sim.script_input(InputScript(0, ((0.002, 0.005),)))
    sim.script_input(InputScript(1, ((0.004, math.inf),)))
    rec = RecordingDriver(sim, capacity=8)
    fb = rec.make_feedback()
    assert fb.inputs == 0 and fb.state == 0
    got = []
    for _ in range(8):
        rec.step()
        assert rec.read(fb)
        got.append(fb.inputs)
    assert got == [0, 0, 1, 1, 3, 2, 2, 2]           # samples at t = 0, 1, ..., 7 ms
    trace = rec.trace()
    assert trace.digital_inputs is not None and trace.digital_inputs.tolist() == got
    rep = ReplayDriver(trace)
    fb2 = rep.make_feedback()
    replayed = []
    for _ in range(8):
        assert rep.read(fb2)
        replayed.append(fb2.inputs)
    assert replayed == got
    with pytest.raises(SimulationError, match="bit"):
        InputScript(64, ())
    with pytest.raises(SimulationError, match="intervals"):
        InputScript(0, ((0.5, 0.2),))
    with pytest.raises(SimulationError, match="intervals"):
        InputScript(0, ((0.0, 1.0), (0.5, 2.0)))
