"""The command-to-position lag: measured on recordings (synthetic delays, the in-process
simulator), kept in the params file, given to ``guide``, and the estimator's friction following
the command that much later."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.cli import main
from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_COMMAND_LAG_S, nominal_drive_parameters
from leadthrough.errors import DataError
from leadthrough.estimation.estimator import EstimatorConfig, ExternalForceEstimator
from leadthrough.estimation.friction_torque import COMMAND_HISTORY
from leadthrough.identification.command_lag import measure_command_lag
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import load_params, save_params
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.sim.guiding_params import shipped_params_path
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.run import run_trajectory


def _commanded(t: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Smooth commanded positions [rad], shape (len(t), n): a few sines per joint."""
    rng = np.random.default_rng(seed)
    amp, freq, phase = rng.uniform(0.05, 0.3, (3, n)), rng.uniform(0.2, 1.5, (3, n)), \
        rng.uniform(0, 2 * np.pi, (3, n))
    return np.sum(amp[:, None, :] * np.sin(2 * np.pi * freq[:, None, :] * t[None, :, None]
                                           + phase[:, None, :]), axis=0)


@settings(max_examples=25, deadline=None)
@given(period=st.sampled_from([1e-3, 2e-3, 4e-3, 8e-3]), lag=st.floats(0.0, 0.03),
       seed=st.integers(0, 1000))
def test_the_lag_of_a_delayed_command_is_recovered(period: float, lag: float, seed: int) -> None:
    """Positions that are the command ``lag`` later, with a constant sag and encoder noise:
    the measured lag is within a tenth of a period (the grid's parabola) of the true one."""
    t = np.arange(0.0, 6.0, period)
    n = 6
    q_cmd = _commanded(t, n, seed)
    rng = np.random.default_rng(seed + 1)
    q = np.column_stack([np.interp(t - lag, t, q_cmd[:, j]) for j in range(n)])
    q += rng.uniform(-0.01, 0.01, n) + rng.normal(0.0, 2e-6, q.shape)
    q_cmd[:, 5] = q_cmd[0, 5]  # a joint commanded to stand still: not measured
    got = measure_command_lag(Recording(time=t, q=q, q_cmd=q_cmd, current=np.zeros_like(q)))
    assert got is not None and got.period_s == pytest.approx(period)
    assert np.isnan(got.joints_s[5]) and np.all(np.isfinite(got.joints_s[:5]))
    assert abs(got.lag_s - lag) <= 0.1 * period + 1e-4


def test_no_lag_without_commands_or_motion() -> None:
    t = np.arange(0.0, 2.0, 1e-3)
    q = np.zeros((t.size, 6))
    assert measure_command_lag(Recording(time=t, q=q, current=q)) is None
    assert measure_command_lag(Recording(time=t, q=q, current=q, q_cmd=q + 1e-4)) is None


def test_the_in_process_simulator_shows_its_command_at_the_next_step(er20: Robot) -> None:
    """``record`` in-process: the command written before a step is the position the servo
    tracks in that step, lag 0 (the wire's emulators are a cycle later: test_record_driver)."""
    t = np.arange(0.0, 1.0, 1e-3)
    q_cmd = guide_start_pose(er20) + 0.3 * _commanded(t, er20.n, 4)
    qd_cmd = np.gradient(q_cmd, t, axis=0)
    sim = SimRobot(er20, SimConfig(seed=5), q0=q_cmd[0])
    got = measure_command_lag(run_trajectory(sim, q_cmd, qd_cmd))
    assert got is not None and got.lag_s < 0.25e-3  # 0 samples of delay


def _estimates(er20: Robot, lag: float, commands: np.ndarray, motion: np.ndarray,
               reset_at: int, dt: float) -> np.ndarray:
    """τ_ext of a command-friction estimator with ``command_lag=lag``, fed ``commands`` as
    qd_cmd and the positions of the joint velocities ``motion``, reset at sample
    ``reset_at``."""
    n = er20.n
    params = replace(nominal_drive_parameters(er20), coulomb=np.full(n, 20.0),
                     viscous=np.full(n, 5.0))
    cfg = EstimatorConfig(friction_velocity="command", warm_up_s=0.0, dt=dt,
                          output_cutoff_hz=50.0, command_lag=lag)
    est = ExternalForceEstimator(er20, params, np.zeros(n), cfg)
    inp, out = est.make_input(), est.make_output()
    q = guide_start_pose(er20).copy()
    est.reset(q)
    rows = []
    for k, (c, v) in enumerate(zip(commands, motion, strict=True)):
        if k == reset_at:
            est.reset(q)
        q = q + v * dt
        inp.t, inp.q[:], inp.current[:], inp.qd_cmd[:] = k * dt, q, 1.0, c
        est.update(inp, out)
        rows.append(out.tau_ext.copy())
    return np.array(rows)


@settings(max_examples=10, deadline=None)
@given(delay=st.integers(0, 12), seed=st.integers(0, 1000), dt=st.sampled_from([1e-3, 8e-3]))
def test_the_friction_follows_the_command_delay_samples_later(er20: Robot, delay: int,
                                                              seed: int, dt: float) -> None:
    """An estimator with a lag of ``delay`` samples gives bit for bit what one without gives
    when fed the command ``delay`` samples late, zeros before each reset (a reset is at
    rest: the ring forgets the commands before it)."""
    rng = np.random.default_rng(seed)
    steps, reset_at = 300, 170
    commands = np.cumsum(rng.normal(0.0, 0.02, (steps, er20.n)), axis=0)
    late = np.zeros_like(commands)
    for start, stop in ((0, reset_at), (reset_at, steps)):
        late[start + delay:stop] = commands[start:stop - delay]
    lagged = _estimates(er20, delay * dt, commands, late, reset_at, dt)
    np.testing.assert_array_equal(lagged, _estimates(er20, 0.0, late, late, reset_at, dt))
    if delay:  # and the lag changes the estimate (the friction follows the command)
        assert np.max(np.abs(lagged - _estimates(er20, 0.0, commands, late, reset_at, dt))) > 1.0


def test_a_lag_beyond_the_ring_or_the_range_is_refused(er20: Robot) -> None:
    params = nominal_drive_parameters(er20)
    with pytest.raises(DataError, match="command lag") as e:
        ExternalForceEstimator(er20, params, np.zeros(er20.n), EstimatorConfig(
            dt=5e-4, command_lag=COMMAND_HISTORY * 5e-4))
    assert e.value.field == "command_lag"
    for bad in (-1e-3, MAX_COMMAND_LAG_S * 1.01, float("nan")):
        with pytest.raises(DataError):
            EstimatorConfig(command_lag=bad)
        with pytest.raises(DataError):
            replace(params, command_lag=bad)


def test_params_file_keeps_the_lag_and_refuses_bad_values(er20: Robot, tmp_path: Path) -> None:
    zeros = np.zeros(er20.n)
    stats = ResidualStats(mean=zeros, std=np.ones(er20.n), std_pct_max=zeros, rms=zeros,
                          rel_error_pct=0.0, J=1.0, k_omega=1.0,
                          samples=np.ones(er20.n, dtype=np.int64))
    params = nominal_drive_parameters(er20)
    none = save_params(tmp_path / "none.toml", er20, "ols", params, stats)
    assert "command_lag" not in none.read_text()
    assert load_params(none, er20).params.command_lag == 0.0
    path = save_params(tmp_path / "p.toml", er20, "ols", replace(params, command_lag=0.008),
                       stats)
    assert load_params(path, er20).params.command_lag == 0.008
    for bad in ("-0.001", "0.5", '"8 ms"'):
        (tmp_path / "bad.toml").write_text(
            path.read_text().replace("command_lag = 0.008", f"command_lag = {bad}"))
        with pytest.raises(DataError) as e:
            load_params(tmp_path / "bad.toml", er20)
        assert e.value.field == "meta.command_lag"


def test_guide_takes_the_lag_from_the_params_or_the_command_line(
        er20: Robot, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pf = load_params(shipped_params_path("er20"), er20)
    assert pf.params.command_lag == 0.0    # identified in-process
    lagged = replace(pf, params=replace(pf.params, command_lag=0.008))
    for dt, samples in ((8e-3, 1), (2e-3, 4), (1e-3, 8)):
        parts = build_loop(er20, lagged, LoopConfig(), dt)
        assert int(parts.estimator.record["command_delay"][0]) == samples
    out = tmp_path / "s.parquet"
    args = ["guide", "--robot", "er20", "--params", str(shipped_params_path("er20")),
            "--duration", "0.5", "-o", str(out)]
    for bad in ("-0.01", "0.2", "nan"):
        assert main([*args, "--command-lag", bad]) == 2
        err = capsys.readouterr().err
        assert "--command-lag" in err and "Traceback" not in err and not out.exists()
    assert main([*args, "--command-lag", "0.004", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["session"] == str(out)
