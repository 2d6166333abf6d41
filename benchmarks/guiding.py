"""Force following on the simulated er20 (issue 6): rest, push +x (Fig. 4), diagonal and seam
(Fig. 5), and the full cycle time. Parameters come from calibration (consistent method on a
60 s excitation with a friction sweep, z₀ from a presliding test, seed 1), never from the
simulator's truth.

    python benchmarks/guiding.py [--poses 20] [--rest-seconds 10] [--random 24]
                                 [--out benchmarks/out]

1. Rest: no force, ``--poses`` random poses × ``--rest-seconds``, both controllers: peak
   commanded speed and rest drift (virtual friction: exactly 0; the velocity baseline drifts).
2. Push +x with 40 N for 3 s (the ``push-x`` script), both controllers: peak speed along x,
   off-axis / main-axis speed, overshoot of the 0.2 m/s cap, speed at the end; Fig. 4 PNG.
3. Diagonal and seam sessions: Fig. 5 PNG.
4. Random pushes (``--random`` sessions of 8 pushes, 20–60 N in random directions, 100 kg
   mass): travel after each release beyond the shortest stop (``release_overruns``), faults.
5. Cycle time of the loop's controller periods (estimator + controller + IK + limits +
   interpolation), median and p99, and as a multiple of one ``pin.rnea`` call: in the diagonal
   and seam sessions, where the simulator's work between cycles evicts the loop from the caches,
   and for the loop alone, replaying the sessions' recorded feedback (same computation, bit for
   bit; :mod:`leadthrough.drivers.replay`) five times: each replay, and each cycle's fastest
   of the five (the computation's own spread, without the machine's random interruptions),
   split into moving cycles and cycles at rest; and how often the machine interrupts a loop that
   does nothing else (on a VM: a few hundred times a second, by tens of µs: a cycle is hit with
   a probability of its length times that rate, which sets the p99 once it passes 1 %).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from leadthrough.control.guiding import GuidingConfig
from leadthrough.drivers.protocol import Driver
from leadthrough.drivers.replay import FeedbackTrace
from leadthrough.excitation.design import ExcitationConfig
from leadthrough.identification.api import identify_with_sweep
from leadthrough.identification.params_file import ParamsFile, load_params, save_params
from leadthrough.identification.presliding import fit_presliding
from leadthrough.robot import Robot, load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopConfig, build_loop
from leadthrough.session.metrics import force_error_in_motion, phantom_forces, release_overruns
from leadthrough.session.plots import plot_force_velocity, plot_path_3d
from leadthrough.session_format import SessionLog
from leadthrough.sim.calibration_set import (
    record_calibration_set,
    record_friction_sweep,
    record_presliding_test,
)
from leadthrough.sim.plant import PLANT_NAMES
from leadthrough.sim.session import (
    PUSH_MASS_KG,
    SimSessionConfig,
    light_guiding,
    replay_session,
    run_sim_session,
    sim_robot_seed,
)
from realtime_probe import ProbeDriver, compiled_allocations

CONTROLLERS = ("virtual-friction", "velocity")
#: Replays of each session's loop for the cycle time.
REPLAYS = 5
#: Length of the probe of the machine's interruptions [s], and the shortest gap counted [µs].
INTERRUPTION_PROBE_S = 1.0
INTERRUPTION_GAP_US = 10.0


def rnea_time_us(robot_name: str = "er20", repeats: int = 20000) -> float:
    """Median time of one pin.rnea call [µs]."""
    robot = load_robot(robot_name)
    m, d = robot.model, robot.model.createData()
    q, v, a = robot.neutral(), np.full(robot.n, 0.1), np.full(robot.n, 0.2)
    ts = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        pin.rnea(m, d, q, v, a)
        ts[i] = time.perf_counter() - t0
    return float(np.median(ts) * 1e6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--rest-seconds", type=float, default=10.0)
    parser.add_argument("--random", type=int, default=24, help="random-push sessions")
    parser.add_argument("--sections", default="12345",
                        help="sections to run (default 12345; 5 implies 3's sessions)")
    parser.add_argument("--reference", metavar="REV", default=None,
                        help="also time the diagonal and seam sessions with the code of commit "
                             "REV (section 5; via replay_equivalence.py's export)")
    parser.add_argument("--params", type=Path, default=None,
                        help="use these parameters instead of calibrating (e.g. the "
                             "guiding_params.toml an earlier run wrote into --out)")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/out"))
    parser.add_argument("--plant", choices=PLANT_NAMES, default=PLANT_NAMES[0],
                        help="simulated plant (default realistic; ideal: the plant before "
                             "issue 24)")
    parser.add_argument("--seed", type=int, default=1,
                        help="simulated robot instance (calibration and sessions)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    robot = load_robot("er20")
    if args.params is not None:
        pf = load_params(args.params, robot)
        print(f"Parameters: {args.params}")
    else:
        cal = record_calibration_set(robot, seed=args.seed, duration=60.0,
                                     excitation_config=ExcitationConfig(starts=4),
                                     plant=args.plant)
        sweep = record_friction_sweep(robot, seed=args.seed, run=2, q_start=guide_start_pose(robot),
                                      plant=args.plant)
        pre = fit_presliding(record_presliding_test(robot, seed=args.seed, run=3,
                                                    q_start=guide_start_pose(robot),
                                                    plant=args.plant).measured, robot)
        sc = identify_with_sweep(cal.identification.measured, sweep.measured, robot)
        r = sc.result
        path = save_params(args.out / "guiding_params.toml", robot, r.method,
                           pre.applied_to(r.params), r.stats,
                           sim_seed=args.seed, friction_sweep=True)
        pf = load_params(path, robot)
        print("Parameters: consistent + friction sweep + presliding test; sweep fit RMS per "
              "joint " + ", ".join(f"{v:.2f}" for v in sc.sweep.rms) + " N·m, z0 "
              + ", ".join(f"{1e4 * v:.2f}" for v in pre.presliding) + f" e-4 rad -> {path}")
    if "1" in args.sections:
        section_rest(robot, pf, args.poses, args.rest_seconds, args.plant)
    if "2" in args.sections:
        section_push(robot, pf, args.out, args.plant)
    if "3" in args.sections or "5" in args.sections:
        timed = section_paths(robot, pf, args.out, args.plant)
    if "4" in args.sections:
        section_random(robot, pf, args.random, args.plant)
    if "5" in args.sections:
        section_cycle_time(robot, pf, timed, args.reference)


def section_rest(robot: Robot, pf: ParamsFile, poses_n: int, seconds: float,
                 plant: str = PLANT_NAMES[0]) -> None:
    """1. Rest, no force, random poses, both controllers."""
    print(f"\n1. Rest, no force: {poses_n} random poses × {seconds:g} s")
    rng = np.random.default_rng(0)
    poses = [rng.uniform(0.5 * robot.lower_limits, 0.5 * robot.upper_limits)
             for _ in range(poses_n)]
    for ctl in CONTROLLERS:
        vmax, drift, nonzero, faults = 0.0, 0.0, 0, 0
        for k, q0 in enumerate(poses):
            s = run_sim_session(robot, pf, SimSessionConfig(
                seed=sim_robot_seed(None, pf),
                operator="rest", duration_s=seconds, q0=tuple(q0), run=600 + k, plant=plant,
                loop=LoopConfig(guiding=GuidingConfig(controller=ctl))))
            vmax = max(vmax, s.summary.max_linear_speed, s.summary.max_angular_speed)
            drift = max(drift, s.summary.rest_drift_m or 0.0)
            nonzero += int(np.any(s.result.log.twist_cmd_base != 0.0))
            faults += len(s.summary.faults)
        print(f"  {ctl:<17} peak commanded speed {vmax:.4f} (m/s | rad/s), sessions with "
              f"any nonzero command {nonzero}/{poses_n}, max rest drift "
              f"{1000 * drift:.2f} mm, faults {faults}")


def section_push(robot: Robot, pf: ParamsFile, out: Path, plant: str = PLANT_NAMES[0]
                 ) -> None:
    """2. Push +x with 40 N, both controllers; Fig. 4."""
    print(f"\n2. Push +x, 40 N from 1 s to 4 s, virtual mass {PUSH_MASS_KG:g} kg "
          "(Table IV's 1000 kg would reach 0.075 m/s)")
    logs = {}
    for ctl in CONTROLLERS:
        guiding = replace(light_guiding(), controller=ctl)
        s = run_sim_session(robot, pf, SimSessionConfig(operator="push-x", plant=plant,
                                                        seed=sim_robot_seed(None, pf),
                                                        loop=LoopConfig(guiding=guiding)))
        log = logs[ctl] = s.result.log
        v = log.twist_cmd_base[:, :3]
        main_peak = float(np.abs(v[:, 0]).max())
        off = float(np.linalg.norm(v[:, 1:], axis=1).max())
        end = float(np.linalg.norm(v[-1]))
        ratio = off / max(main_peak, 1e-12)
        over = max(0.0, main_peak - 0.2)
        print(f"  {ctl:<17} peak vx {main_peak:.3f} m/s, off-axis/main {ratio:.3f}, "
              f"overshoot of 0.2 m/s {over:.3f}, |v| at end {end:.3f} m/s, "
              f"faults {s.summary.faults or 'none'}")
        err = log.wrench_base[:, :3] - log.wrench_applied_base[:, :3]  # type: ignore[index]
        print(f"  {'':<17} force estimate error RMS {np.sqrt(np.mean(np.sum(err**2, 1))):.1f} N"
              + _in_motion(log))
    print("  ->", plot_force_velocity({"virtual friction": logs["virtual-friction"],
                                      "velocity [14]": logs["velocity"]},
                                     out / "fig4_push_x.png"))


def _in_motion(log: SessionLog) -> str:
    """Issue 24's figures: force error RMS while the TCP moves >= 0.02 m/s, and the largest
    estimated force within 0.5 s after a release (goals 5 N and δ = 15 N)."""
    rms, phantom = force_error_in_motion(log), phantom_forces(log)
    text = "" if rms is None else f"; in motion (>= 0.02 m/s) {rms:.1f} N RMS"
    if phantom is not None and phantom.size:
        text += f"; phantom after release (0.5 s) max {phantom.max():.1f} N"
    return text


def section_paths(robot: Robot, pf: ParamsFile, out: Path, plant: str = PLANT_NAMES[0]
                  ) -> list[TimedSession]:
    """3. Diagonal and seam sessions (Fig. 5), probed for section 5."""
    print("\n3. Diagonal and seam sessions (virtual friction)")
    paths, targets, timed = {}, {}, []
    for op in ("diagonal", "seam"):
        cfg = SimSessionConfig(operator=op, plant=plant, seed=sim_robot_seed(None, pf))
        probe: list[ProbeDriver] = []

        def wrap(d: Driver, keep: list[ProbeDriver] = probe) -> Driver:
            keep.append(ProbeDriver(d, round(60.0 / d.dt)))
            return keep[-1]

        s = run_sim_session(robot, pf, cfg, record_feedback=True, wrap_driver=wrap)
        paths[op] = s.result.log
        log = s.result.log
        every = round(cfg.loop.guiding.dt / float(log.time[1] - log.time[0]))
        # a cycle moves when it commands a twist (else it holds its setpoint and reuses the
        # setpoint's kinematics)
        moving = np.any(log.twist_cmd_base[::every] != 0.0, axis=1)[:s.result.cycle_us.size]
        assert s.feedback is not None
        timed.append(TimedSession(op, cfg, s.result.cycle_us, moving, s.feedback,
                                  probe[0].finish()))
        if s.p1_base is not None and s.p2_base is not None:
            targets.update({"P1": s.p1_base, "P2": s.p2_base})
        print(f"  {op:<9} max speed {s.summary.max_linear_speed:.3f} m/s, faults "
              f"{s.summary.faults or 'none'}" + _in_motion(log))
    print("  ->", plot_path_3d(paths, out / "fig5_paths.png", targets=targets))
    return timed


def section_random(robot: Robot, pf: ParamsFile, sessions: int, plant: str = PLANT_NAMES[0]
                   ) -> None:
    """4. Random pushes: travel beyond the shortest stop after each release."""
    light = light_guiding()
    a_max = light.limits.max_linear_acceleration
    print(f"\n4. Random pushes, {sessions} sessions × 8 (operator seeds 0..{sessions - 1}, "
          f"{PUSH_MASS_KG:g} kg): travel after a release beyond a stop at {a_max:g} m/s²")
    overruns, faults = [], []
    for k in range(sessions):
        s = run_sim_session(robot, pf, SimSessionConfig(operator="random", operator_seed=k,
                                                        seed=sim_robot_seed(None, pf),
                                                        loop=LoopConfig(guiding=light),
                                                        plant=plant))
        over = release_overruns(s.result.log, a_max)
        if over is not None:  # the simulator always records the applied wrench
            overruns.append(over)
        faults += [f"{f} (seed {k})" for f in s.summary.faults]
    o = 1e3 * np.concatenate(overruns)
    print(f"  {o.size} releases: median {np.median(o):.1f} mm, p90 {np.percentile(o, 90):.1f} "
          f"mm, max {o.max():.1f} mm, total {o.sum():.0f} mm; faults {faults or 'none'}")


def section_cycle_time(robot: Robot, pf: ParamsFile, timed: list[TimedSession],
                       reference: str | None) -> None:
    """5. Cycle time in the simulated sessions and of the loop alone; what the periods
    compiled, collected and allocated; the reference commit's cycle time."""
    r = rnea_time_us()
    print("\n5. Cycle time (estimator + controller + IK + limits + interpolation), diagonal and "
          f"seam sessions; one pin.rnea: {r:.2f} µs; goal p99 <= 100 µs")
    in_loop = np.concatenate([t.cycle_us for t in timed])
    _report("in the simulated session", in_loop, r)
    if reference is not None:
        ref = reference_cycle_us(reference)
        _report(f"in the simulated session, commit {reference}", ref, r)
        print(f"  {'':<44} today / {reference}: median "
              f"{np.median(in_loop) / np.median(ref):.2f}×, p99 "
              f"{np.percentile(in_loop, 99) / np.percentile(ref, 99):.2f}×")
    _report_worst_case(robot, pf, timed)
    # the same loop on the recorded feedback, without the simulator between the cycles,
    # REPLAYS times (the same computation each time, bit for bit)
    runs = np.concatenate([np.array([replay_session(robot, pf, t.config, t.feedback).cycle_us
                                     for _ in range(REPLAYS)]) for t in timed], axis=1)
    for k in range(REPLAYS):
        _report(f"loop alone, replay {k + 1}", runs[k], r)
    # each cycle's fastest replay: what the computation itself costs, without the machine's
    # interruptions (they hit a cycle at random, see below)
    fastest = runs.min(axis=0)
    _report(f"loop alone, each cycle's fastest of {REPLAYS}", fastest, r)
    mov = np.concatenate([t.moving for t in timed])
    _report(f"  of which moving ({mov.sum()} cycles)", fastest[mov], r)
    _report(f"  of which at rest ({(~mov).sum()} cycles)", fastest[~mov], r)
    gaps = interruptions()
    rate = gaps.size / INTERRUPTION_PROBE_S
    print(f"  the machine: an empty loop is interrupted {rate:.0f} times/s, by median "
          f"{np.median(gaps):.0f} µs (p90 {np.percentile(gaps, 90):.0f} µs); a cycle of "
          f"{np.median(fastest[mov]):.0f} µs is hit with probability "
          f"{100 * rate * np.median(fastest[mov]) * 1e-6:.1f} %")


def _report_worst_case(robot: Robot, pf: ParamsFile, timed: list[TimedSession]) -> None:
    """What the servo periods of the simulated sessions compiled and collected, and (a replay
    of their feedback under tracemalloc, so that the simulator's own allocations do not count)
    what they allocated."""
    periods = sum(t.probe["periods"] for t in timed)
    new = {k: v for t in timed for k, v in t.probe["new_signatures"].items()}
    collections = sum(t.probe["collections"] for t in timed)
    nrt = sum(t.probe["nrt_allocations"] for t in timed)
    print(f"  {periods} servo periods of the simulated sessions: compiled or loaded "
          f"{sum(new.values())} signatures ({', '.join(new) or 'none'}), garbage collections "
          f"{collections}")
    kept, transient = [], []
    for t in timed:
        holder: list[ProbeDriver] = []

        def wrap(d: Driver, keep: list[ProbeDriver] = holder, reads: int = t.feedback.reads
                 ) -> Driver:
            keep.append(ProbeDriver(d, reads, trace_memory=True))
            return keep[-1]

        replay_session(robot, pf, t.config, t.feedback, wrap_driver=wrap)
        fig = holder[0].finish()
        kept.append(fig["kept"])
        transient.append(fig["transient"])
    tr_all = np.concatenate(transient)
    print(f"  the loop alone (replay under tracemalloc): memory kept over the periods "
          f"{', '.join(f'{k:+d} B' for k in kept)}; allocated and freed within a period: "
          f"median {np.median(tr_all):.0f} B, max {tr_all.max():.0f} B (Pinocchio's returned "
          "arrays, Python scalars and views)")
    parts = build_loop(robot, pf, timed[0].config.loop, timed[0].feedback.dt)
    q0 = timed[0].feedback.q[np.argmax(timed[0].feedback.fresh)]
    for part in parts:
        part.reset(q0)
    inside = compiled_allocations(parts)
    print("  allocations per call inside the compiled functions (called from compiled code): "
          + ", ".join(f"{k} {v:g}" for k, v in inside.items()) + f"; per period "
          f"{nrt / max(periods, 1):.1f} come from the dispatcher wrapping each array "
          "argument of a call from Python (freed when the call returns)")


def reference_cycle_us(rev: str) -> np.ndarray:
    """Cycle times [µs] of the diagonal and seam sessions simulated with commit ``rev``'s code
    (exported and run by ``replay_equivalence.py``'s reference side, in a subprocess of this
    run)."""
    import tempfile

    from replay_equivalence import export_reference, run_reference
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        run_reference(export_reference(rev, work), work / "sessions", ["diagonal", "seam"])
        return np.concatenate([np.load(work / "sessions" / f"{c}.npz")["cycle_us"]
                               for c in ("diagonal", "seam")])


@dataclass
class TimedSession:
    """A simulated session kept for the cycle time: its settings, controller cycle times [µs],
    which cycles moved, its recorded feedback, and its probe's figures."""

    name: str
    config: SimSessionConfig
    cycle_us: np.ndarray
    moving: np.ndarray
    feedback: FeedbackTrace
    probe: dict[str, Any]


def interruptions(seconds: float = INTERRUPTION_PROBE_S) -> np.ndarray:
    """The machine's interruptions of a running thread: gaps [µs] longer than
    :data:`INTERRUPTION_GAP_US` between consecutive clock reads of a loop that does nothing
    else, over ``seconds``."""
    reads = np.ones(round(seconds * 1e7))   # touched (no page faults while timing); ~7e6 reads/s
    clock = time.perf_counter
    end = clock() + seconds
    k = 0
    while k < reads.size:
        reads[k] = t = clock()
        k += 1
        if t > end:
            break
    gaps = 1e6 * np.diff(reads[:k])
    return gaps[gaps > INTERRUPTION_GAP_US]


def _report(label: str, us: np.ndarray, rnea_us: float) -> None:
    """One line of cycle times [µs]: median and p99, and as multiples of one pin.rnea."""
    med, p99 = np.median(us), np.percentile(us, 99)
    print(f"  {label:<44} median {med:5.1f} µs, p99 {p99:5.1f} µs "
          f"({med / rnea_us:.0f}× / {p99 / rnea_us:.0f}× pin.rnea)")


if __name__ == "__main__":
    main()
