"""Same commands as a reference commit: replay recorded guiding sessions through today's loop.

    python benchmarks/replay_equivalence.py --reference REV [--work DIR] [CASE ...]

1. The reference commit's source is exported (``git archive REV src``) into ``DIR/ref`` and
   ``benchmarks/equivalence_reference.py`` runs there: it calibrates the simulated er20 (seed 1,
   30 s excitation and a friction sweep), runs the cases below with the reference code, and
   saves each session's feedback (every driver read) and what the loop computed from it.
2. Today's code loads the same params file and replays each feedback trace through today's loop
   (:func:`leadthrough.sim.session.replay_session`), built from the same settings.
3. Per case: the largest difference of the joint commands (position [rad], velocity [rad/s]) of
   every servo period, and whether the safety states, faults and transitions are identical.
   Today's loop ends a session with a commanded stop (issue 25): where the commanded motion is
   not at rest at the end of the duration, it runs on until it is; those periods ("stop
   after") have no reference and are not compared.

The replay is open loop (the recorded robot does not answer today's commands), so the comparison
holds for any change of the simulator: it checks the loop alone. Goal: 1e-12 rad.

Today's loop starts guiding only on a fresh press of the enabling device (a digital input of the
driver); a reference trace recorded before the drivers reported inputs carries none, so the
replay adds the press the simulated session scripts (input 0, pressed once the estimator is
ready, ``warm_up_s + tare_s`` after the first sample, and held).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
GOAL_RAD = 1e-12


def export_reference(rev: str, work: Path) -> Path:
    """The reference commit's ``src`` under ``work/ref`` (fresh)."""
    ref = work / "ref"
    subprocess.run(["rm", "-rf", str(ref)], check=True)
    ref.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(REPO), "archive", rev, "src"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(ref)], input=archive, check=True)
    return ref


def run_reference(ref: Path, out: Path, cases: list[str]) -> None:
    """The reference sessions, computed by the reference code."""
    env = dict(os.environ, PYTHONPATH=str(ref / "src"))
    subprocess.run([sys.executable, str(HERE / "equivalence_reference.py"), str(out), *cases],
                   check=True, env=env)


def compare(out: Path, names: list[str]) -> bool:
    """Replay each case with today's code and compare; returns whether all meet the goal."""
    from equivalence_cases import CASES  # the case table (plain values)
    from leadthrough.identification.params_file import load_params
    from leadthrough.robot import load_robot

    today = _today_api()
    robot = load_robot("er20")
    pf = load_params(out / "params.toml", robot)
    print(f"{'case':<22}{'reads':>7}  {'max |Δq_cmd| [rad]':>19}  {'max |Δqd_cmd|':>14}  "
          f"{'states':>7}  {'events':>7}  {'stop after':>10}  reference replays itself")
    ok = True
    for name in names:
        ref = np.load(out / f"{name}.npz")
        trace = today.trace(ref)
        log = today.replay(robot, pf, CASES[name], trace)
        k = ref["q_cmd"].shape[0]            # today's loop may add its end-of-session stop
        extra = log.q_cmd.shape[0] - k
        dq = float(np.max(np.abs(log.q_cmd[:k] - ref["q_cmd"])))
        dqd = float(np.max(np.abs(log.qd_cmd[:k] - ref["qd_cmd"])))
        states = bool(np.array_equal(log.state[:k], ref["state"])
                      and np.array_equal(log.fault[:k], ref["fault"]))
        t_end = float(log.time[k - 1])
        events = [[e.t, e.kind, e.label, e.cause] for e in log.events
                  if e.kind == "transition" and e.t <= t_end]
        same_events = events == json.loads(str(ref["events"]))
        itself = all(np.array_equal(ref[k], ref["replay_" + k])
                     for k in ("q_cmd", "qd_cmd", "state", "fault"))
        good = dq <= GOAL_RAD and dqd <= GOAL_RAD and states and same_events
        ok = ok and good
        print(f"{name:<22}{ref['fb_t'].size:>7}  {dq:>19.3g}  {dqd:>14.3g}  "
              f"{'same' if states else 'DIFFER':>7}  {'same' if same_events else 'DIFFER':>7}  "
              f"{extra:>7} ms  {'yes' if itself else 'NO'}")
    return ok


class _TodayAPI:
    """Today's names for the trace, the configuration of a case and the replay."""

    def trace(self, ref: np.lib.npyio.NpzFile) -> object:
        from leadthrough.drivers.replay import FeedbackTrace
        from leadthrough.session.loop_config import LoopConfig
        from leadthrough.sim.session import ENABLE_INPUT

        inputs = ref.get("fb_inputs")
        if inputs is None:      # the scripted press of the enabling device (see the doc)
            est = LoopConfig().estimator
            held = ref["fb_fresh"] & (ref["fb_t"] >= est.warm_up_s + est.tare_s)
            inputs = np.where(held, 1 << ENABLE_INPUT, 0).astype(np.int64)
        return FeedbackTrace(dt=float(ref["fb_dt"]), t=ref["fb_t"], q=ref["fb_q"],
                             current=ref["fb_current"], sequence=ref["fb_sequence"],
                             fresh=ref["fb_fresh"], digital_inputs=inputs)

    def config(self, robot: object, case: dict[str, object]) -> object:
        """Today's SimSessionConfig of a case (the reference builds the same settings with its
        own API: equivalence_reference.session_config)."""
        from dataclasses import replace

        import pinocchio as pin

        from leadthrough.control.guiding import GuidingConfig
        from leadthrough.control.safety import SafetyConfig
        from leadthrough.robot.poses import guide_start_pose
        from leadthrough.session.loop_config import LoopConfig
        from leadthrough.sim.driver import InjectedFault, InjectedFaultKind
        from leadthrough.sim.session import SimSessionConfig, light_guiding

        guiding = GuidingConfig()
        if "mass" in case:
            guiding = light_guiding(float(case["mass"]))  # type: ignore[arg-type]
        guiding = replace(guiding, controller=str(case.get("controller", "virtual-friction")))
        if "frame" in case:
            guiding = replace(guiding, frame=str(case["frame"]))
        if "friction_mode" in case:
            guiding = replace(guiding, friction_mode=str(case["friction_mode"]))
        if case.get("axes") == "translation":
            guiding = replace(guiding, axes_enabled=(True,) * 3 + (False,) * 3)
        if "rezero_s" in case:
            guiding = replace(guiding, rezero_s=float(case["rezero_s"]))  # type: ignore[arg-type]
        if "box_dx" in case:
            data = robot.model.createData()  # type: ignore[attr-defined]
            pin.framesForwardKinematics(robot.model, data,  # type: ignore[attr-defined]
                                        guide_start_pose(robot))  # type: ignore[arg-type]
            x0 = float(data.oMf[robot.tcp_frame_id].translation[0])  # type: ignore[attr-defined]
            inf = float("inf")
            guiding = replace(guiding, safety=SafetyConfig(
                workspace_min=(-inf, -inf, -inf),
                workspace_max=(x0 + float(case["box_dx"]), inf, inf)))  # type: ignore[arg-type]
        estimator = LoopConfig().estimator
        if "method" in case:
            estimator = replace(estimator, method=str(case["method"]))
        faults = ()
        if "fault" in case:
            kind, t0, t1, joint, offset = case["fault"]  # type: ignore[misc]
            faults = (InjectedFault(InjectedFaultKind(kind), t_start=t0, t_end=t1, joint=joint,
                                    offset=offset),)
        return SimSessionConfig(operator=str(case["operator"]),
                                operator_seed=case.get("operator_seed"),  # type: ignore[arg-type]
                                loop=LoopConfig(estimator=estimator, guiding=guiding),
                                faults=faults)

    def replay(self, robot: object, pf: object, case: dict[str, object], trace: object
               ) -> object:
        from leadthrough.sim.session import replay_session
        return replay_session(robot, pf, self.config(robot, case), trace).log  # type: ignore[arg-type]


def _today_api() -> _TodayAPI:
    return _TodayAPI()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reference", required=True, help="reference commit (e.g. ffa859f)")
    parser.add_argument("--work", type=Path, default=None,
                        help="folder for the export and the recordings (default: a temporary "
                             "one; reuse one to skip the reference run)")
    parser.add_argument("cases", nargs="*", help="cases to run (default: all)")
    args = parser.parse_args()
    sys.path.insert(0, str(HERE))
    from equivalence_cases import CASES
    names = args.cases or list(CASES)
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work if args.work is not None else Path(tmp)
        out = work / "sessions"
        if not all((out / f"{n}.npz").exists() for n in names):
            print(f"reference {args.reference}: exporting and running its sessions ...",
                  flush=True)
            run_reference(export_reference(args.reference, work), out, names)
        ok = compare(out, names)
    print(f"\nall cases within {GOAL_RAD:g} rad with the same states and transitions: "
          f"{'yes' if ok else 'NO'}")
    raise SystemExit(0 if ok else 1)


if __name__ == "__main__":
    main()
