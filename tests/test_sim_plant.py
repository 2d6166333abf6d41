"""Plant presets: the ideal plant is the plant before issue 24 bit for bit; the preset reaches
the simulator from the configuration, the recording helpers, sessions and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from leadthrough.cli import main
from leadthrough.data.io import load_recording
from leadthrough.errors import ControlError, SimulationError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.trajectory_file import save_trajectory
from leadthrough.robot import Robot
from leadthrough.sim import ConstantWrench, SimConfig, SimRobot, run_trajectory
from leadthrough.sim.checks import check_hold
from leadthrough.sim.dress_pack import DressPackConfig, arm_links, dress_pack_inertias
from leadthrough.sim.drive_friction import DriveTrain
from leadthrough.sim.drive_mismatch import DriveMismatchConfig
from leadthrough.sim.driver import SimDriver
from leadthrough.sim.drivetrain import DriveTrainTruth
from leadthrough.sim.link_truth import LinkMismatchConfig, outside_box, second_moment
from leadthrough.sim.plant import PlantPreset
from leadthrough.sim.robot import draw_true_parameters
from leadthrough.sim.sensors import DelayLine, SensorConfig
from leadthrough.sim.session import SimSessionConfig
from leadthrough.sim.thermal import ThermalConfig, production_loss

DATA = Path(__file__).parent / "data"
POSE = np.array([0.3, -0.6, 0.4, 0.5, 0.8, 0.2])


def _golden_run(robot: Robot, plant: str) -> dict[str, np.ndarray]:
    """The run stored in ``data/ideal_plant_seed5.npz`` (made with commit 40b2d16, before the
    presets existed): motion on every joint and a wrench from 0.3 s."""
    sim = SimRobot(robot, SimConfig(seed=5, run=2, plant=plant), q0=POSE,
                   operator=ConstantWrench((40.0, -20.0, 10.0, 1.0, 0.0, -2.0), 0.3))
    t = np.arange(600) * 1e-3
    log = run_trajectory(sim, POSE + 0.05 * np.sin(2 * np.pi * t)[:, None] * np.ones(6))
    return {"q": log.q, "current": log.current, "true_current": log.truth.current,
            "true_q": log.truth.q}


def test_ideal_plant_is_bit_identical_to_the_plant_before_presets(er20: Robot) -> None:
    golden = np.load(DATA / "ideal_plant_seed5.npz")
    run = _golden_run(er20, "ideal")
    for name in ("q", "current", "true_current", "true_q"):
        np.testing.assert_array_equal(run[name], golden[name], err_msg=name)


def test_realistic_is_the_default_and_names_are_checked() -> None:
    assert SimConfig().plant is PlantPreset.REALISTIC
    assert SimSessionConfig().plant is PlantPreset.REALISTIC
    assert SimConfig(plant="ideal").plant is PlantPreset.IDEAL
    with pytest.raises(SimulationError, match=r"plant.*'perfect'.*realistic, ideal"):
        SimConfig(plant="perfect")  # type: ignore[arg-type]
    with pytest.raises(SimulationError, match=r"session\.plant"):
        SimSessionConfig(plant="perfect")  # type: ignore[arg-type]
    with pytest.raises(ControlError, match=r"session\.warm_up_s.*ideal plant"):
        SimSessionConfig(plant="ideal", warm_up_s=60.0)


def _trajectory(path: Path, robot: Robot) -> TrajectorySamples:
    t = np.arange(800) * 1e-3
    s = np.sin(np.pi * t)[:, None] * np.ones(robot.n)
    c = np.pi * np.cos(np.pi * t)[:, None] * np.ones(robot.n)
    traj = TrajectorySamples(time=t, q=POSE + 0.05 * s, qd=0.05 * c,
                             qdd=-0.05 * np.pi * s * np.pi)
    save_trajectory(path, traj, robot.name)
    return traj


def test_record_cli_runs_the_chosen_plant(er20: Robot, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    traj = _trajectory(tmp_path / "traj.csv", er20)
    out = tmp_path / "ideal.parquet"
    assert main(["record", "--robot", "er20", "--trajectory", str(tmp_path / "traj.csv"),
                 "--seed", "3", "--plant", "ideal", "--json", "-o", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["plant"] == "ideal"
    sim = SimRobot(er20, SimConfig(seed=3, plant="ideal"), q0=traj.q[0])
    direct = run_trajectory(sim, traj.q, traj.qd)
    np.testing.assert_array_equal(load_recording(out).current, direct.current)
    with pytest.raises(SystemExit) as e:
        main(["record", "--robot", "er20", "--trajectory", str(tmp_path / "traj.csv"),
              "--plant", "perfect", "-o", str(tmp_path / "x.parquet")])
    assert e.value.code == 2 and "invalid choice: 'perfect'" in capsys.readouterr().err


def test_record_cli_warms_the_robot_up(er20: Robot, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    traj = _trajectory(tmp_path / "traj.csv", er20)
    args = ["record", "--robot", "er20", "--trajectory", str(tmp_path / "traj.csv"),
            "--seed", "3", "--json"]
    assert main([*args, "--warm-up", "60", "-o", str(tmp_path / "warm.parquet")]) == 0
    assert json.loads(capsys.readouterr().out)["warm_up_min"] == 60.0
    sim = SimRobot(er20, SimConfig(seed=3, warm_up_s=3600.0), q0=traj.q[0])
    direct = run_trajectory(sim, traj.q, traj.qd)
    np.testing.assert_array_equal(load_recording(tmp_path / "warm.parquet").current,
                                  direct.current)
    for bad in (["--warm-up", "-5"], ["--warm-up", "nan"], ["--plant", "ideal", "--warm-up", "1"]):
        out = tmp_path / "bad.parquet"
        assert main([*args, *bad, "-o", str(out)]) == 2, bad
        assert "warm" in capsys.readouterr().err and not out.exists()


def test_realistic_links_leave_the_box_consistently(er20: Robot) -> None:
    """About one link in five has a quantity outside the identifiers' ±30 % box; every link is
    physically consistent; the dress pack adds a few kg over the ideal plant's links."""
    seeds = range(200)
    outside, added = [], []
    for seed in seeds:
        real = draw_true_parameters(er20, SimConfig(seed=seed)).inertias
        ideal = draw_true_parameters(er20, SimConfig(seed=seed, plant="ideal")).inertias
        for j, link in enumerate(real, start=1):
            outside.append(outside_box(er20.model.inertias[j], link, 0.3))
            assert link.mass > 0.0
            # positive semi-definite second moment: the inertia's triangle inequalities
            assert np.linalg.eigvalsh(second_moment(link.inertia)).min() >= -1e-12
        added.append(sum(r.mass - i.mass for r, i in zip(real, ideal, strict=True)))
    assert 0.15 <= np.mean(outside) <= 0.25
    arm = sum(er20.model.inertias[j].mass for j in arm_links(er20.model))
    assert arm == pytest.approx(38.0 + 18.0)  # the er20's upper arm and forearm
    # the median instance has no mass outlier: what it adds is the pack (5–10 % of the arm)
    assert 0.05 * arm <= np.median(added) <= 0.10 * arm


def test_dress_pack_hangs_beside_the_arm(er20: Robot) -> None:
    pack = dress_pack_inertias(er20.model, DressPackConfig(), np.random.default_rng(7))
    assert set(pack) == set(arm_links(er20.model)) == {2, 4}
    for j, inertia in pack.items():
        tip = np.asarray(er20.model.jointPlacements[j + 1].translation)
        c = np.asarray(inertia.lever)
        along = float(c @ tip) / float(tip @ tip)
        beside = float(np.linalg.norm(c - along * tip))
        assert along == pytest.approx(0.5) and 0.08 <= beside <= 0.15
    with pytest.raises(SimulationError, match=r"dress_pack\.start/end"):
        DressPackConfig(start=0.9, end=0.2)


def _steady_friction(drive: DriveTrainTruth, robot: Robot, q: np.ndarray, qd: np.ndarray
                     ) -> np.ndarray:
    """The drive train's friction after sliding at constant ``qd`` (the bristles settled)."""
    train = DriveTrain(drive, robot.gear_ratio)
    for _ in range(3000):
        train.update(q, qd, np.zeros(robot.n), 1e-3)
    return train.friction.copy()


def test_realistic_friction_has_its_own_stribeck_shape_and_nonlinear_viscous(er20: Robot
                                                                             ) -> None:
    ideal = draw_true_parameters(er20, SimConfig(seed=4, plant="ideal")).drive
    real = draw_true_parameters(er20, SimConfig(seed=4)).drive
    exponents = np.concatenate([draw_true_parameters(er20, SimConfig(seed=s)).drive
                                .stribeck_exponent_gear for s in range(30)])
    assert exponents.min() >= 0.5 and exponents.max() <= 2.0
    assert np.ptp(exponents) > 1.2  # drawn over the range, not eq. 15's 2
    # the same levels; the viscous friction at the velocity limit split, not changed
    np.testing.assert_array_equal(real.coulomb_gear, ideal.coulomb_gear)
    vmax = er20.velocity_limit
    np.testing.assert_allclose(real.viscous * vmax + real.viscous_power
                               * vmax**real.viscous_exponent, ideal.viscous * vmax, rtol=1e-12)
    q = np.zeros(er20.n)
    for v in (0.002, 0.03, 0.3):
        qd = np.full(er20.n, v)
        ripple = 1.0 + real.ripple * np.sin(q * real.ripple_frequency + real.ripple_phase)
        shape = (real.coulomb_motor + real.coulomb_gear + real.bristle
                 + real.stribeck_motor * np.exp(-np.abs(er20.gear_ratio * v
                                                        / real.stribeck_velocity_motor)
                                                ** real.stribeck_exponent_motor)
                 + real.stribeck_gear * np.exp(-np.abs(v / real.stribeck_velocity_gear)
                                               ** real.stribeck_exponent_gear))
        expected = shape * ripple + real.viscous_power * v**real.viscous_exponent
        np.testing.assert_allclose(_steady_friction(real, er20, q, qd), expected, rtol=1e-6)
    # the degressive viscous part: at a tenth of the limit above the linear law
    v = 0.1 * vmax
    total = real.viscous * v + real.viscous_power * v**real.viscous_exponent
    assert np.all(total > 1.05 * ideal.viscous * v)


def test_realistic_coulomb_friction_grows_with_the_transmitted_torque(er20: Robot) -> None:
    """μ·|τ| with μ of several per cent (the ideal plant: 1 %), on the sliding friction."""
    mus = np.concatenate([draw_true_parameters(er20, SimConfig(seed=s)).drive.load_coefficient
                          for s in range(30)])
    assert mus.min() >= 0.03 and mus.max() <= 0.10 and 0.05 < mus.mean() < 0.08
    ideal = draw_true_parameters(er20, SimConfig(seed=4, plant="ideal")).drive
    assert np.all(ideal.load_coefficient < 0.0125)
    real = draw_true_parameters(er20, SimConfig(seed=4)).drive
    q, qd = np.zeros(er20.n), np.full(er20.n, 0.05)
    tau = 0.3 * er20.max_torque * np.array([1, -1, 1, -1, 1, -1])
    free = DriveTrain(real, er20.gear_ratio)
    loaded = DriveTrain(real, er20.gear_ratio)
    for _ in range(3000):
        free.update(q, qd, np.zeros(er20.n), 1e-3)
        loaded.update(q, qd, tau, 1e-3)
    np.testing.assert_allclose(loaded.friction - free.friction,
                               real.load_coefficient * np.abs(tau), rtol=1e-6)


def _sliding_friction_in_motion(sim: SimRobot, speed: float = 0.05) -> np.ndarray:
    """Mean friction torque (bristles, power-law and linear viscous) while every joint slides
    at ``speed`` [rad/s], the last second of two."""
    q0 = sim.q_command
    dt = sim.config.timestep
    friction = []
    for k in range(2000):
        sim.command(q0 + speed * k * dt, np.full(sim.robot.n, speed))
        sim.step()
        if k >= 1000:
            qd = sim.true_state()[1]
            friction.append(sim.true_friction_torque
                            + sim.mj_model.dof_damping * qd)
    return np.mean(friction, axis=0)


def test_friction_of_a_cold_robot_falls_after_an_hour_of_production(er20: Robot) -> None:
    cold = SimRobot(er20, SimConfig(seed=2), q0=POSE)
    warm = SimRobot(er20, SimConfig(seed=2, warm_up_s=3600.0), q0=POSE)
    assert np.all(cold.temperature_c == 20.0)
    assert np.all(warm.temperature_c > 30.0) and np.all(warm.temperature_c < 60.0)
    assert warm.time == 0.0  # a fast-forward: the robot's time and state did not move
    ratio = _sliding_friction_in_motion(cold) / _sliding_friction_in_motion(warm)
    assert np.all(ratio > 1.15) and np.all(ratio < 2.0), ratio  # tens of per cent


def test_joints_heat_by_their_friction_losses(er20: Robot) -> None:
    """Short of the time constant, T − T_a = R_th·E/τ_th with E the friction energy."""
    sim = SimRobot(er20, SimConfig(seed=3), q0=POSE)
    th = sim.truth.thermal
    assert th is not None
    t = np.arange(10000) * 1e-3
    w = 2 * np.pi * 0.5
    energy = np.zeros(er20.n)
    for k in range(t.size):
        sim.command(POSE + 0.3 * np.sin(w * t[k]), np.full(er20.n, 0.3 * w * np.cos(w * t[k])))
        sim.step()
        qd = sim.true_state()[1]
        energy += np.abs((sim.true_friction_torque + sim.mj_model.dof_damping * qd) * qd) * 1e-3
    expected = th.resistance * energy / th.time_constant_s
    np.testing.assert_allclose(sim.temperature_c - th.ambient_c, expected, rtol=0.02)


def test_warm_up_settles_where_heating_meets_cooling(er20: Robot) -> None:
    sim = SimRobot(er20, SimConfig(seed=5), q0=POSE)
    th = sim.truth.thermal
    assert th is not None
    sim.warm_up(12 * 3600.0)
    loss = production_loss(sim.truth.drive, er20, ThermalConfig(),
                           np.exp(-th.beta_static * (sim.temperature_c - th.ambient_c)),
                           np.exp(-th.beta_viscous * (sim.temperature_c - th.ambient_c)))
    np.testing.assert_allclose(sim.temperature_c, th.ambient_c + th.resistance * loss, rtol=1e-6)
    # below the rise at cold friction (20-35 K), because the warm joints lose less
    assert np.all(sim.temperature_c - th.ambient_c < 35.0)
    sim.set_temperature(np.full(er20.n, th.ambient_c))
    _sliding_friction_in_motion(sim, 0.0)  # held at rest: presliding only, no heating
    assert np.all(np.abs(sim.temperature_c - th.ambient_c) < 1e-4)


def test_the_ideal_plant_has_no_temperature(er20: Robot) -> None:
    with pytest.raises(SimulationError, match="ideal plant has no thermal model"):
        SimConfig(plant="ideal", warm_up_s=60.0)
    with pytest.raises(SimulationError, match="ideal plant has no thermal model"):
        SimRobot(er20, SimConfig(plant="ideal")).warm_up(60.0)
    with pytest.raises(SimulationError, match="warm_up_s"):
        SimRobot(er20, SimConfig()).warm_up(-1.0)


def test_realistic_drives_have_their_own_torque_constant_and_cogging(er20: Robot) -> None:
    scales = np.concatenate([draw_true_parameters(er20, SimConfig(seed=s)).drive
                             .torque_constant_scale for s in range(30)])
    assert np.all(np.abs(scales - 1.0) <= 0.04) and np.ptp(scales) > 0.05
    ideal = SimRobot(er20, SimConfig(seed=2, plant="ideal"), q0=POSE)
    np.testing.assert_array_equal(ideal.true_torque_per_amp, er20.torque_per_amp)
    assert np.all(ideal.true_cogging_torque(POSE) == 0.0)
    sim = SimRobot(er20, SimConfig(seed=2), q0=POSE)
    drive = sim.truth.drive
    # cogging: a torque periodic in the motor angle, k periods per motor revolution
    period = 2.0 * np.pi / drive.cogging_frequency
    cog = sim.true_cogging_torque(POSE)
    np.testing.assert_allclose(sim.true_cogging_torque(POSE + period), cog,
                               atol=1e-9 * er20.max_torque.max())
    np.testing.assert_allclose(sim.true_cogging_torque(POSE + 0.5 * period), -cog,
                               atol=1e-9 * er20.max_torque.max())
    assert np.all(drive.cogging >= 0.001 * er20.max_torque)
    assert np.all(drive.cogging <= 0.004 * er20.max_torque)
    # held, the currents are the true drives' (within the noise), not the drive file's
    h = check_hold(er20, SimConfig(seed=2), POSE)
    assert np.all(h.error_in_sigma < 0.5)
    # ... which a 4 s average resolves: on the loaded joints 2 and 3, per cent off the file's
    nominal = er20.torque_to_current(sim.true_gravity_torque(POSE))
    assert np.max(np.abs(h.current_mean[1:3] / nominal[1:3] - 1.0)) > 0.01


def test_delay_line_interpolates_between_samples() -> None:
    line = DelayLine(2, 3.0)
    line.push(np.array([5.0, -5.0]))  # the first sample fills the past
    np.testing.assert_array_equal(line.delayed(2.5), [5.0, -5.0])
    for k in range(1, 8):
        line.push(np.array([float(k), -2.0 * k]))
    np.testing.assert_allclose(line.delayed(0.0), [7.0, -14.0])
    np.testing.assert_allclose(line.delayed(1.25), [5.75, -11.5])
    np.testing.assert_allclose(line.delayed(3.0), [4.0, -8.0])


def _quiet(plant: str = "realistic", run: int = 0) -> SimConfig:
    """Noise-free current sensing (a 32-bit ADC), so that timing shows exactly."""
    return SimConfig(seed=6, run=run, plant=plant,
                     sensors=SensorConfig(current_noise=0.0, current_drift=0.0,
                                          current_bias=0.0, adc_bits=32))


def test_realistic_currents_lag_the_positions(er20: Robot) -> None:
    lags = [draw_true_parameters(er20, SimConfig(seed=s)).current_lag_s for s in range(40)]
    assert min(lags) >= 0.0 and max(lags) <= 2e-3 and np.ptp(lags) > 1.5e-3
    t = np.arange(400) * 1e-3
    q_cmd = POSE + 0.1 * np.sin(2 * np.pi * 2.0 * t)[:, None] * np.ones(er20.n)
    ideal = run_trajectory(SimRobot(er20, _quiet("ideal"), q0=POSE), q_cmd)
    np.testing.assert_allclose(ideal.current, ideal.truth.current, rtol=0, atol=1e-6)
    sim = SimRobot(er20, _quiet(run=3), q0=POSE)
    lag = sim.truth.current_lag_s / 1e-3
    assert lag == draw_true_parameters(er20, _quiet(run=0)).current_lag_s / 1e-3  # per robot
    log = run_trajectory(sim, q_cmd)
    m, f = int(lag), lag - int(lag)
    late = (1 - f) * log.truth.current[3 - m:-m or None] + f * log.truth.current[2 - m:-m - 1]
    np.testing.assert_allclose(log.current[3:], late[:log.current.shape[0] - 3], atol=1e-6)


@pytest.mark.parametrize(("plant", "jitter"), [("ideal", 0.0), ("realistic", 0.0),
                                               ("realistic", 6e-4)])
def test_the_sampled_current_is_the_truth_the_sensor_measured(er20: Robot, plant: str,
                                                             jitter: float) -> None:
    """``true_sampled_current`` is the current at the instant the sensor sampled it: with a
    noise-free sensor it is the measured current, and with a lag it trails the step's own."""
    sim = SimRobot(er20, _quiet(plant), q0=POSE)
    driver = SimDriver(sim, sample_jitter_s=jitter)
    np.testing.assert_array_equal(sim.true_sampled_current, sim.true_current)  # at rest
    apart = []
    for k in range(400):
        sim.command(POSE + 0.1 * np.sin(2 * np.pi * 2.0 * k * 1e-3) * np.ones(er20.n))
        driver.step()
        np.testing.assert_allclose(sim.read().current, sim.true_sampled_current, rtol=0,
                                   atol=1e-6)
        apart.append(np.abs(sim.true_sampled_current - sim.true_current).max())
    late = sim.truth.current_lag_s > 0 or jitter > 0
    assert (max(apart) > 1e-3) == late, (plant, jitter, max(apart))


def test_a_driver_can_ask_for_sample_jitter(er20: Robot) -> None:
    """Each sample is taken up to the jitter before its reported instant: in motion the reported
    positions trail the unjittered ones by e·q̇, e uniform in [0, jitter]."""
    speed, jitter = 0.2, 6e-4
    plain, jittered = SimRobot(er20, _quiet(), q0=POSE), SimRobot(er20, _quiet(), q0=POSE)
    driver = SimDriver(jittered, sample_jitter_s=jitter)
    early = []
    for k in range(600):
        for sim in (plain, jittered):
            sim.command(POSE + speed * k * 1e-3, np.full(er20.n, speed))
        qd = plain.true_state()[1]
        plain.step()
        driver.step()
        if k >= 300:  # the joints move at about 0.2 rad/s: e = trail / q̇ per joint
            early.append((plain.read().q - jittered.read().q) / qd)
    e = np.array(early)
    lsb = er20.encoder_resolution / 0.15  # one count of the encoder at >= 0.15 rad/s
    assert np.all(e >= -lsb) and np.all(e <= jitter + lsb)
    assert np.mean(e) == pytest.approx(0.5 * jitter, rel=0.1)
    assert np.std(e) == pytest.approx(jitter / np.sqrt(12.0), rel=0.15)  # uniform
    with pytest.raises(SimulationError, match="sample_jitter_s"):
        SimDriver(SimRobot(er20, _quiet(), q0=POSE), sample_jitter_s=2e-3)


@pytest.mark.parametrize(("make", "field"), [
    (lambda: ThermalConfig(time_constant_min=(0.0, 30.0)), "thermal.time_constant_min"),
    (lambda: ThermalConfig(static_ratio=(0.8, 1.2)), "thermal.static_ratio"),
    (lambda: DressPackConfig(offset=(0.2, 0.1)), "dress_pack.offset"),
    (lambda: DriveMismatchConfig(cogging=(-0.01, 0.0)), "drive_mismatch.cogging"),
    (lambda: DriveMismatchConfig(stribeck_exponent=(0.0, 2.0)), "drive_mismatch.stribeck"),
    (lambda: LinkMismatchConfig(outlier_deviation=(0.5, 1.5)), "links.outlier_deviation"),
    (lambda: SensorConfig(current_lag_s=(0.0, 0.5)), "sensors.current_lag_s"),
])
def test_bad_realistic_settings_name_their_field(make: object, field: str) -> None:
    with pytest.raises(SimulationError) as e:
        make()  # type: ignore[operator]
    assert e.value.field is not None and e.value.field.startswith(field)


def test_true_total_friction_closes_mujocos_equation_of_motion(er20: Robot) -> None:
    """``true_total_friction`` is all the friction the step applied: with the motors' torque,
    cogging and the hand it closes the step's equation of motion, M·q̈ + bias =
    τ_motor + cogging − friction + τ_ext (the joints' linear damping is MuJoCo's passive
    force, −D·q̇, which the total friction holds; no constraint acts on the arm)."""
    q0 = np.array([0.2, -0.4, 0.3, 0.1, 0.5, -0.2])
    sim = SimRobot(er20, SimConfig(seed=3), q0=q0,
                   operator=ConstantWrench((20.0, -10.0, 15.0, 0.0, 0.0, 0.0), t_start=0.05))
    m, d = sim.mj_model, sim.mj_data
    worst, damping, scale = 0.0, 0.0, 0.0
    for k in range(300):
        sim.command(q0 + 0.05 * np.sin(0.02 * k), np.full(6, 1.0))
        q_before = d.qpos.copy()
        sim.step()
        lhs = np.zeros(er20.n)
        mujoco.mj_mulM(m, d, lhs, d.qacc)
        lhs += d.qfrc_bias
        rhs = (sim.true_current * sim.true_torque_per_amp + sim.true_cogging_torque(q_before)
               - sim.true_total_friction + sim.true_external_torque)
        worst = max(worst, float(np.abs(lhs - rhs).max()))
        damping = max(damping, float(np.abs(d.qfrc_passive).max()))
        scale = max(scale, float(np.abs(sim.true_total_friction).max()))
    assert scale > 1.0 and damping > 0.1    # friction and damping are there to be checked
    assert worst < 1e-9 * scale
