"""Demo steps after calibration: the payload test (Table III) and the guiding sessions (Fig. 4,
Fig. 5), on the simulated robot with calibrated parameters."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.data.preprocess import ProcessedData, preprocess
from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.estimation.drive_gains import DriveGains
from leadthrough.estimation.payload import estimate_payload
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot.description import Robot
from leadthrough.session.loop_config import LoopConfig
from leadthrough.session.plots import plot_force_velocity, plot_path_3d
from leadthrough.session_format import SessionLog, save_session
from leadthrough.sim.calibration_set import CalibrationSet, record_excitation
from leadthrough.sim.mujoco_model import Payload
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.robot import SimConfig
from leadthrough.sim.session import (
    SimSession,
    SimSessionConfig,
    light_guiding,
    run_sim_session,
)

__all__ = ["PAPER_WEIGHTS_N", "PAPER_WORST", "PAYLOAD_RUN_S", "UNLOADED_RUN",
           "GuidingDemo", "PayloadRow", "payload_run", "payload_table", "run_guiding_demo"]

Array = NDArray[np.float64]

#: The paper's Table III payload weights [N].
PAPER_WEIGHTS_N = (71.54, 101.92, 120.54, 154.84)
#: The paper's worst Table III error: 7.84 N, 5.6 %.
PAPER_WORST = "up to 7.84 N, 5.6 %"
#: Length of each Table III payload run [s]. The estimate's noise comes from the currents' slow
#: error in motion (the simulator's sensor: 0.75 % of max current, 50 ms correlation); over six
#: 60 s runs of the same payload its spread was 0.4 N (1σ), 0.55 % of the lightest payload, so
#: one 60 s run misses 1 % about one time in four. Four minutes halve the spread.
PAYLOAD_RUN_S = 240.0
#: The simulated run's noise number (``SimConfig.run``) of the held-out trajectory without a
#: payload.
UNLOADED_RUN = 9


@dataclass(frozen=True)
class PayloadRow:
    """One row of Table III.

    Attributes:
        true_n: Payload weight [N].
        estimated_n: Estimated weight [N].
        error_pct: Relative error [%].
    """

    true_n: float
    estimated_n: float
    error_pct: float


def payload_run(robot: Robot, cal: CalibrationSet, seed: int, seconds: float,
                plant: PlantPreset | str, payload: Payload | None, run: int) -> ProcessedData:
    """One run of the held-out trajectory on simulated robot ``seed`` (``run`` numbers the
    run's noise: :data:`UNLOADED_RUN`, Table III's from 10 on)."""
    config = SimConfig(seed=seed, run=run, plant=plant_preset(plant))
    return preprocess(record_excitation(robot, cal.held_out_excitation, seconds, config,
                                        payload=payload).measured, robot)


def payload_table(robot: Robot, cal: CalibrationSet,
                  params: Mapping[str, DriveModelParameters], seed: int,
                  seconds: float, plant: PlantPreset | str = PlantPreset.REALISTIC,
                  reference: bool = False, unloaded: ProcessedData | None = None,
                  drive_gains: Mapping[str, DriveGains] | None = None
                  ) -> dict[str, list[PayloadRow]]:
    """Table III: each payload on its own run of the held-out trajectory, weight from motion.

    Each payload is recorded once and estimated with every parameter set.

    Args:
        robot: The robot.
        cal: The calibration set (its held-out trajectory is reused with the payloads).
        params: Label (e.g. the method) → parameters identified on the unloaded robot.
        seed: Simulated robot instance.
        seconds: Length of each payload run [s].
        plant: Simulated plant (the one ``cal`` was recorded on).
        reference: Also estimate every payload against a run of the trajectory without a
            payload (``estimate_payload``'s ``reference``), under the label
            ``"<label> vs unloaded"``.
        unloaded: That run (:func:`payload_run` with :data:`UNLOADED_RUN`); None: recorded
            here where needed.
        drive_gains: Label → drive gains measured with a known mass; each payload is then
            also estimated against the unloaded run through them, under
            ``"<label> vs unloaded, gains"``.

    Returns:
        Label → one row per payload of :data:`PAPER_WEIGHTS_N`.
    """
    g = float(np.linalg.norm(robot.model.gravity.linear))
    gains = dict(drive_gains or {})
    if (reference or gains) and unloaded is None:
        unloaded = payload_run(robot, cal, seed, seconds, plant, None, UNLOADED_RUN)
    labels = [*params, *(f"{label} vs unloaded" for label in params if reference),
              *(f"{label} vs unloaded, gains" for label in gains)]
    rows: dict[str, list[PayloadRow]] = {label: [] for label in labels}
    for k, weight in enumerate(PAPER_WEIGHTS_N):
        data = payload_run(robot, cal, seed, seconds, plant, Payload(weight / g, (0.0, 0.0, 0.1)),
                           10 + k)
        for label, p in params.items():
            estimates = {label: estimate_payload(data, robot, p, "motion")}
            if reference:
                estimates[f"{label} vs unloaded"] = estimate_payload(data, robot, p, "motion",
                                                                     reference=unloaded)
            if label in gains:
                estimates[f"{label} vs unloaded, gains"] = estimate_payload(
                    data, robot, p, "motion", reference=unloaded, drive_gains=gains[label])
            for key, est in estimates.items():
                rows[key].append(PayloadRow(true_n=weight, estimated_n=est.weight_n,
                                            error_pct=100.0 * (est.weight_n - weight) / weight))
    return rows


@dataclass(frozen=True)
class GuidingDemo:
    """The demo's guiding sessions.

    Attributes:
        sessions: Name (``"<operator>/<controller>"``) → session.
        fig4: Fig. 4 PNG.
        fig5: Fig. 5 PNG.
    """

    sessions: dict[str, SimSession]
    fig4: Path
    fig5: Path


def run_guiding_demo(robot: Robot, params: ParamsFile, seed: int, out: Path,
                     say: Callable[[str], None]) -> GuidingDemo:
    """Rest and push +x with both controllers, diagonal and seam with virtual friction (push +x
    and the seam with the translational virtual mass :data:`PUSH_MASS_KG`, the rest with Table
    IV's: a 1000 kg tool swings about a hand-held point for seconds, too slow to place a seam's
    end points).

    Writes each session to ``out/session_<operator>_<controller>.parquet`` and Fig. 4 / Fig. 5.
    """
    sessions: dict[str, SimSession] = {}
    plan = [(op, ctl) for op in ("rest", "push-x") for ctl in ("virtual-friction", "velocity")]
    plan += [("diagonal", "virtual-friction"), ("seam", "virtual-friction")]
    for op, ctl in plan:
        guiding = light_guiding() if op in ("push-x", "seam") else GuidingConfig()
        loop = LoopConfig(guiding=replace(guiding, controller=ctl))
        s = run_sim_session(robot, params, SimSessionConfig(operator=op, seed=seed, loop=loop))
        sessions[f"{op}/{ctl}"] = s
        save_session(s.log, out / f"session_{op}_{ctl}.parquet")
        sm = s.summary
        drift = "" if sm.rest_drift_m is None else f", rest drift {1000 * sm.rest_drift_m:.2f} mm"
        if sm.force_rms_in_motion_n is not None:
            drift += f", force RMS in motion {sm.force_rms_in_motion_n:.1f} N"
        if sm.phantom_force_n is not None:
            drift += f", phantom {sm.phantom_force_n:.1f} N"
        say(f"      {op:<8} {ctl:<16} max {sm.max_linear_speed:.3f} m/s{drift}, "
            f"faults {', '.join(sm.faults) or 'none'}")
    logs: dict[str, SessionLog] = {k: v.log for k, v in sessions.items()}
    fig4 = plot_force_velocity({"virtual friction": logs["push-x/virtual-friction"],
                                "velocity [14]": logs["push-x/velocity"]}, out / "fig4.png")
    seam = sessions["seam/virtual-friction"]
    targets = {}
    if seam.p1_base is not None and seam.p2_base is not None:
        targets = {"P1": seam.p1_base, "P2": seam.p2_base}
    fig5 = plot_path_3d({"diagonal": logs["diagonal/virtual-friction"],
                         "seam": logs["seam/virtual-friction"]}, out / "fig5.png",
                        targets=targets)
    return GuidingDemo(sessions=sessions, fig4=fig4, fig5=fig5)
