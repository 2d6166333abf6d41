"""``leadthrough guide``: a hand-guiding session on the built-in simulated robot, or with
``--driver D --host H`` on a robot controller (:mod:`leadthrough.cli.guide_robot`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from leadthrough.cli.arg_checks import (
    check_not_input,
    require_sweep,
    warm_up_seconds,
    with_command_lag,
)
from leadthrough.cli.guide_robot import add_robot_arguments, guide_on_robot
from leadthrough.cli.record_robot import (
    EXIT_CODES_HELP,
    EXIT_FAULT,
    EXIT_LINK,
    EXIT_OK,
    refuse_settings,
)
from leadthrough.control.guiding import CONTROLLERS, GuidingConfig
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.errors import DataError
from leadthrough.fileio import require_folder
from leadthrough.identification.params_file import ParamsFile, load_params
from leadthrough.robot.description import load_robot
from leadthrough.session.loop_config import SLOW_COMMAND_VELOCITY, LoopConfig
from leadthrough.session_format import save_session
from leadthrough.sim.operator_scripts import OPERATOR_NAMES
from leadthrough.sim.plant import PLANT_NAMES
from leadthrough.sim.session import (
    SimSessionConfig,
    light_guiding,
    run_sim_session,
    sim_robot_seed,
)

__all__ = ["register"]


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "guide", help="hand-guide the simulated robot with a scripted operator",
        description="Run a guiding session on the simulated robot: a scripted operator pushes "
                    "the tool, the external force is estimated from the motor currents with the "
                    "identified parameters (eq. 27-30), and the controller follows it (virtual "
                    "mass and friction, eq. 31-36, or the velocity baseline [14]) through the "
                    "safety layer, differential IK and 1 ms interpolation. Everything is "
                    "recorded to Parquet.",
        epilog="examples:\n  leadthrough guide --robot er20 --params params.toml --operator push-x "
               "-o session.parquet --json\n  leadthrough guide --driver ur-rtde --host 10.0.0.2 "
               "--robot ur5 --params params.toml --enable-input 0 --mark-input 1 "
               "-o session.parquet   (until Ctrl-C)\n\n" + EXIT_CODES_HELP + " (Ctrl-C, "
               "SIGTERM or --duration is the normal end of a session: 0 when nothing faulted)",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robot", default="er20", help="robot (default: er20)")
    p.add_argument("--params", type=Path, required=True,
                   help="identified parameters (leadthrough identify -o params.toml)")
    p.add_argument("--operator", choices=OPERATOR_NAMES, default=None,
                   help="scripted operator on the simulator (default: push-x)")
    p.add_argument("--controller", choices=CONTROLLERS, default="virtual-friction",
                   help="force-following law (default: virtual-friction, the paper's)")
    p.add_argument("--friction", choices=("fixed", "auto"), default="fixed",
                   help="virtual friction: Table IV values or eq. 36 from the identified noise")
    p.add_argument("--mass", type=float, default=None, metavar="KG",
                   help="translational virtual mass [kg] (default: Table IV's 1000; the "
                        "push demonstrations use 100 so that 40 N reaches the 0.2 m/s cap)")
    p.add_argument("--duration", type=float, default=None,
                   help="session length [s] (default: the operator script's; with --driver: "
                        "until Ctrl-C)")
    p.add_argument("--seed", type=int, default=None,
                   help="simulated robot instance (default: the one the params were identified "
                        "on, their [meta] sim_seed, else 1); another one is refused")
    p.add_argument("--operator-seed", type=int, default=None, metavar="N",
                   help="seed of the random operator's pushes (default: --seed); vary this "
                        "for other push sequences on the same robot")
    p.add_argument("--run", type=int, default=None, metavar="N",
                   help="the simulator's session number: its sensor noise (default 500); vary "
                        "this to see how a session spreads with the noise alone")
    p.add_argument("--allow-no-sweep", action="store_true",
                   help="guide with parameters identified without a friction sweep (refused "
                        "otherwise: their friction is 15-24 %% low at guiding speeds, which "
                        "reads as a 20-50 N force against the motion)")
    p.add_argument("--plant", choices=PLANT_NAMES, default=PLANT_NAMES[0],
                   help="simulated plant: realistic (default) or ideal (the plant before issue "
                        "24); the one the params were recorded on")
    p.add_argument("--hand-release", action="store_true",
                   help="stop at the acceleration limit when the hand lets go of the moving "
                        "tool, whatever the force estimate says (issue 24; off by default: it "
                        "brakes a hand that eases off, e.g. at a seam's end points)")
    p.add_argument("--warm-up", type=float, default=0.0, metavar="MINUTES",
                   help="production-like motion the realistic robot did before the session "
                        "[min] (default 0: cold, as a calibration in the morning)")
    p.add_argument("--command-lag", type=float, default=None, metavar="S",
                   help="how long a command takes to show in the measured position on this "
                        "robot's interface [s] (default: the lag `identify` measured on the "
                        "params' recording, [meta] command_lag; give it when the params come "
                        "from another interface, e.g. identified in-process and guided over a "
                        "driver)")
    p.add_argument("--realtime", action="store_true", help="pace to the wall clock")
    p.add_argument("-o", "--output", type=Path, required=True, help="session .parquet")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_robot_arguments(p)
    p.set_defaults(func=run, link_error_exit=EXIT_LINK)


def _note_missing_presliding(pf: ParamsFile) -> None:
    """A note on stderr when ``pf`` carries no presliding test, or one without the friction's
    relaxation at rest (after the input's checks, so that bad input gets its one error line
    only)."""
    if not pf.params.presliding.size:
        print(f"leadthrough: note: {pf.path} carries no presliding test (joints.*.presliding):"
              f" a joint commanded slower than {SLOW_COMMAND_VELOCITY:g} rad/s keeps the "
              "command's friction (record one: excite --presliding, then identify "
              "--presliding-test)", file=sys.stderr, flush=True)
    elif not pf.params.presliding_relaxation.size:
        print(f"leadthrough: note: {pf.path} carries no relaxation of the friction at rest "
              "(joints.*.presliding_relaxation, fitted since 2026-11-28): the estimate at "
              "rest drifts about twice as fast (identify --presliding-test again)",
              file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough guide``."""
    robot = load_robot(args.robot)
    pf = require_sweep(with_command_lag(load_params(args.params, robot), args.command_lag),
                       args.allow_no_sweep)
    guiding = GuidingConfig() if args.mass is None else light_guiding(args.mass)
    guiding = replace(guiding, controller=args.controller, friction_mode=args.friction)
    if args.hand_release:
        guiding = replace(guiding, hand_release=HandReleaseConfig(enabled=True))
    require_folder(args.output)
    check_not_input(args.output, "-o", (("--params", args.params),))
    if args.driver is not None:
        _note_missing_presliding(pf)
        return guide_on_robot(args, robot, pf, guiding)
    refuse_settings(args, ("enable_input", "mark_input", "reset_input", "host", "port",
                           "watchdog", "rt_priority", "cpus", "lock_memory"),
                    "a robot setting given for the simulator",
                    "--driver D with it (the simulator scripts its inputs)")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise DataError("out of range", field="--duration", value=args.duration,
                        expected="finite seconds > 0 on the simulator (leave it out for the "
                                 "operator script's length)")
    if args.seed is not None and args.seed < 0:
        raise DataError("out of range", field="--seed", value=args.seed,
                        expected="a simulated robot instance >= 0")
    _note_missing_presliding(pf)
    args.operator = args.operator or "push-x"
    seed = sim_robot_seed(args.seed, pf)
    loop = LoopConfig(guiding=guiding)
    cfg = SimSessionConfig(operator=args.operator, duration_s=args.duration, seed=seed,
                           **({} if args.run is None else {"run": args.run}),
                           operator_seed=args.operator_seed, paced=args.realtime, loop=loop,
                           plant=args.plant, warm_up_s=warm_up_seconds(args.warm_up))
    session = run_sim_session(robot, pf, cfg)
    save_session(session.log, args.output)
    summary = session.summary.to_json()
    summary["session"] = str(args.output)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        s = session.summary
        drift = "n/a" if s.rest_drift_m is None else f"{1000 * s.rest_drift_m:.3f} mm"
        over = "n/a" if s.release_overrun_m is None else f"{1000 * s.release_overrun_m:.1f} mm"
        print(f"{args.operator} with {args.controller}: max speed {s.max_linear_speed:.3f} m/s, "
              f"{s.max_angular_speed:.3f} rad/s; max acc {s.max_linear_acc:.3f} m/s²; rest "
              f"drift {drift}; overrun after a release {over}; faults {s.faults or 'none'}; "
              f"cycle {s.cycle_time_us.median:.0f} µs median, {s.cycle_time_us.p99:.0f} µs p99 "
              f"-> {args.output}")
    if session.summary.faults:
        print(f"leadthrough: a fault was latched in the session ("
              f"{', '.join(dict.fromkeys(session.summary.faults))}): exit code {EXIT_FAULT}",
              file=sys.stderr)
        return EXIT_FAULT
    return EXIT_OK
