"""The demo pipeline on the built-in simulated robot (``leadthrough demo``).

Steps, each printed as it runs:

1. design the excitation trajectory (after checking the dynamic model and the simulator);
2. record it (and a held-out trajectory) at 1 kHz;
3. calibrate with all methods: Table II and Fig. 3;
4. the payload test: Table III;
5. guiding sessions with both controllers: Fig. 4, Fig. 5;
6. a welding-seam session taught and exported: Fig. 6, ``path.json`` / ``path.csv``.

Everything lands in one report folder with ``report.html`` (self-contained), ``report.md``,
``summary.json``, the params file, the recordings, the sessions and the exported path.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from leadthrough.data.io import save_recording
from leadthrough.data.preprocess import preprocess
from leadthrough.demo.guiding_steps import (
    PAYLOAD_RUN_S,
    GuidingDemo,
    PayloadRow,
    payload_table,
    run_guiding_demo,
)
from leadthrough.errors import LeadthroughError
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.excitation.friction_sweep import FrictionSweepConfig
from leadthrough.identification.api import METHODS, IdentifyConfig
from leadthrough.identification.calibration import calibrate
from leadthrough.identification.comparison import Table2, ratio_summary, table2, table2_markdown
from leadthrough.identification.friction_sweep import SweepFit
from leadthrough.identification.params_file import ParamsFile, save_params
from leadthrough.identification.plots import plot_torque_fit
from leadthrough.identification.presliding import PreslidingFit
from leadthrough.identification.proposed import ProposedConfig
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import (
    CalibrationSet,
    SimRecording,
    compare_on_calibration_set,
    record_calibration_set,
    record_friction_sweep,
    record_presliding_test,
)
from leadthrough.sim.checks import check_hold, check_push, check_regressor
from leadthrough.sim.robot import SimConfig
from leadthrough.teach import tcp_path, teach_session, write_program_csv, write_program_json
from leadthrough.teach.plots import plot_taught_path
from leadthrough.teach.program import TaughtProgram
from leadthrough.teach.programs import LANGUAGES, ProgramOptions, write_robot_program

__all__ = ["DemoResult", "run_demo"]

DEMO_POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)
#: Method whose parameters drive estimation and guiding (lowest held-out J on er20).
GUIDING_METHOD = "consistent"


@dataclass
class DemoResult:
    """Everything the demo measured (the report and summary are built from it).

    Attributes:
        robot: Robot name.
        seed: Simulated robot instance.
        quick: Shorter recordings and searches.
        checks: Model and simulator checks (JSON-ready).
        table2: Table II cells.
        table2_ratios: J ratios per data set.
        runtimes_s: Identification runtime per method [s].
        condition_number: Excitation condition number.
        payload: Table III rows per method.
        guiding: The guiding sessions.
        program: The taught seam, or None if the teach-in failed (``teach_error`` says why).
        teach_error: Why there is no program.
        seam_target_errors_mm: |P1 − target P1|, |P2 − target P2| [mm].
        sweep_rms: RMS of the eq. 15 fit to the friction sweep per joint [N·m].
        files: Output files by role.
        total_s: Wall time [s].
    """

    robot: str
    seed: int
    quick: bool
    checks: dict[str, Any] = field(default_factory=dict)
    table2: Table2 = field(default_factory=lambda: Table2([], []))
    table2_ratios: dict[str, dict[str, float]] = field(default_factory=dict)
    runtimes_s: dict[str, float] = field(default_factory=dict)
    condition_number: float = 0.0
    payload: dict[str, list[PayloadRow]] = field(default_factory=dict)
    guiding: GuidingDemo | None = None
    program: TaughtProgram | None = None
    teach_error: str = ""
    seam_target_errors_mm: tuple[float, float] | None = None
    sweep_rms: list[float] = field(default_factory=list)
    files: dict[str, Path] = field(default_factory=dict)
    total_s: float = 0.0


def run_demo(robot: Robot, seed: int, out: Path, quick: bool,
             say: Callable[[str], None]) -> DemoResult:
    """Run all steps, writing into ``out`` (which must exist)."""
    t_start = time.perf_counter()
    res = DemoResult(robot=robot.name, seed=seed, quick=quick)
    say("[1/6] excitation design (after checking the model and the simulator) ...")
    _checks(res, robot, seed, quick, say)
    say("[2/6] recordings at 1 kHz (identification and held-out trajectories) ...")
    cal, sweep, pre = _recordings(res, robot, seed, quick, out, say)
    say("[3/6] calibration: " + ", ".join(METHODS) + " ...")
    params, guiding_params = _calibration(res, robot, seed, quick, out, cal, sweep, pre, say)
    say("[4/6] payload test (Table III): weight from motion with the unloaded model ...")
    res.payload = payload_table(robot, cal, {m: pf.params for m, pf in params.items()}, seed,
                                20.0 if quick else PAYLOAD_RUN_S)
    for k, row in enumerate(res.payload[GUIDING_METHOD]):
        cells = ", ".join(f"{m} {rows[k].estimated_n:7.2f} N ({rows[k].error_pct:+.2f} %)"
                          for m, rows in res.payload.items())
        say(f"      {row.true_n:7.2f} N: {cells}")
    say(f"[5/6] guiding sessions ({GUIDING_METHOD} parameters with the friction sweep) ...")
    res.guiding = run_guiding_demo(robot, guiding_params, seed, out, say)
    res.files["fig4"] = res.guiding.fig4
    res.files["fig5"] = res.guiding.fig5
    say("[6/6] teach-in of the welding-seam session ...")
    _teach(res, robot, out, say)
    res.total_s = time.perf_counter() - t_start
    return res


def _checks(res: DemoResult, robot: Robot, seed: int, quick: bool,
            say: Callable[[str], None]) -> None:
    """Step 1's checks: the regressor against Pinocchio and MuJoCo, the simulator's currents
    against the drive model at rest and under a push."""
    q0 = np.clip(np.resize(np.array(DEMO_POSE), robot.n), robot.lower_limits, robot.upper_limits)
    reg = check_regressor(robot, samples=200 if quick else 1000, seed=seed)
    config = SimConfig(seed=seed)
    hold = check_hold(robot, config, q0)
    push = check_push(robot, config, q0, np.array([50.0, 0, 0, 0, 0, 0]))
    say(f"      base parameters {reg.base_parameters} of {10 * robot.n}; K·φ vs pin.rnea "
        f"{reg.rel_error_rnea:.1e}, vs MuJoCo {reg.rel_error_mujoco:.1e}; hold "
        f"{1e3 * hold.max_joint_error.max():.1e} mrad, currents vs gravity "
        f"{hold.error_in_sigma.max():.2f} σ, 50 N push {push.error_in_sigma.max():.2f} σ")
    res.checks = {
        "base_parameters": reg.base_parameters,
        "regressor_rel_error": {"rnea": reg.rel_error_rnea, "mujoco": reg.rel_error_mujoco,
                                "base": reg.rel_error_base},
        "hold": {"max_joint_error_rad": float(hold.max_joint_error.max()),
                 "current_error_sigma": hold.error_in_sigma.tolist()},
        "push_50N_x": {"current_error_sigma": push.error_in_sigma.tolist()},
    }


def _recordings(res: DemoResult, robot: Robot, seed: int, quick: bool, out: Path,
                say: Callable[[str], None]
                ) -> tuple[CalibrationSet, SimRecording, SimRecording]:
    """Step 2: the excitation, its held-out twin, the friction sweep and the presliding test,
    recorded."""
    duration = 20.0 if quick else 60.0
    exc_cfg = ExcitationConfig(starts=1 if quick else 2, seed=0,
                               max_iterations=60 if quick else 100)
    cal = record_calibration_set(robot, seed=seed, duration=duration, excitation_config=exc_cfg,
                                 progress=lambda s: say("      " + s))
    res.condition_number = cal.excitation.condition_number
    res.files["identification recording"] = save_recording(cal.identification.measured,
                                                           out / "identification.parquet")
    res.files["held-out recording"] = save_recording(cal.held_out.measured,
                                                     out / "held_out.parquet")
    sweep = record_friction_sweep(robot, seed=seed, run=2, q_start=guide_start_pose(robot))
    res.files["friction-sweep recording"] = save_recording(sweep.measured,
                                                           out / "friction_sweep.parquet")
    say(f"      friction sweep recorded: {sweep.measured.duration:.0f} s, "
        f"{len(FrictionSweepConfig().speeds)} speeds out and back")
    pre = record_presliding_test(robot, seed=seed, run=3, q_start=guide_start_pose(robot))
    res.files["presliding-test recording"] = save_recording(pre.measured,
                                                            out / "presliding_test.parquet")
    say(f"      presliding test recorded: {pre.measured.duration:.0f} s")
    return cal, sweep, pre


def _calibration(res: DemoResult, robot: Robot, seed: int, quick: bool, out: Path,
                 cal: CalibrationSet, sweep: SimRecording, pre: SimRecording,
                 say: Callable[[str], None]) -> tuple[dict[str, ParamsFile], ParamsFile]:
    """Step 3: Table II with all methods, Fig. 3, and the guiding parameters (with the
    sweep, z₀ from the presliding test). Returns the params of Table III's methods and the
    guiding params."""
    # Table II compares the methods on eq. 21 as the paper writes it: no load-dependent friction
    # (``proposed`` has none), so every method fits the same model
    cfg = IdentifyConfig(proposed=ProposedConfig(generations=60 if quick else 150,
                                                 polish_iterations=150 if quick else 300),
                         load_friction=False)
    comparison = compare_on_calibration_set(robot, cal, METHODS, cfg,
                                            progress=lambda s: say("      " + s))
    comp = comparison.comparison
    res.table2 = table2(comp, comparison.floors)
    res.table2_ratios = ratio_summary(comp, comparison.floors)
    res.runtimes_s = {m: comp.results[m].runtime_s for m in METHODS}
    say("\nTable II (mean [N·m], std/max torque [%], J [N·m]):\n"
        + table2_markdown(res.table2) + "\n")
    params: dict[str, ParamsFile] = {}
    for m in ("proposed", GUIDING_METHOD):
        r = comp.results[m]
        path = save_params(out / f"params_{m}.toml", robot, m, r.params, r.stats, seed)
        res.files[f"params ({m})"] = path
        params[m] = ParamsFile.from_result(r, path, seed)
    guided = calibrate(cal.identification.measured, robot, GUIDING_METHOD, cfg,
                       friction_sweep=sweep.measured, presliding_test=pre.measured)
    # both given, both fitted
    sweep_fit, fit = cast(SweepFit, guided.sweep), cast(PreslidingFit, guided.presliding)
    path = guided.save(out / "params_guiding.toml", robot, seed)
    res.files["params (guiding: consistent + friction sweep)"] = path
    res.sweep_rms = sweep_fit.rms.tolist()
    say("      guiding parameters: consistent with the friction sweep (fit RMS "
        + ", ".join(f"{v:.2f}" for v in sweep_fit.rms) + " N·m), z0 "
        + ", ".join(f"{1e4 * v:.2f}" for v in fit.presliding) + " e-4 rad, relaxation "
        + ", ".join(f"{v:.3f}" for v in fit.relaxation) + " 1/s")
    held = preprocess(cal.held_out.measured, robot, cfg.preprocess)
    res.files["fig3"] = plot_torque_fit(
        out / "fig3.png", robot, held, {m: comp.results[m].params for m in METHODS},
        title=f"{robot.name} (simulated), held-out trajectory")
    return params, guided.params_file(path, seed)


def _teach(res: DemoResult, robot: Robot, out: Path, say: Callable[[str], None]) -> None:
    if res.guiding is None:
        return
    seam = res.guiding.sessions["seam/virtual-friction"]
    log = seam.log
    try:
        program = teach_session(log, robot, tolerance_mm=1.0, speed_m_s=0.1)
    except LeadthroughError as e:  # a session the teach-in rejects is a result, not a crash
        res.teach_error = str(e)
        say(f"      no program: {e}")
        return
    res.program = program
    res.files["path (JSON)"] = write_program_json(program, out / "path.json")
    res.files["path (CSV)"] = write_program_csv(program, out / "path.csv")
    _robot_programs(res, robot, program, out, say)
    targets = {}
    line = program.welding_line
    if seam.p1_base is not None and seam.p2_base is not None:
        targets = {"P1": seam.p1_base, "P2": seam.p2_base}
        if line is not None:
            res.seam_target_errors_mm = (
                1e3 * float(np.linalg.norm(line.p1_base - seam.p1_base)),
                1e3 * float(np.linalg.norm(line.p2_base - seam.p2_base)))
    full = tcp_path(log, robot, float(log.time[0]), float(log.time[-1]))
    res.files["fig6"] = plot_taught_path(full, program, out / "fig6.png", targets)
    if line is not None:
        errs = "" if res.seam_target_errors_mm is None else (
            f"; endpoints vs operator targets {res.seam_target_errors_mm[0]:.1f} / "
            f"{res.seam_target_errors_mm[1]:.1f} mm")
        say(f"      welding line {1e3 * line.length_m:.1f} mm, max deviation "
            f"{line.max_deviation_mm:.2f} mm, {len(program.waypoints)} waypoints{errs}")


def _robot_programs(res: DemoResult, robot: Robot, program: TaughtProgram, out: Path,
                    say: Callable[[str], None]) -> None:
    """The taught seam as URScript, KUKA KRL, FANUC TP and ABB RAPID (each read back and
    solved back to the taught joints within 0.01° before it is written): ``seam.script``,
    ``seam.src`` + ``seam.dat``, ``seam.ls``, ``seam.mod`` (KRL and TP need the file to carry
    the program's name)."""
    options = ProgramOptions(name="seam", speed_m_s=0.1)
    for language in LANGUAGES:
        try:
            paths = write_robot_program(program, robot, language, out / "seam",
                                        options, source="seam session")
        except LeadthroughError as e:  # reported, like a failed teach-in
            say(f"      no {language} program: {e}")
            continue
        for path in paths:
            res.files[f"program ({language}{path.suffix})"] = path
    say("      robot programs: " + ", ".join(
        path.name for key, path in res.files.items() if key.startswith("program (")))
