"""Calibration commands, the robot's side: ``excite`` (an excitation, friction sweep or
presliding test) and ``record`` (run it on the simulated robot or a robot and log it); the
model's side: :mod:`leadthrough.cli.identify_cmd`."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.cli.arg_checks import (
    MAX_PAYLOAD_COM_M,
    check_output,
    check_payload_torques,
    check_trajectory_limits,
    warm_up_seconds,
)
from leadthrough.cli.friction_experiments import excite_friction_experiment
from leadthrough.cli.record_robot import (
    EXIT_CODES_HELP,
    EXIT_LINK,
    add_driver_arguments,
    record_on_robot,
    refuse_settings,
)
from leadthrough.data.io import save_recording
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError
from leadthrough.excitation.design import ExcitationConfig, design_excitation
from leadthrough.excitation.trajectory_file import load_trajectory, save_trajectory
from leadthrough.progress import Progress
from leadthrough.robot.description import load_robot
from leadthrough.sim.mujoco_model import Payload
from leadthrough.sim.plant import PLANT_NAMES
from leadthrough.sim.robot import SimConfig, SimRobot
from leadthrough.sim.run import run_trajectory

__all__ = ["register"]

_RAW = argparse.RawDescriptionHelpFormatter


def register(sub: Any) -> None:
    """Add ``excite`` and ``record``."""
    for add in (_register_excite, _register_record):
        add(sub)


def _register_excite(sub: Any) -> None:
    p = sub.add_parser("excite", help="design an exciting trajectory", formatter_class=_RAW,
                       description="Optimise a Fourier excitation trajectory (rest to rest) for "
                                   "identification: minimal condition number within joint, "
                                   "speed, acceleration, torque and floor limits.",
                       epilog="examples:\n  leadthrough excite --robot er20 --duration 60 -o "
                              "traj.csv\n  leadthrough excite --robot er20 --sweep -o sweep.csv "
                              " # friction sweep for identify --friction-sweep\n"
                              "  leadthrough excite --robot er20 --presliding -o pre.csv "
                              " # presliding test for identify --presliding-test")
    p.add_argument("--robot", default="er20", help="built-in name or robot TOML")
    p.add_argument("--duration", type=float, default=60.0, help="length [s], whole periods")
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start")
    p.add_argument("--harmonics", type=int, default=5)
    p.add_argument("--base-frequency", type=float, default=0.1, help="f0 [Hz]")
    p.add_argument("--starts", type=int, default=4, help="random starts")
    p.add_argument("--floor", type=float, default=0.3, help="min TCP height [m]")
    p.add_argument("--sweep", action="store_true",
                   help="instead, a friction sweep: constant-velocity passes out and back at "
                        "10 speeds, all joints at once (about 45 s)")
    p.add_argument("--friction-check", action="store_true",
                   help="instead, a friction check (4 speeds out and back, ~15 s) for "
                        "refresh-friction: run it before guiding on a robot whose friction "
                        "has drifted since its calibration (warm, or cold)")
    p.add_argument("--presliding", action="store_true",
                   help="instead, a presliding test: out-and-back excursions of 0.03–1.5 mrad "
                        "at rest, all joints at once (about 80 s)")
    p.add_argument("--start", type=float, nargs="+", default=None, metavar="Q",
                   help="sweep / presliding test configuration [rad] (default: the guiding "
                        "start pose)")
    p.add_argument("-o", "--output", type=Path, required=True, help="trajectory CSV")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_excite)


def _register_record(sub: Any) -> None:
    p = sub.add_parser("record", help="run a trajectory on the simulated robot or a robot",
                       formatter_class=_RAW,
                       description="Run a joint trajectory (an excitation, a friction sweep or a "
                                   "presliding test from `excite`) and log q and the motor "
                                   "currents (or joint torques): on the simulated robot at 1 kHz, "
                                   "or with --driver on a robot controller at its own cycle, "
                                   "after a slow approach to the trajectory's start.",
                       epilog="examples:\n  leadthrough record --robot er20 --trajectory traj.csv "
                              "-o rec.parquet\n  leadthrough record --driver fanuc-j519 --host "
                              "192.168.1.10 --robot er20 --trajectory traj.csv -o rec.parquet"
                              "\n\n" + EXIT_CODES_HELP + " (the simulator's run has no fault: 0 or "
                              "2)")
    p.add_argument("--robot", default="er20")
    p.add_argument("--trajectory", type=Path, required=True, help="trajectory CSV")
    p.add_argument("--seed", type=int, default=None,
                   help="simulated robot instance (true parameters; default 0)")
    p.add_argument("--run", type=int, default=None,
                   help="simulated recording number (sensor noise; default 0)")
    p.add_argument("--plant", choices=PLANT_NAMES, default=None,
                   help="simulated plant: realistic (default; model mismatch, load- and "
                        "temperature-dependent friction) or ideal (the plant before issue 24)")
    p.add_argument("--warm-up", type=float, default=None, metavar="MINUTES",
                   help="production-like motion the simulated robot did before the recording "
                        "[min] (default 0: a cold robot; its friction is tens of per cent "
                        "higher than after an hour)")
    p.add_argument("--payload-mass", type=float, default=None,
                   help="simulated payload at the TCP [kg]")
    p.add_argument("--payload-com", type=float, nargs=3, default=None,
                   metavar=("X", "Y", "Z"),
                   help="payload CoM in the TCP frame [m] (with --payload-mass; default 0 0 0.05)")
    add_driver_arguments(p)
    p.add_argument("-o", "--output", type=Path, required=True, help="recording .parquet/.csv")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_record, link_error_exit=EXIT_LINK)


MAX_EXCITATION_S = 3600.0


def run_excite(args: argparse.Namespace) -> int:
    """Execute ``leadthrough excite``."""
    check_output(args.output, (".csv",))
    robot = load_robot(args.robot)
    if args.sweep or args.presliding or args.friction_check:
        return excite_friction_experiment(args, robot)
    if args.start is not None:
        raise DataError("a start pose is for the friction experiments only", field="--start",
                        value=args.start,
                        expected="--start with --sweep, --presliding or --friction-check")
    cfg = ExcitationConfig(harmonics=args.harmonics, base_frequency=args.base_frequency,
                           starts=args.starts, seed=args.seed, floor_height=args.floor)
    period = 1.0 / cfg.base_frequency
    if not 0 < args.duration <= MAX_EXCITATION_S:
        raise DataError("out of range", field="--duration", value=args.duration,
                        expected=f"0 < duration <= {MAX_EXCITATION_S:g} s")
    periods = args.duration / period
    if not math.isclose(periods, round(periods), abs_tol=1e-9):
        raise DataError("duration must be a whole number of periods", field="--duration",
                        value=args.duration,
                        expected=f"a positive multiple of 1/f0 = {period:g} s")
    bar = Progress("designing excitation", cfg.starts)
    res = design_excitation(robot, cfg, progress=bar)
    bar.close(f"cond = {res.condition_number:.1f}")
    samples = res.trajectory.at_rate(args.duration, 1000.0)
    save_trajectory(args.output, samples, robot.name,
                    {"condition_number": f"{res.condition_number:.6g}",
                     "harmonics": str(cfg.harmonics), "base_frequency": f"{cfg.base_frequency:g}"})
    out = {"robot": robot.name, "condition_number": res.condition_number,
           "start_conditions": list(res.start_conditions),
           "max_velocity_ratio": res.max_velocity_ratio,
           "max_acceleration_ratio": res.max_acceleration_ratio,
           "max_torque_ratio": res.max_torque_ratio, "min_tcp_height_m": res.min_tcp_height,
           "duration_s": args.duration, "runtime_s": res.runtime_s, "output": str(args.output)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"condition number {res.condition_number:.1f} (starts: "
              f"{', '.join(f'{c:.1f}' for c in res.start_conditions)}); max speed "
              f"{100 * res.max_velocity_ratio:.0f} %, acceleration "
              f"{100 * res.max_acceleration_ratio:.0f} %, torque {100 * res.max_torque_ratio:.0f} %"
              f" of limits; TCP >= {res.min_tcp_height:.2f} m; written to {args.output}")
    return 0


def run_record(args: argparse.Namespace) -> int:
    """Execute ``leadthrough record``."""
    check_output(args.output, (".csv", ".parquet", ".pq"), (("--trajectory", args.trajectory),))
    if args.driver is None:
        refuse_settings(args, ("host", "port", "approach"), "a robot setting given without a "
                        "driver (the recording would come from the simulator)",
                        "--driver D with it, or none of --host, --port, --approach")
    robot = load_robot(args.robot)
    traj, traj_robot = load_trajectory(args.trajectory)
    if traj_robot is not None and traj_robot != robot.name:
        raise DataError("trajectory was designed for another robot", source=args.trajectory,
                        field="robot", value=traj_robot, expected=f"'{robot.name}'")
    if traj.q.shape[1] != robot.n:
        raise DataError("joint count does not match the robot", source=args.trajectory,
                        field="q", value=traj.q.shape[1], expected=f"{robot.n}")
    check_trajectory_limits(args.trajectory, traj, robot)
    if args.driver is not None:
        return record_on_robot(args, robot, traj)
    args.seed = 0 if args.seed is None else args.seed
    args.plant = PLANT_NAMES[0] if args.plant is None else args.plant
    args.warm_up = 0.0 if args.warm_up is None else args.warm_up
    config = SimConfig(seed=args.seed, run=0 if args.run is None else args.run, plant=args.plant,
                       warm_up_s=warm_up_seconds(args.warm_up))
    t = np.arange(traj.time[0], traj.time[-1] + 0.5 * config.timestep, config.timestep)
    q_cmd = np.column_stack([np.interp(t, traj.time, traj.q[:, j]) for j in range(robot.n)])
    qd_cmd = np.column_stack([np.interp(t, traj.time, traj.qd[:, j]) for j in range(robot.n)])
    if args.payload_mass is None and args.payload_com is not None:
        raise DataError("a CoM without a mass", field="--payload-com", value=args.payload_com,
                        expected="--payload-com with --payload-mass")
    com = (0.0, 0.0, 0.05) if args.payload_com is None else tuple(args.payload_com)
    if args.payload_com is not None and not np.linalg.norm(com) <= MAX_PAYLOAD_COM_M:
        raise DataError("out of range", field="--payload-com", value=list(com),
                        expected=f"a CoM within {MAX_PAYLOAD_COM_M:g} m of the TCP")
    payload = None if args.payload_mass is None else Payload(args.payload_mass, com)
    if payload is not None:
        check_payload_torques(args.trajectory, traj, robot, payload.as_pin_inertia(),
                              "--payload-mass", args.payload_mass)
    sim = SimRobot(robot, config, payload=payload, q0=q_cmd[0])
    bar = Progress("recording", t.size)
    log = run_trajectory(sim, q_cmd, qd_cmd, progress=bar)
    bar.close()
    rec = Recording(time=log.time, q=log.q, current=log.current, q_cmd=log.q_cmd,
                    robot=robot.name, sim_seed=args.seed)
    save_recording(rec, args.output)
    out = {"robot": robot.name, "samples": rec.samples, "duration_s": rec.duration,
           "seed": args.seed, "run": config.run, "plant": args.plant, "warm_up_min": args.warm_up,
           "payload_mass_kg": args.payload_mass,
           "max_tracking_error_rad": float(np.max(np.abs(log.truth.q - q_cmd))),
           "output": str(args.output)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"recorded {rec.duration:.1f} s ({rec.samples} samples) to {args.output}")
    return 0

