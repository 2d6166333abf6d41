"""The guiding controller on the er20 at the algorithm level (a perfect servo: the measured q is
the last setpoint): rest, the +x push, frames and axes, the baseline, deadman and events."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pytest

from leadthrough.control import (
    AutoFriction,
    AutoFrictionConfig,
    CartesianLimits,
    Cause,
    DifferentialIK,
    Fault,
    GuidingConfig,
    GuidingController,
    GuidingInput,
    HandReleaseConfig,
    HermiteInterpolator,
    SafetyConfig,
    State,
    VirtualFrictionConfig,
)
from leadthrough.control import (
    GuidingStatus as Status,
)
from leadthrough.errors import ControlError
from leadthrough.robot import Robot

DT = 0.01
SUB = 10
Q_WORK = np.array([0.0, -0.6, 0.9, 0.0, 0.8, 0.0])       # TCP at (0.72, 0, 0.31) m, μ = 0.26
#: Rounding allowance of norms compared with a limit (the limits are exact up to rounding).
ROUND = 1e-12
#: The paper's law alone (eq. 31–33), without the stop after letting go.
PAPER_LAW = HandReleaseConfig(enabled=False)


def pose_ik(robot: Robot, q_guess: np.ndarray, position: np.ndarray) -> np.ndarray:
    """Joint position putting the TCP at ``position`` with the orientation at ``q_guess``."""
    m, d, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    pin.framesForwardKinematics(m, d, q_guess)
    target = pin.SE3(d.oMf[fid].rotation.copy(), np.asarray(position, dtype=float))
    q = q_guess.copy()
    for _ in range(50):
        pin.framesForwardKinematics(m, d, q)
        e = pin.log6(d.oMf[fid].actInv(target)).vector
        if np.linalg.norm(e) < 1e-13:
            break
        q += np.linalg.solve(pin.computeFrameJacobian(m, d, q, fid, pin.LOCAL), e)
    return q


def fk_positions(robot: Robot, qs: np.ndarray) -> np.ndarray:
    """TCP positions [m], shape (k, 3), of joint positions (k, n)."""
    m, d, fid = robot.model, robot.model.createData(), robot.tcp_frame_id
    out = np.empty((qs.shape[0], 3))
    for i, q in enumerate(qs):
        pin.framesForwardKinematics(m, d, q)
        out[i] = d.oMf[fid].translation
    return out


@dataclass
class Trace:
    """Per-cycle outputs (k cycles) and the 1 ms commands (k·10)."""

    twist_base: np.ndarray
    twist_tool: np.ndarray
    position: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    state: np.ndarray
    fault: np.ndarray
    status: np.ndarray
    speed_scale: np.ndarray
    friction: np.ndarray
    q_ms: np.ndarray
    qd_ms: np.ndarray


Inject = Callable[[int, GuidingInput], None]


def run(ctl: GuidingController, q0: np.ndarray, wrench_base: np.ndarray,
        deadman: np.ndarray | None = None, inject: Inject | None = None,
        interpolate: bool = True) -> Trace:
    """Run ``len(wrench_base)`` cycles from ``q0`` with a perfect servo.

    Args:
        ctl: The controller (reset here).
        q0: Start [rad].
        wrench_base: Operator wrench per cycle, base axes at the TCP, shape (k, 6).
        deadman: Per cycle; default released at cycle 0, then held.
        inject: Called with (cycle, input) after the input is filled, to corrupt it.
        interpolate: Also produce the 1 ms commands.
    """
    k_n, n = wrench_base.shape[0], ctl.n
    if deadman is None:
        deadman = np.arange(k_n) > 0
    ctl.reset(q0)
    interp = HermiteInterpolator(n, DT, SUB)
    interp.reset(q0)
    cmd = interp.make_command()
    inp, out = ctl.make_input(), ctl.make_output()
    inp.q[:] = q0
    k_ms = k_n * SUB if interpolate else 0
    tr = Trace(twist_base=np.zeros((k_n, 6)), twist_tool=np.zeros((k_n, 6)),
               position=np.zeros((k_n, 3)), q=np.zeros((k_n, n)), qd=np.zeros((k_n, n)),
               state=np.zeros(k_n, dtype=int), fault=np.zeros(k_n, dtype=int),
               status=np.zeros(k_n, dtype=int), speed_scale=np.zeros(k_n),
               friction=np.zeros((k_n, 6)), q_ms=np.zeros((k_ms, n)), qd_ms=np.zeros((k_ms, n)))
    for k in range(k_n):
        inp.t, inp.sequence, inp.deadman = k * DT, k, bool(deadman[k])
        inp.wrench_base[:] = wrench_base[k]
        if inject is not None:
            inject(k, inp)
        status = ctl.update(inp, out)
        tr.twist_base[k], tr.twist_tool[k] = out.twist_base, out.twist_tool
        tr.position[k] = out.transform_tool_to_base[:3, 3]
        tr.q[k], tr.qd[k] = out.q, out.qd
        tr.state[k], tr.fault[k], tr.status[k] = out.state, out.fault, status
        tr.speed_scale[k], tr.friction[k] = out.speed_scale, out.friction
        if interpolate:
            interp.set_target(out.q, out.qd)
            for i in range(SUB):
                interp.update(cmd)
                tr.q_ms[k * SUB + i], tr.qd_ms[k * SUB + i] = cmd.q, cmd.qd
        inp.q[:] = out.q                       # perfect servo
    return tr


def linear_speed(twist: np.ndarray) -> np.ndarray:
    return np.linalg.norm(twist[:, :3], axis=1)


def linear_acc(twist: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(twist[:, :3], axis=0), axis=1) / DT


def random_work_poses(robot: Robot, k: int, seed: int) -> list[np.ndarray]:
    """Poses away from limits and singularities (μ > 0.05)."""
    rng = np.random.default_rng(seed)
    ik = DifferentialIK(robot)
    poses: list[np.ndarray] = []
    while len(poses) < k:
        q = rng.uniform(robot.lower_limits + 0.3, robot.upper_limits - 0.3)
        ik.compute_kinematics(q)
        if ik.manipulability > 0.05:
            poses.append(q)
    return poses


# --------------------------------------------------------------------- must show 1


def test_rest_commands_exactly_zero_velocity_at_20_random_poses(er20: Robot) -> None:
    """No force, estimator noise below δ (a bias plus noise up to 14.9 N / N·m), 20 poses × 10 s:
    the commanded twist and joint velocity are 0.0 exactly and the setpoints and the 1 ms
    commands stay bit for bit at the start (rest drift 0)."""
    rng = np.random.default_rng(7)
    ctl = GuidingController(er20)
    for q0 in random_work_poses(er20, 20, seed=11):
        noise = np.clip(rng.normal(3.0, 5.0, size=(1000, 6)), -14.9, 14.9)
        tr = run(ctl, q0, noise)
        assert np.all(tr.state[1:] == State.GUIDING)
        assert np.all(tr.twist_base == 0.0) and np.all(tr.qd == 0.0)
        assert np.all(tr.q == q0) and np.all(tr.q_ms == q0) and np.all(tr.qd_ms == 0.0)


def test_velocity_baseline_drifts_where_virtual_friction_holds(er20: Robot) -> None:
    """The same noise with [14]: the commanded velocity is not zero and the TCP drifts."""
    rng = np.random.default_rng(8)
    noise = np.clip(rng.normal(3.0, 5.0, size=(1000, 6)), -14.9, 14.9)
    base = run(GuidingController(er20, GuidingConfig(controller="velocity")), Q_WORK, noise)
    vf = run(GuidingController(er20), Q_WORK, noise)
    drift = np.linalg.norm(base.position[-1] - base.position[0])
    assert np.all(vf.position == vf.position[0])
    assert drift > 0.05                                       # metres, in 10 s
    assert np.count_nonzero(linear_speed(base.twist_base)) > 900


# --------------------------------------------------------------------- must show 2


def test_push_x_40n_moves_along_x_capped_then_stops_on_stopping_friction(er20: Robot) -> None:
    """Table IV defaults. 40 N along +x for 8.6 s (with off-axis estimator noise below δ), then
    released: a = (40 − 15)/1000, speed capped at 0.2 m/s without overshoot, off-axis motion 0
    in the command and ≤ 2 % in the joint commands' TCP path, then a stop at δ_s/M (the
    paper's law alone: without the stop after letting go, which test_control_hand_release
    covers)."""
    q0 = pose_ik(er20, np.array([-np.pi / 2, -0.6, 0.9, 0.0, 0.8, 0.0]), [-0.65, -0.85, 0.31])
    k_n, release = 1500, 860
    rng = np.random.default_rng(9)
    w = np.zeros((k_n, 6))
    w[:, 1:] = rng.uniform(-10.0, 10.0, size=(k_n, 5))         # estimator noise, below δ
    w[1:release, 0] = 40.0     # from the press (before it the estimate is no push)
    tr = run(GuidingController(er20, GuidingConfig(hand_release=PAPER_LAW)), q0, w)
    vx = tr.twist_base[:, 0]
    assert np.all(tr.fault == Fault.NONE)
    # along x only: the other five commanded components are exactly zero
    assert np.all(tr.twist_base[:, 1:] == 0.0)
    # acceleration (40 − 15)/1000 m/s² up to the cap, capped at 0.2 m/s, no overshoot
    a = np.diff(np.concatenate([[0.0], vx]))[:release] / DT
    np.testing.assert_allclose(a[vx[:release] < 0.2 - 1e-12][1:], 0.025, rtol=1e-9)
    assert vx.max() <= 0.2 + ROUND and np.count_nonzero(vx >= 0.2 - ROUND) > 50
    assert np.all(np.diff(vx[:release]) >= 0.0)
    # release: deceleration δ_s/M = 0.05 m/s², then exactly at rest
    dec = -np.diff(vx[release - 1:]) / DT
    moving = vx[release:] > 0.0
    np.testing.assert_allclose(dec[moving], 0.05, rtol=1e-9)
    stop = release + int(np.argmax(vx[release:] == 0.0))
    assert (stop - release) * DT == pytest.approx(0.2 / 0.05, abs=2 * DT)
    assert np.all(tr.twist_base[stop:] == 0.0) and np.all(tr.q[stop:] == tr.q[stop])
    # the joint commands (1 ms, after IK and interpolation) move the TCP along x only
    p = fk_positions(er20, tr.q_ms)
    v = np.diff(p, axis=0) / (DT / SUB)
    off_axis_ratio = np.abs(v[:, 1:]).max() / np.abs(v[:, 0]).max()
    assert off_axis_ratio <= 0.02
    # measured: 8e-4 at 1 ms (joint-space Hermite segments between the setpoints, whose knot
    # velocities are the chords' slopes), 5e-6 at the 10 ms setpoints (IK residual)
    p10 = fk_positions(er20, tr.q)
    v10 = np.diff(p10, axis=0) / DT
    assert np.abs(v10[:, 1:]).max() / np.abs(v10[:, 0]).max() < 1e-4
    # the setpoints' speed is the commanded one up to the IK's residual (measured 2.5e-6)
    assert np.abs(v10[:, 0]).max() <= 0.2 * (1 + 1e-5)
    assert p[-1, 0] - p[0, 0] == pytest.approx(
        np.sum(vx) * DT, abs=1e-6)                            # the path integrates the twist


# --------------------------------------------------------------------- frames, axes, modes


def test_tool_frame_translation_only(er20: Robot) -> None:
    """frame="tool", rotations disabled: a push along the tool z axis moves the TCP along that
    axis in the base frame; torques are ignored."""
    cfg = GuidingConfig(frame="tool", axes_enabled=(True,) * 3 + (False,) * 3,
                        virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6))
    ctl = GuidingController(er20, cfg)
    ik = DifferentialIK(er20)
    ik.compute_kinematics(Q_WORK)
    R = ik.transform_tool_to_base.rotation
    w = np.zeros((200, 6))
    w[:, :3] = R[:, 2] * 40.0                                 # along tool z, in base axes
    w[:, 3:] = [30.0, -20.0, 25.0]                            # torques, ignored
    tr = run(ctl, Q_WORK, w)
    assert np.all(tr.twist_tool[:, [0, 1, 3, 4, 5]] == 0.0)
    assert tr.twist_tool[-1, 2] > 0.0
    np.testing.assert_allclose(tr.twist_base[:, :3], tr.twist_tool[:, 2:3] * R[:, 2],
                               atol=1e-15)
    # orientation kept: the TCP path follows the tool z axis
    d = tr.position[-1] - tr.position[0]
    np.testing.assert_allclose(d / np.linalg.norm(d), R[:, 2], atol=1e-9)


def test_locked_axis_does_not_move(er20: Robot) -> None:
    cfg = GuidingConfig(axes_enabled=(False, True, True, True, True, True))
    w = np.zeros((300, 6))
    w[:, 0], w[:, 1] = 80.0, 30.0
    tr = run(GuidingController(er20, cfg), Q_WORK, w, interpolate=False)
    assert np.all(tr.twist_base[:, 0] == 0.0) and tr.twist_base[-1, 1] > 0.0


def test_auto_friction_from_noise(er20: Robot) -> None:
    """friction_mode="auto" (eq. 36): the thresholds in use follow the pose; a force below
    them moves nothing, one above them does."""
    mean = np.array([-4.2, -0.05, 1.25, 0.34, 0.52, -0.37])
    std = np.array([15.0, 19.0, 3.2, 0.9, 1.0, 0.43])
    acfg = AutoFrictionConfig(basis="mean+std", guiding_ratio=1.0, stopping_ratio=3.0)
    cfg = GuidingConfig(friction_mode="auto", auto_friction=acfg)
    ctl = GuidingController(er20, cfg, noise_mean=mean, noise_std=std)
    ik = DifferentialIK(er20)
    ik.compute_kinematics(Q_WORK)
    J = np.zeros((6, 6))
    ik.jacobian_in_frame("base", J)
    expected, expected_s = np.zeros(6), np.zeros(6)
    AutoFriction(mean, std, acfg).update(J, ik.manipulability, expected, expected_s)
    below = np.tile(0.99 * expected, (100, 1))
    tr = run(ctl, Q_WORK, below, interpolate=False)
    np.testing.assert_allclose(tr.friction[-1], expected, rtol=1e-12)
    assert np.all(tr.twist_base == 0.0)
    above = np.zeros((100, 6))
    above[:, 0] = expected[0] + 20.0
    tr = run(ctl, Q_WORK, above, interpolate=False)
    assert tr.twist_base[-1, 0] > 0.0
    assert not np.allclose(tr.friction[-1], expected)          # moved: thresholds followed
    with pytest.raises(ControlError, match="noise_mean"):
        GuidingController(er20, cfg)


def test_singularity_slows_then_stops(er20: Robot) -> None:
    """A torque turning the wrist toward q5 = 0: the speed scale drops below 1 as μ falls
    below the slow threshold, then SINGULARITY stops it."""
    cfg = GuidingConfig(frame="tool", virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6))
    ctl = GuidingController(er20, cfg)
    q0 = np.array([0.0, -0.6, 0.9, 0.0, 0.35, 0.0])
    ik = DifferentialIK(er20)
    ik.compute_kinematics(q0)
    w = np.zeros((600, 6))
    w[:, 3:] = ik.transform_tool_to_base.rotation @ np.array([0.0, -30.0, 0.0])
    tr = run(ctl, q0, w, interpolate=False)
    hit = int(np.argmax(tr.state == State.FAULT))
    assert tr.fault[hit] == Fault.SINGULARITY
    scale = tr.speed_scale[:hit]
    assert scale.min() < 0.5
    # below the scaled cap, or decelerating toward it at the acceleration limit
    ang = np.linalg.norm(tr.twist_base[:hit, 3:], axis=1)
    cap = 0.2 * scale
    assert np.all((ang[1:] <= cap[1:] * (1 + ROUND))
                  | np.isclose(ang[1:], ang[:-1] - 0.4 * DT, rtol=1e-9, atol=0))
    assert np.all(tr.twist_base[-1] == 0.0) and np.all(tr.state[hit:] == State.FAULT)


# --------------------------------------------------------------------- deadman, events


def test_deadman_release_stops_at_the_limit_then_idle(er20: Robot) -> None:
    cfg = GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6))
    ctl = GuidingController(er20, cfg)
    w = np.zeros((300, 6))
    w[:, 1] = 60.0                                            # keeps pushing after release
    held = (np.arange(300) > 0) & (np.arange(300) < 150)
    tr = run(ctl, Q_WORK, w, deadman=held)
    assert tr.twist_base[149, 1] == pytest.approx(0.2)
    stopping = tr.state == State.STOPPING
    assert stopping[150] and not stopping[149]
    acc = linear_acc(tr.twist_base)
    assert acc[149:].max() <= 0.4 * (1 + ROUND)
    assert acc[149] == pytest.approx(0.4, rel=1e-9)           # the stop uses the full limit
    idle = 150 + int(np.argmax(tr.state[150:] == State.IDLE))
    assert np.all(tr.twist_base[idle:] == 0.0) and idle - 150 == pytest.approx(50, abs=1)
    assert np.all(tr.fault == Fault.NONE) and np.all(tr.status == Status.OK)
    causes = [(e.cause, e.from_state, e.to_state) for e in ctl.events]
    assert causes == [(Cause.RESET, State.IDLE, State.IDLE),
                      (Cause.DEADMAN_PRESSED, State.IDLE, State.GUIDING),
                      (Cause.DEADMAN_RELEASED, State.GUIDING, State.STOPPING),
                      (Cause.STOPPED, State.STOPPING, State.IDLE)]
    assert [e.t for e in ctl.events] == pytest.approx([0.0, 0.01, 1.5, idle * DT])


def test_deadman_held_at_start_needs_a_new_press(er20: Robot) -> None:
    w = np.zeros((60, 6))
    w[:20, 0] = w[35:, 0] = 80.0    # pushes while held, lets go, pushes from the new press
    held = np.ones(60, dtype=bool)
    held[20:35] = False
    tr = run(GuidingController(er20), Q_WORK, w, deadman=held, interpolate=False)
    assert np.all(tr.state[:35] == State.IDLE) and np.all(tr.twist_base[:35] == 0.0)
    assert np.all(tr.state[35:] == State.GUIDING) and tr.twist_base[-1, 0] > 0.0
    no_edge = GuidingConfig(safety=SafetyConfig(require_deadman_edge=False))
    tr = run(GuidingController(er20, no_edge), Q_WORK, w, deadman=np.ones(60, dtype=bool),
             interpolate=False)
    assert np.all(tr.state == State.GUIDING)


# --------------------------------------------------------------------- set-up errors


def test_setup_errors(er20: Robot) -> None:
    with pytest.raises(ControlError, match=r"guiding.frame"):
        GuidingConfig(frame="world")
    with pytest.raises(ControlError, match=r"guiding.controller"):
        GuidingConfig(controller="pid")
    with pytest.raises(ControlError, match=r"safety.joint_limit_margin"):
        GuidingConfig(safety=SafetyConfig(joint_limit_margin=0.005))
    with pytest.raises(ControlError, match=r"safety.workspace_max"):
        SafetyConfig(workspace_min=(0.0, 0.0, 0.0), workspace_max=(1.0, -1.0, 1.0))
    ctl = GuidingController(er20)
    with pytest.raises(ControlError, match="joint limits"):
        ctl.reset(er20.upper_limits + 0.1)
    with pytest.raises(ControlError, match="wrong size"):
        ctl.reset(np.zeros(5))
    boxed = GuidingController(er20, GuidingConfig(safety=SafetyConfig(
        workspace_min=(1.0, -1.0, 0.0), workspace_max=(2.0, 1.0, 1.0))))
    with pytest.raises(ControlError, match="workspace box"):
        boxed.reset(Q_WORK)
    assert CartesianLimits().max_linear_speed == 0.2


def test_after_a_stop_breaking_away_takes_the_stopping_friction(er20: Robot) -> None:
    """For settle_s + rezero_s after the motion stops, a push between δ and δ_s moves nothing
    (the drives are settling); afterwards the same push starts motion again (the paper's law
    with the settling; the stop after letting go would wait for a fresh grip)."""
    q0 = pose_ik(er20, np.array([-np.pi / 2, -0.6, 0.9, 0.0, 0.8, 0.0]), [-0.65, -0.85, 0.31])
    cfg = GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6),
                        settle_s=0.3, rezero_s=0.2, hand_release=PAPER_LAW)
    w = np.zeros((300, 6))
    w[:50, 0] = 40.0                  # push: moves
    w[50:, 0] = -30.0                 # then a pull above δ = 15 N but below δ_s = 50 N
    tr = run(GuidingController(er20, cfg), q0, w, interpolate=False)
    vx = tr.twist_base[:, 0]
    stop = 50 + int(np.argmax(vx[50:] == 0.0))
    assert vx[49] > 0.0 and stop > 50
    hold = round((cfg.settle_s + cfg.rezero_s) / DT)
    assert np.all(vx[stop:stop + hold] == 0.0)          # held while settling
    assert vx[stop + hold + 1] < 0.0                      # then the pull moves it
    assert np.all(tr.fault == Fault.NONE)


def test_after_a_release_at_rest_breaking_away_takes_the_stopping_friction(er20: Robot) -> None:
    """A hold below δ at rest, then let go: the estimate swinging the other way (the gears
    unloading) moves nothing for settle_s + rezero_s; a hold that never drops does not start a
    settle window, so the same pull then moves the tool at once (the paper's law with the
    settling; with the stop after letting go the tool stays put, see
    test_control_hand_release)."""
    cfg = GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6),
                        settle_s=0.3, rezero_s=0.2, hand_release=PAPER_LAW)
    hold = round((cfg.settle_s + cfg.rezero_s) / DT)
    w = np.zeros((200, 6))
    w[:100, 0] = 12.0                 # a hand resting on the tool, below δ = 15 N: no motion
    # let go: the estimate (3 Hz low-pass) swings to -30 N (< δ_s = 50 N)
    tau = 1.0 / (2 * np.pi * 3.0)
    w[100:, 0] = -30.0 + 42.0 * np.exp(-np.arange(100) * DT / tau)
    tr = run(GuidingController(er20, cfg), Q_WORK, w, interpolate=False)
    vx = tr.twist_base[:, 0]
    moves = int(np.argmax(vx < 0.0))
    # held while the drives settle (from the release, seen within 0.1 s), then it moves
    assert np.all(vx[:moves] == 0.0) and 100 + hold < moves <= 100 + hold + 10
    assert np.all(tr.fault == Fault.NONE)
    # no hold before: the same pull moves the tool as soon as it passes δ
    w[:100, 0] = 0.0
    w[100:, 0] = -30.0 + 30.0 * np.exp(-np.arange(100) * DT / tau)
    tr = run(GuidingController(er20, cfg), Q_WORK, w, interpolate=False)
    vx = tr.twist_base[:, 0]
    first = 100 + int(np.argmax(w[100:, 0] <= -15.0))
    assert np.all(vx[:first] == 0.0) and vx[first] < 0.0


def test_rest_cycles_reuse_the_kinematics_bit_for_bit(er20: Robot) -> None:
    """A cycle at rest reuses the kinematics and the IK residual of the unchanged setpoint; a
    controller made to recompute them every cycle gives the same outputs, bit for bit, through
    pushes, stops, rests, a deadman release, a refused reset, a fault and its clearing; and the
    cache is used (fewer kinematics than cycles)."""
    cfg = GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6),
                        safety=SafetyConfig(workspace_min=(-0.2, -1.5, -0.5),
                                            workspace_max=(1.8, 1.5, 2.0)))
    q_outside = Q_WORK.copy()
    q_outside[0] = 2.5                      # TCP at x = -0.58 m: outside the box, refused
    k_n = 700
    w = np.zeros((k_n, 6))
    w[10:120, 0] = 40.0                     # push +x, release, stop and rest
    w[250:330, 4] = 30.0                    # turn about y, release
    w[400:480, 1] = -70.0                   # push −y, deadman released while moving (cycle 450)
    w[520, 2] = np.nan                      # a fault at rest, cleared at cycle 560
    w[600:680, 2] = 70.0                    # push +z after the clearing and a new press
    k = np.arange(k_n)
    # released at cycle 0, from 450 to 470 and (a new press after the reset) 570 to 580
    deadman = (k > 0) & ((k < 450) | (k > 470)) & ((k < 570) | (k > 580))
    cached, fresh = GuidingController(er20, cfg), GuidingController(er20, cfg)
    outs = []
    kinematics = [0]
    compute = cached._ik.frame_kinematics

    def counted(q: np.ndarray) -> None:
        kinematics[0] += 1
        compute(q)

    cached._ik.frame_kinematics = counted  # type: ignore[method-assign]
    for ctl, recompute in ((cached, False), (fresh, True)):
        ctl.reset(Q_WORK)
        inp, out = ctl.make_input(), ctl.make_output()
        inp.q[:] = Q_WORK
        rows = []
        for k in range(k_n):
            inp.t, inp.sequence, inp.deadman = k * DT, k, bool(deadman[k])
            inp.wrench_base[:] = w[k]
            if recompute:
                ctl.record["kinematics_fresh"] = ctl.record["residual_fresh"] = False
            ctl.update(inp, out)
            if k in (200, 540):             # at rest, and in FAULT before its clearing
                with pytest.raises(ControlError, match="workspace"):
                    ctl.reset(q_outside)
            if k == 560:
                assert ctl.clear_fault(k * DT)
            rows.append(np.concatenate([out.q, out.qd, out.transform_tool_to_base.ravel(),
                                        out.twist_base, [out.manipulability, out.ik_residual,
                                                         out.state, out.fault]]))
            inp.q[:] = out.q                # perfect servo
        outs.append(np.array(rows))
    states = outs[0][:, -2]
    assert {State.GUIDING, State.STOPPING, State.FAULT, State.IDLE} <= set(states.tolist())
    np.testing.assert_array_equal(outs[0], outs[1])
    assert 0.2 * k_n < kinematics[0] < 0.8 * k_n              # rest cycles reused them
    # the session moved in every push, and rested (cached cycles) in between
    moving = np.any(outs[0][:, 6:12] != np.roll(outs[0][:, 6:12], 1, axis=0), axis=1)
    assert moving[20:120].all() and not moving[200:240].any() and moving[610:680].any()
