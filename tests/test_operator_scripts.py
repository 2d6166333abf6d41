"""Scripted operators: wrench profiles, timing, marks, reproducibility, saturation, registry."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pytest

from leadthrough.errors import LeadthroughError, SimulationError
from leadthrough.robot import Robot
from leadthrough.sim import (
    OPERATOR_NAMES,
    Mark,
    ScriptedOperator,
    SimConfig,
    SimRobot,
    hold,
    make_operator,
)
from leadthrough.sim.operator_scripts import PushScript, ScriptedPush, SeamOperator, random_pushes

START = np.array([1.0, 0.3, 0.5])
DT = 1e-3
POSE = np.array([0.3, -0.6, 0.4, 0.5, 0.8, 0.2])


class Sampled(NamedTuple):
    """A script sampled at 1 ms: times [s], shape (N,); wrenches, base frame, shape (N, 6)."""

    t: np.ndarray
    wrench_base: np.ndarray


def _sample(op: ScriptedOperator, tcp: np.ndarray = START) -> Sampled:
    """The script over its whole session, TCP fixed at ``tcp``."""
    t = np.arange(round(op.duration_s / DT)) * DT
    return Sampled(t, np.array([op.wrench(float(tk), tcp) for tk in t]))


# ----------------------------------------------------------------------------------- registry
@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_registry_builds_every_script(name: str) -> None:
    op = make_operator(name, seed=3, tcp_start_base=START)
    assert isinstance(op, ScriptedOperator)
    assert op.name == name
    assert op.duration_s > 0.0
    assert all(isinstance(m, Mark) for m in op.marks)
    assert [m.t for m in op.marks] == sorted(m.t for m in op.marks)
    assert all(0.0 <= m.t <= op.duration_s for m in op.marks)
    w = op.wrench(0.5, START)
    assert w.shape == (6,) and np.all(np.isfinite(w))


def test_unknown_name_names_value_and_valid_names() -> None:
    with pytest.raises(SimulationError) as info:
        make_operator("push_x", seed=0, tcp_start_base=START)
    err = info.value
    assert isinstance(err, LeadthroughError)
    assert err.value == "push_x" and err.field == "operator"
    msg = str(err)
    assert "'push_x'" in msg
    assert all(name in msg for name in OPERATOR_NAMES)


@pytest.mark.parametrize("start", [[1.0, 2.0], [1.0, math.nan, 0.0], [[1.0, 2.0, 3.0]],
                                   ["a", "b", "c"]])
def test_bad_start_position_raises(start: list) -> None:
    with pytest.raises(SimulationError, match="tcp_start_base"):
        make_operator("seam", seed=0, tcp_start_base=start)


@pytest.mark.parametrize("seed", [-1, 1.5, True])
def test_bad_seed_raises(seed: object) -> None:
    with pytest.raises(SimulationError, match="seed"):
        make_operator("random", seed=seed, tcp_start_base=START)  # type: ignore[arg-type]


def test_bad_pushes_raise() -> None:
    with pytest.raises(SimulationError, match="push"):
        ScriptedPush(1.0, 1.05, (1.0, 0.0, 0.0), ramp_s=0.05)  # shorter than two ramps
    with pytest.raises(SimulationError, match="force_base"):
        ScriptedPush(1.0, 2.0, (1.0, math.inf, 0.0))
    a, b = ScriptedPush(1.0, 2.0, (1.0, 0.0, 0.0)), ScriptedPush(1.5, 3.0, (1.0, 0.0, 0.0))
    with pytest.raises(SimulationError, match="overlap"):
        PushScript(name="x", pushes=(a, b), duration_s=4.0)
    with pytest.raises(SimulationError, match="duration_s"):
        PushScript(name="x", pushes=(a,), duration_s=1.5)
    with pytest.raises(SimulationError, match="marks"):
        PushScript(name="x", pushes=(a,), duration_s=3.0, marks=(Mark(3.5, "P1"),))


def test_bad_seam_settings_raise() -> None:
    with pytest.raises(SimulationError, match=r"seam\.stiffness"):
        SeamOperator(START, stiffness=-1.0)
    with pytest.raises(SimulationError, match="lean_gain"):
        SeamOperator(START, lean_gain=-1.0)
    with pytest.raises(SimulationError, match=r"seam\.mark_after_s"):
        SeamOperator(START, dwell_s=1.0, mark_after_s=1.0)


# ------------------------------------------------------------------------------------- pushes
def test_rest_is_zero_throughout() -> None:
    op = make_operator("rest", seed=0, tcp_start_base=START)
    w = _sample(op).wrench_base
    assert not w.any()
    assert op.marks == ()


def test_push_x_profile_and_timing() -> None:
    op = make_operator("push-x", seed=0, tcp_start_base=START)
    assert isinstance(op, PushScript)
    (p,) = op.pushes
    assert (p.t_start, p.t_end, p.magnitude) == (1.0, 4.0, 40.0)
    assert op.duration_s >= p.t_end + 1.0  # time after the release to come to rest
    t, w = _sample(op)
    assert not w[:, 1:].any()  # +x only, no torque
    assert not w[t <= 1.0].any()  # settling time: no hand
    full = (t >= 1.0 + p.ramp_s) & (t <= 4.0 - p.ramp_s)
    np.testing.assert_array_equal(w[full, 0], 40.0)
    assert not w[t >= 4.0].any()  # released: exactly zero
    # raised-cosine edges: half force mid-ramp, monotonic, at most π/2·F·dt/ramp per step
    assert op.wrench(1.0 + p.ramp_s / 2, START)[0] == pytest.approx(20.0)
    assert op.wrench(4.0 - p.ramp_s / 2, START)[0] == pytest.approx(20.0)
    rise = w[(t >= 1.0) & (t <= 1.0 + p.ramp_s), 0]
    assert np.all(np.diff(rise) > 0)
    assert np.abs(np.diff(w[:, 0])).max() <= math.pi / 2 * 40.0 * DT / p.ramp_s + 1e-9


def test_diagonal_profile_and_marks() -> None:
    op = make_operator("diagonal", seed=0, tcp_start_base=START)
    assert isinstance(op, PushScript)
    (p,) = op.pushes
    t, w = _sample(op)
    full = (t >= p.t_start + p.ramp_s) & (t <= p.t_end - p.ramp_s)
    assert full.sum() > 2900  # about 3 s of full force
    diag = 40.0 * np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    np.testing.assert_allclose(w[full, :3], np.broadcast_to(diag, (int(full.sum()), 3)),
                               rtol=1e-12)
    assert not w[:, 3:].any()
    assert not w[~((t >= p.t_start) & (t < p.t_end))].any()
    assert [m.label for m in op.marks] == ["P1", "P2"]
    p1, p2 = op.marks
    assert p1.t < p.t_start and p2.t >= p.t_end + 1.0  # marked at rest, before and after
    assert not op.wrench(p1.t, START).any() and not op.wrench(p2.t, START).any()


def test_random_is_reproducible_by_seed() -> None:
    a = make_operator("random", seed=11, tcp_start_base=START)
    b = make_operator("random", seed=11, tcp_start_base=START)
    c = make_operator("random", seed=12, tcp_start_base=START)
    assert isinstance(a, PushScript) and isinstance(c, PushScript)
    assert a == b
    assert a.pushes != c.pushes
    np.testing.assert_array_equal(_sample(a).wrench_base, _sample(b).wrench_base)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_pushes_within_ranges(seed: int) -> None:
    op = random_pushes(seed)
    assert len(op.pushes) == 8
    forces = np.array([p.force_base for p in op.pushes])
    mags = np.linalg.norm(forces, axis=1)
    assert np.all((mags >= 20.0) & (mags <= 60.0))
    # directions differ push to push (not a fixed axis)
    dirs = forces / mags[:, None]
    assert np.abs(dirs @ dirs.T - np.eye(8)).max() < 1.0 - 1e-3
    for p, nxt in zip(op.pushes, op.pushes[1:], strict=False):
        assert 0.5 <= p.t_end - p.t_start <= 2.0
        assert 0.05 <= p.ramp_s <= 0.1
        assert 0.5 <= nxt.t_start - p.t_end <= 1.5
    t, w = _sample(op)
    f = np.linalg.norm(w[:, :3], axis=1)
    assert f.max() <= 60.0 + 1e-9
    in_push = np.zeros(t.shape, dtype=bool)
    for p in op.pushes:
        in_push |= (t >= p.t_start) & (t < p.t_end)
    assert not w[~in_push].any()  # released between pushes
    # smooth onsets: no step bigger than the steepest raised-cosine ramp allows
    assert np.abs(np.diff(w[:, :3], axis=0)).max() <= math.pi / 2 * 60.0 * DT / 0.05 + 1e-9


# --------------------------------------------------------------------------------------- seam
def _seam() -> SeamOperator:
    """The registry's seam with the lean switched off and a 1500 N/m, 150 N·s/m hand, 2 s
    dwells (the pure spring-damper the tests below check in closed form)."""
    return SeamOperator(START, stiffness=1500.0, damping=150.0, lean_gain=0.0, dwell_s=2.0,
                        mark_after_s=1.5)


def test_seam_geometry_target_and_marks() -> None:
    op = _seam()
    tm = op.timing
    assert np.linalg.norm(op.p2_base - op.p1_base) == pytest.approx(0.3)
    assert 0.05 < np.linalg.norm(op.p1_base - START) < 0.3
    t = np.arange(round(op.duration_s / DT)) * DT
    targets = [op.target(float(tk)) for tk in t]
    pos = np.array([g.position_base for g in targets])
    vel = np.array([g.velocity_base for g in targets])
    np.testing.assert_array_equal(pos[t <= tm.t_leave_start], np.broadcast_to(START, (int(
        (t <= tm.t_leave_start).sum()), 3)))
    speed = np.linalg.norm(vel, axis=1)
    assert speed.max() <= 0.05 + 1e-12 and speed.max() > 0.049  # hand-like, cruises at 5 cm/s
    # velocity is the derivative of the position; no jumps
    np.testing.assert_allclose(np.diff(pos, axis=0) / DT, 0.5 * (vel[1:] + vel[:-1]), atol=2e-4)
    # dwells at P1 and P2 around the marks
    p1, p2 = op.marks
    assert (p1.label, p2.label) == ("P1", "P2")
    assert tm.t_at_p1 < p1.t < tm.t_leave_p1 and tm.t_at_p2 < p2.t < tm.t_release
    for lo, hi, point in [(tm.t_at_p1, tm.t_leave_p1, op.p1_base),
                          (tm.t_at_p2, tm.t_release, op.p2_base)]:
        np.testing.assert_allclose(pos[(t >= lo) & (t <= hi)], np.broadcast_to(point, (int(
            ((t >= lo) & (t <= hi)).sum()), 3)), atol=1e-12)
    # P1 -> P2 is a straight line
    u = (op.p2_base - op.p1_base) / 0.3
    r = pos[(t >= tm.t_leave_p1) & (t <= tm.t_at_p2)] - op.p1_base
    assert np.abs(r - np.outer(r @ u, u)).max() < 1e-12
    assert np.all(np.diff(r @ u) >= 0)


def test_seam_spring_saturation_and_release() -> None:
    op = _seam()
    t = op.marks[0].t  # dwell at P1: target at rest
    d = np.array([0.01, -0.02, 0.005])
    op.wrench(t - DT, op.p1_base + d)  # TCP at rest there: velocity estimate zero
    w = op.wrench(t, op.p1_base + d)
    np.testing.assert_allclose(w[:3], -1500.0 * d, atol=1e-9)
    assert not w[3:].any()
    # far away: saturated at 60 N, still pulling toward the target
    op.reset()
    far = np.array([0.3, 0.5, -0.4])
    w = op.wrench(t, op.p1_base + far)
    assert np.linalg.norm(w[:3]) == pytest.approx(60.0, rel=1e-12)
    np.testing.assert_allclose(w[:3] / 60.0, -far / np.linalg.norm(far), atol=1e-12)
    # the hand lets go: exactly zero wherever the TCP is
    assert not op.wrench(op.timing.t_release, op.p1_base + far).any()
    assert not op.wrench(op.duration_s, START).any()


def test_seam_damper_uses_tcp_velocity() -> None:
    op = _seam()
    t0 = op.marks[0].t - 0.5
    v = np.array([0.02, 0.0, -0.01])
    for k in range(300):  # TCP drifts through P1 at constant v; the 10 ms filter settles
        t = t0 + k * DT
        p = op.p1_base + v * (t - op.marks[0].t)
        w = op.wrench(t, p)
    np.testing.assert_allclose(w[:3], 1500.0 * (op.p1_base - p) - 150.0 * v, atol=1e-6)
    # a repeated call at the same t (any position) keeps the velocity estimate
    w_again = op.wrench(t, p)
    np.testing.assert_array_equal(w_again, w)
    w_moved = op.wrench(t, p + np.array([1e-3, 0.0, 0.0]))
    np.testing.assert_allclose(w_moved[:3] - w[:3], [-1.5, 0.0, 0.0], atol=1e-9)
    # time going back (a restarted session) forgets the velocity: no damper force at rest
    w0 = op.wrench(op.timing.t_at_p1, op.p1_base)
    assert np.all(np.isfinite(w0)) and not w0.any()


def test_seam_lean_grows_while_the_tool_is_short_and_relaxes_on_the_move() -> None:
    """At a point, a tool held short of it gets an ever firmer push (k_i·error per second, up to
    the saturation); once the target moves on, the lean fades with the time constant accel_s."""
    op = SeamOperator(START, stiffness=3000.0, damping=0.0, lean_gain=1000.0)
    tm = op.timing
    d = np.array([0.004, -0.003, 0.0])  # the tool stops 5 mm short of P1
    t0 = tm.t_at_p1
    steps = round(1.0 / DT)
    w = np.array([op.wrench(t0 + k * DT, op.p1_base - d) for k in range(steps + 1)])
    np.testing.assert_allclose(w[0, :3], 3000.0 * d, atol=1e-9)
    np.testing.assert_allclose(w[-1, :3], 3000.0 * d + 1000.0 * 1.0 * d, rtol=1e-3)
    assert np.all(np.diff(np.linalg.norm(w[:, :3], axis=1)) > 0)
    # held far enough short for long enough: saturated at max_force, no wind-up beyond it
    k = steps
    for k in range(steps, 40 * steps):
        w_k = op.wrench(t0 + k * DT, op.p1_base - 3.0 * d)
        if t0 + k * DT >= tm.t_leave_p1 - DT:
            break
    assert np.linalg.norm(w_k[:3]) == pytest.approx(60.0, rel=1e-9)
    # the target moves on: with the tool on the target, the force left is the lean, fading
    lean = []
    for j in range(round(op.accel_s / DT) + 1):
        t = tm.t_leave_p1 + DT * (j + 1)
        lean.append(np.linalg.norm(op.wrench(t, op.target(t).position_base)[:3]))
    assert lean[-1] == pytest.approx(lean[0] * np.exp(-1.0), rel=0.01)
    # pure spring-damper without it
    flat = SeamOperator(START, stiffness=3000.0, damping=0.0, lean_gain=0.0)
    w = [flat.wrench(t0 + k * DT, flat.p1_base - d) for k in range(steps)]
    np.testing.assert_allclose(w[-1][:3], 3000.0 * d, atol=1e-9)


def test_seam_leads_an_admittance_along_the_line() -> None:
    """A 10 kg point mass with 50 N·s/m damping, driven by the hand: well damped, reaches P1 and
    P2 at the marks, stays on the seam, never needs more than 60 N."""
    op = _seam()
    m, c = 10.0, 50.0
    p, v = START.copy(), np.zeros(3)
    n = round(op.duration_s / DT)
    pos, force = np.empty((n, 3)), np.empty((n, 3))
    for k in range(n):
        f = op.wrench(k * DT, p)[:3]
        pos[k], force[k] = p, f
        v = v + DT * (f - c * v) / m
        p = p + DT * v
    t = np.arange(n) * DT
    assert np.linalg.norm(force, axis=1).max() <= 60.0
    for mark, point in zip(op.marks, (op.p1_base, op.p2_base), strict=True):
        assert np.linalg.norm(pos[round(mark.t / DT)] - point) < 1e-6
    tm = op.timing
    target = np.array([op.target(float(tk)).position_base for tk in t[t < tm.t_release]])
    assert np.linalg.norm(pos[t < tm.t_release] - target, axis=1).max() < 5e-3
    u = (op.p2_base - op.p1_base) / 0.3
    r = pos[(t >= tm.t_leave_p1) & (t <= tm.t_at_p2)] - op.p1_base
    assert np.linalg.norm(r - np.outer(r @ u, u), axis=1).max() < 1e-6


# -------------------------------------------------------------------------------- integration
def test_sim_robot_feels_the_push_x_script(er20: Robot) -> None:
    op = make_operator("push-x", seed=0, tcp_start_base=START)
    sim = SimRobot(er20, SimConfig(seed=4), q0=POSE, operator=op)
    log = hold(sim, 4.2)  # through the release at 4 s
    expected = np.array([op.wrench(float(tk), START) for tk in log.time])
    np.testing.assert_array_equal(log.truth.wrench_base, expected)
    pushing = (log.time >= 1.05) & (log.time <= 3.95)
    np.testing.assert_array_equal(log.truth.wrench_base[pushing, 0], 40.0)
    assert np.abs(log.truth.external_torque[pushing]).max() > 1.0  # J^T·F felt by the joints
    assert not log.truth.external_torque[log.time >= 4.0].any()
    # the servo holds the pose against the 40 N push
    assert np.abs(log.truth.q - POSE).max() < 5e-3
