"""``leadthrough payload``: payload mass (and CoM) from a recording with the payload attached;
``leadthrough drive-gains``: the drives' gains and load friction from a run with a known mass
(:mod:`leadthrough.estimation.drive_gains`), for ``payload --drive-gains``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.data.io import load_recording
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError
from leadthrough.estimation.drive_gains import KnownPayload, estimate_drive_gains
from leadthrough.estimation.drive_gains_file import load_drive_gains, save_drive_gains
from leadthrough.estimation.payload import estimate_payload
from leadthrough.identification.params_file import ParamsFile, load_params
from leadthrough.robot.description import Robot, load_robot

__all__ = ["register"]

#: The option of each of ``KnownPayload``'s fields.
_KNOWN_PAYLOAD_OPTIONS = {"known_payload.mass_kg": "--mass", "known_payload.com_tcp": "--com",
                          "known_payload.inertia_com": "--inertia"}


def register(sub: Any) -> None:
    """Add the subcommands."""
    p = sub.add_parser(
        "payload", help="identify a payload with the unloaded robot's parameters",
        description="Estimate the payload at the flange from a recording made with it attached, "
                    "using parameters identified on the unloaded robot (paper Table III).",
        epilog="example: leadthrough payload loaded.parquet --robot er20 --params params.toml "
               "--reference unloaded.parquet --drive-gains gains.toml --json",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p, "a recording with the payload attached")
    p.add_argument("--reference", type=Path, default=None,
                   help="a recording of the same trajectory without the payload: the payload "
                        "is fitted to the difference of the two runs' residuals, which "
                        "cancels the model's own error along the path (motion only)")
    p.add_argument("--drive-gains", type=Path, default=None,
                   help="drive gains measured with a known mass (leadthrough drive-gains)")
    p.add_argument("--method", choices=("motion", "static"), default="motion",
                   help="during motion (default, the paper's) or from static poses")
    p.set_defaults(func=run)
    g = sub.add_parser(
        "drive-gains", help="measure the drives' gains with a known mass",
        description="Measure each drive's gain (true torque per torque read through the drive "
                    "file) and its gear's load friction from a run of a trajectory with a "
                    "known mass attached and a run of it without (Gautier and Briot, IROS "
                    "2011); payload --drive-gains uses them.",
        epilog="example: leadthrough drive-gains known.parquet --reference unloaded.parquet "
               "--robot er20 --params params.toml --mass 20 --com 0.05 0 0.15 -o gains.toml",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(g, "a recording with the known mass attached")
    g.add_argument("--reference", type=Path, required=True,
                   help="a recording of the same trajectory without the mass")
    g.add_argument("--mass", type=float, required=True, help="the known mass [kg]")
    g.add_argument("--com", type=float, nargs=3, default=(0.0, 0.0, 0.0),
                   metavar=("X", "Y", "Z"), help="its centre of mass in the TCP frame [m]")
    g.add_argument("--inertia", type=float, nargs=3, default=None,
                   metavar=("IXX", "IYY", "IZZ"),
                   help="its principal inertia about the CoM, TCP axes [kg·m²] (default: a "
                        "point mass)")
    g.add_argument("-o", "--output", type=Path, required=True, help="drive-gains TOML file")
    g.set_defaults(func=run_gains)


def _common(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("recording", type=Path, help=what)
    p.add_argument("--robot", default="er20")
    p.add_argument("--params", type=Path, required=True, help="params of the unloaded robot")
    p.add_argument("--columns", type=Path, default=None, help="column map for a raw log")
    p.add_argument("--json", action="store_true")


def _inputs(args: argparse.Namespace
            ) -> tuple[Robot, ParamsFile, Recording, Recording | None]:
    """The robot, the params, the recording and the reference, all of one simulated robot."""
    robot = load_robot(args.robot)
    pf = load_params(args.params, robot)
    rec = load_recording(args.recording, args.columns)
    rec.check_joint_range(robot)
    _same_simulated_robot(rec.sim_seed, pf.sim_seed, "recorded on another simulated robot than "
                          "the params were identified on", args.recording, "sim_seed",
                          "the params' [meta] sim_seed")
    reference = None
    if args.reference is not None:
        reference = load_recording(args.reference, args.columns)
        reference.check_joint_range(robot)
        _same_simulated_robot(reference.sim_seed, rec.sim_seed, "recorded on another simulated "
                              "robot than the payload's recording", args.reference, "sim_seed",
                              "the recording's sim_seed")
    return robot, pf, rec, reference


def _same_simulated_robot(seed: int | None, other: int | None, message: str, source: Path,
                          field: str, what: str) -> None:
    """Refuse ``source`` (its ``field`` = ``seed``) made on another simulated robot instance than
    ``other`` (``what``); a real robot's None matches anything."""
    if None not in (seed, other) and seed != other:
        raise DataError(message, source=source, field=field, value=seed,
                        expected=f"{other} ({what})")


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough payload``."""
    robot, pf, rec, reference = _inputs(args)
    gains = None
    if args.drive_gains is not None:
        gains, seed = load_drive_gains(args.drive_gains, robot)
        _same_simulated_robot(seed, rec.sim_seed, "drive gains of another simulated robot",
                              args.drive_gains, "meta.sim_seed", "the recording's sim_seed")
    est = estimate_payload(rec, robot, pf.params, args.method, reference=reference,
                           drive_gains=gains)
    out: dict[str, Any] = {"robot": robot.name, "method": est.method, "mass_kg": est.mass_kg,
                           "mass_std_kg": est.mass_std_kg, "weight_N": est.weight_n,
                           "samples": est.samples,
                           "reference": None if args.reference is None else str(args.reference),
                           "reference_shift_s": est.reference_shift_s,
                           "drive_gains": None if gains is None else str(args.drive_gains)}
    if est.com_tcp is not None:
        out["com_m"] = [float(v) for v in est.com_tcp]
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        com = "" if est.com_tcp is None else \
            " at CoM (" + ", ".join(f"{v:.3f}" for v in est.com_tcp) + ") m in the TCP frame"
        against = "" if est.reference_shift_s is None else \
            f", against {args.reference} (shifted {est.reference_shift_s:+.3f} s)"
        through = "" if gains is None else f", through the drive gains of {args.drive_gains}"
        print(f"payload {est.mass_kg:.3f} ± {est.mass_std_kg:.3f} kg ({est.weight_n:.2f} N)"
              f"{com}{against}{through}")
    return 0


def run_gains(args: argparse.Namespace) -> int:
    """Execute ``leadthrough drive-gains``."""
    inertia = None
    if args.inertia is not None:
        ixx, iyy, izz = (float(v) for v in args.inertia)
        inertia = ((ixx, 0.0, 0.0), (0.0, iyy, 0.0), (0.0, 0.0, izz))
    try:       # KnownPayload checks the values; the message names the option
        known = KnownPayload(args.mass, tuple(args.com), inertia)
    except DataError as e:
        flag = _KNOWN_PAYLOAD_OPTIONS.get(e.field or "", "--mass")
        value = list(args.inertia) if flag == "--inertia" else e.value
        raise DataError(e.message, field=flag, value=value, expected=e.expected) from e
    robot, pf, rec, reference = _inputs(args)
    if reference is None:
        raise DataError("a run without the mass is needed", field="--reference",
                        expected="a recording of the same trajectory without the mass")
    gains = estimate_drive_gains(rec, reference, robot, pf.params, known)
    save_drive_gains(args.output, robot, gains, rec.sim_seed)
    out = {"robot": robot.name, "output": str(args.output),
           "gain": [float(v) for v in gains.gain],
           "gain_std": [float(v) if np.isfinite(v) else None for v in gains.gain_std],
           "load_friction": [float(v) for v in gains.load_friction],
           "applied": [bool(v) for v in gains.applied],
           "reference_shift_s": gains.reference_shift_s}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for name, c, s, mu, a in zip(robot.joint_names, gains.gain, gains.gain_std,
                                     gains.load_friction, gains.applied, strict=True):
            state = (f"gain {c:.4f} ± {s:.4f}, load friction {mu:.4f}" if a
                     else "not loaded enough by the mass: the drive file's gain")
            print(f"{name}: {state}")
        print(f"wrote {args.output}")
    return 0
