"""Reference side of ``benchmarks/replay_equivalence.py``: run the guiding sessions of the
equivalence check with the code of a reference commit and save what they computed.

Not run by hand: ``replay_equivalence.py --reference REV`` checks the commit out into a temporary
git worktree and runs this file there (``PYTHONPATH=<worktree>/src``), so that it imports the
reference commit's ``leadthrough``. It is written against the API of the commits before the
real-time core was restructured (issue 23: ``leadthrough.session.sim_session``,
``leadthrough.drivers.sim_driver``); nothing of today's package is imported.

    python benchmarks/equivalence_reference.py OUT_DIR

writes into ``OUT_DIR``: ``params.toml`` (calibrated on the simulated er20, seed 1), and per case
``<case>.npz``: the feedback trace of every driver read (``fb_*``), the commands and states the
loop produced from it (``q_cmd``, ``qd_cmd``, ``twist``, ``tcp``, ``state``, ``fault``,
``wrench``, ``tau_ext``), the transitions (``events``), and the same arrays from a replay of the
trace through the reference loop (``replay_*``: the reference's own determinism), and the
compute time of each controller cycle in the simulated session (``cycle_us`` [µs]).
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from leadthrough.drivers.sim_driver import Fault, FaultKind
from leadthrough.session.sim_session import (
    SimSessionConfig,
    guide_start_pose,
    light_guiding,
    replay_session,
    run_sim_session,
)

from equivalence_cases import CASES
from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import SafetyConfig
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import identify_with_sweep
from leadthrough.identification.params_file import ParamsFile, load_params, save_params
from leadthrough.robot import load_robot
from leadthrough.sim.calibration_set import record_calibration_set, record_friction_sweep


def session_config(robot: object, case: dict[str, object]) -> SimSessionConfig:
    """The reference API's SimSessionConfig of a case."""
    guiding = GuidingConfig()
    if "mass" in case:
        guiding = light_guiding(float(case["mass"]))  # type: ignore[arg-type]
    if "frame" in case:
        guiding = replace(guiding, frame=str(case["frame"]))
    if "friction_mode" in case:
        guiding = replace(guiding, friction_mode=str(case["friction_mode"]))
    if case.get("axes") == "translation":
        guiding = replace(guiding, axes_enabled=(True,) * 3 + (False,) * 3)
    if "rezero_s" in case:
        guiding = replace(guiding, rezero_s=float(case["rezero_s"]))  # type: ignore[arg-type]
    if "box_dx" in case:
        import pinocchio as pin
        q0 = guide_start_pose(robot)  # type: ignore[arg-type]
        data = robot.model.createData()  # type: ignore[attr-defined]
        pin.framesForwardKinematics(robot.model, data, q0)  # type: ignore[attr-defined]
        x0 = float(data.oMf[robot.tcp_frame_id].translation[0])  # type: ignore[attr-defined]
        inf = float("inf")
        guiding = replace(guiding, safety=SafetyConfig(
            workspace_min=(-inf, -inf, -inf),
            workspace_max=(x0 + float(case["box_dx"]), inf, inf)))  # type: ignore[arg-type]
    estimator = SimSessionConfig().estimator
    if "method" in case:
        estimator = replace(estimator, method=str(case["method"]))
    faults: tuple[Fault, ...] = ()
    if "fault" in case:
        kind, t0, t1, joint, offset = case["fault"]  # type: ignore[misc]
        faults = (Fault(FaultKind(kind), t_start=t0, t_end=t1, joint=joint, offset=offset),)
    return SimSessionConfig(
        operator=str(case["operator"]), controller=str(case.get("controller",
                                                                "virtual-friction")),
        operator_seed=case.get("operator_seed"),  # type: ignore[arg-type]
        estimator=estimator,
        guiding=guiding, faults=faults)


def _arrays(prefix: str, log: object) -> dict[str, np.ndarray]:
    return {f"{prefix}q_cmd": log.q_cmd, f"{prefix}qd_cmd": log.qd_cmd,  # type: ignore[attr-defined]
            f"{prefix}twist": log.twist_cmd_base,  # type: ignore[attr-defined]
            f"{prefix}tcp": log.tcp_cmd_base,  # type: ignore[attr-defined]
            f"{prefix}state": log.state, f"{prefix}fault": log.fault,  # type: ignore[attr-defined]
            f"{prefix}wrench": log.wrench_base,  # type: ignore[attr-defined]
            f"{prefix}tau_ext": log.tau_ext}  # type: ignore[attr-defined]


def main() -> None:
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    only = set(sys.argv[2:])
    robot = load_robot("er20")
    params_path = out / "params.toml"
    if not params_path.exists():
        cal = record_calibration_set(robot, seed=1, duration=30.0,
                                     excitation_config=ExcitationConfig(starts=2))
        sweep = record_friction_sweep(robot, seed=1, run=2, q_start=guide_start_pose(robot))
        sc = identify_with_sweep(cal.identification.measured, sweep.measured, robot)
        r = sc.result
        save_params(params_path, robot, r.method, r.params, r.stats, sim_seed=1)
    pf: ParamsFile = load_params(params_path, robot)
    for name, case in CASES.items():
        if only and name not in only:
            continue
        cfg = session_config(robot, case)
        s = run_sim_session(robot, pf, cfg, record_feedback=True)
        fb = s.feedback
        assert fb is not None
        again = replay_session(robot, pf, cfg, fb)
        events = [[e.t, e.kind, e.label, e.cause] for e in s.result.log.events
                  if e.kind == "transition"]
        np.savez_compressed(
            out / f"{name}.npz", fb_dt=fb.dt, fb_t=fb.t, fb_q=fb.q, fb_current=fb.current,
            fb_sequence=fb.sequence, fb_fresh=fb.fresh, events=json.dumps(events),
            cycle_us=s.result.cycle_us,
            **_arrays("", s.result.log), **_arrays("replay_", again.log))
        print(f"{name}: {fb.reads} reads, faults {s.summary.faults or 'none'}", flush=True)


if __name__ == "__main__":
    main()
