"""Calibration commands, the model's side: ``identify`` (a recording → a params file, with a
friction sweep, a presliding test and the command lag where the recording has them) and
``validate`` (params on a held-out recording)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from leadthrough.cli.arg_checks import check_not_input, check_output
from leadthrough.data.io import load_recording
from leadthrough.data.preprocess import PreprocessConfig
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError
from leadthrough.fileio import require_folder
from leadthrough.identification.api import METHODS, IdentifyConfig, evaluate
from leadthrough.identification.calibration import calibrate
from leadthrough.identification.consistency import min_pseudo_inertia_eigenvalues
from leadthrough.identification.consistent import ConsistentConfig
from leadthrough.identification.metrics import ResidualStats
from leadthrough.identification.params_file import load_params
from leadthrough.identification.presliding import PreslidingFit
from leadthrough.identification.proposed import ProposedConfig
from leadthrough.progress import Progress
from leadthrough.robot.description import Robot, load_robot
from leadthrough.robot.urdf_export import write_urdf_with_inertias

__all__ = ["register", "stats_json"]

_RAW = argparse.RawDescriptionHelpFormatter


def register(sub: Any) -> None:
    """Add ``identify`` and ``validate``."""
    for add in (_register_identify, _register_validate):
        add(sub)


def _register_identify(sub: Any) -> None:
    p = sub.add_parser("identify", help="calibrate the dynamic model from a recording",
                       formatter_class=_RAW,
                       description="Identify link, friction and rotor parameters from an "
                                   f"excitation recording. Methods: {', '.join(METHODS)}.",
                       epilog="example: leadthrough identify rec.parquet --robot er20 "
                              "--method proposed -o params.toml --json")
    p.add_argument("recording", type=Path)
    p.add_argument("--robot", default="er20")
    p.add_argument("--method", choices=METHODS, default="proposed")
    p.add_argument("--columns", type=Path, default=None, help="column map for a raw log")
    # not given: absent (argparse.SUPPRESS), so that a method that does not use one refuses it
    p.add_argument("--seed", type=int, default=argparse.SUPPRESS,
                   help="seed of the proposed search (default 0; proposed only)")
    p.add_argument("--bound", type=_bound, default=argparse.SUPPRESS,
                   help="bounds around the URDF values for proposed/consistent, as a fraction "
                        "(default 0.3 = ±30 %%, the paper's) or 'none' (consistent only)")
    _preprocess_args(p)
    p.add_argument("--friction-sweep", type=Path, default=None, metavar="REC",
                   help="recording of a friction sweep (excite --sweep, then record): the "
                        "friction curve is measured from it (consistent method only)")
    p.add_argument("--load-friction", action=argparse.BooleanOptionalAction,
                   default=IdentifyConfig.load_friction,
                   help="also identify the load-dependent Coulomb friction f_cL (level "
                        "f_c0 + f_cL·|τ_load|; ols-cv, ols-cbrt and consistent without a sweep)")
    p.add_argument("--presliding-test", type=Path, default=None, metavar="REC",
                   help="recording of a presliding test (excite --presliding, then record): "
                        "each joint's presliding length z0 is measured from it and written to "
                        "the params (the estimator's friction at rest)")
    p.add_argument("-o", "--output", type=Path, required=True, help="params TOML")
    p.add_argument("--urdf-out", type=Path, default=None,
                   help="also write the URDF with the identified link inertias")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_identify)


def _register_validate(sub: Any) -> None:
    p = sub.add_parser("validate", help="check identified parameters on a held-out recording",
                       formatter_class=_RAW,
                       description="J, per-joint mean/std and relative torque error of a params "
                                   "file on a recording.",
                       epilog="example: leadthrough validate params.toml heldout.parquet "
                              "--robot er20 --json")
    p.add_argument("params", type=Path)
    p.add_argument("recording", type=Path)
    p.add_argument("--robot", default="er20")
    p.add_argument("--columns", type=Path, default=None)
    _preprocess_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_validate)


def _preprocess_args(p: argparse.ArgumentParser) -> None:
    d = PreprocessConfig()
    p.add_argument("--cutoff", type=float, default=d.position_cutoff_hz,
                   help=f"low-pass cut-off for q and torque [Hz] (default {d.position_cutoff_hz})")
    p.add_argument("--standstill", type=float, default=d.standstill_velocity,
                   help="drop joint samples slower than this [rad/s] "
                        f"(default {d.standstill_velocity})")


def _bound(text: str) -> float | None:
    """Parse --bound: a fraction in (0, 1) or 'none'."""
    if text.strip().lower() == "none":
        return None
    try:
        value = float(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number or 'none'") from e
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"{value} is outside (0, 1)")
    return value


def _identify_config(args: argparse.Namespace) -> IdentifyConfig:
    pre = PreprocessConfig(position_cutoff_hz=args.cutoff, torque_cutoff_hz=args.cutoff,
                           standstill_velocity=args.standstill)
    bound = getattr(args, "bound", 0.3)
    if bound is None and getattr(args, "method", "") == "proposed":
        raise DataError("the paper's method needs finite bounds", field="--bound", value="none",
                        expected="a fraction in (0, 1)")
    proposed = ProposedConfig(seed=getattr(args, "seed", 0),
                              bound=bound if bound is not None else 0.3)
    return IdentifyConfig(preprocess=pre, proposed=proposed,
                          consistent=ConsistentConfig(bound=bound),
                          load_friction=getattr(args, "load_friction",
                                                IdentifyConfig.load_friction))


def stats_json(robot: Robot, stats: ResidualStats) -> dict[str, Any]:
    """Residual statistics as JSON-ready dict."""
    return {
        "J": stats.J,
        "rel_error_pct": stats.rel_error_pct,
        "per_joint": [
            {"joint": jn, "mean": float(stats.mean[k]), "std": float(stats.std[k]),
             "std_pct_max": float(stats.std_pct_max[k]), "rms": float(stats.rms[k])}
            for k, jn in enumerate(robot.joint_names)
        ],
    }


def _print_stats(robot: Robot, stats: ResidualStats, title: str) -> None:
    print(title)
    print(f"  {'joint':<22} {'mean [N·m]':>11} {'std [N·m]':>10} {'std/max [%]':>12}")
    for k, jn in enumerate(robot.joint_names):
        print(f"  {jn:<22} {stats.mean[k]:>11.3f} {stats.std[k]:>10.3f} "
              f"{stats.std_pct_max[k]:>12.2f}")
    print(f"  J = {stats.J:.3f} N·m, relative torque error {stats.rel_error_pct:.2f} %")


def _load(args: argparse.Namespace, robot: Robot) -> Recording:
    rec = load_recording(args.recording, args.columns)
    rec.check_joint_range(robot)
    return rec


#: Longest excitation recording ``excite`` writes [s] (an hour at 1 kHz: 3.6 M rows).
def _check_method_options(args: argparse.Namespace) -> None:
    """Refuse ``--seed`` and ``--bound`` given for a method that does not use them."""
    for option, users in (("seed", ("proposed",)), ("bound", ("proposed", "consistent"))):
        if hasattr(args, option) and args.method not in users:
            raise DataError(f"--{option} is not used by the {args.method} method",
                            field=f"--{option}", value=getattr(args, option),
                            expected=f"--{option} only with --method {' or '.join(users)}")


def run_identify(args: argparse.Namespace) -> int:
    """Execute ``leadthrough identify``."""
    if args.friction_sweep is not None and args.method != "consistent":
        raise DataError("a friction sweep is used by the consistent method only",
                        field="--method", value=args.method,
                        expected="'consistent' with --friction-sweep")
    inputs = (("the recording", args.recording), ("--columns", args.columns),
              ("--friction-sweep", args.friction_sweep),
              ("--presliding-test", args.presliding_test))
    check_output(args.output, (".toml",), inputs)
    _check_method_options(args)
    if args.urdf_out is not None:
        # checked before the identification, so that nothing is written if it cannot be
        if Path(args.urdf_out).suffix.lower() != ".urdf":
            raise DataError("unsupported output file type", source=args.urdf_out,
                            field="--urdf-out", value=Path(args.urdf_out).suffix or "(none)",
                            expected=".urdf")
        require_folder(args.urdf_out)
        check_not_input(args.urdf_out, "--urdf-out", inputs)
        if Path(args.urdf_out).resolve() == Path(args.output).resolve():
            raise DataError("the URDF would overwrite the params file", field="--urdf-out",
                            value=str(args.urdf_out), expected="a path other than -o")
    robot = load_robot(args.robot)
    rec = _load(args, robot)
    sim_seed = rec.sim_seed
    sweep = _companion(args, "friction_sweep", rec, robot)
    presliding_test = _companion(args, "presliding_test", rec, robot)
    bar = Progress(f"identifying ({args.method})", 1)
    cal = calibrate(rec, robot, args.method, _identify_config(args), friction_sweep=sweep,
                    presliding_test=presliding_test, progress=bar)
    result, pre, lag = cal.result, cal.presliding, cal.command_lag
    bar.close(f"J = {result.J:.3f}")
    cal.save(args.output, robot, sim_seed)
    if args.urdf_out is not None:
        write_urdf_with_inertias(robot, result.params.phi, args.urdf_out)
    eig = {jn: float(v) for jn, v in zip(robot.joint_names, result.min_pseudo_inertia_eig,
                                         strict=True)}
    if args.json:
        out = {"method": result.method, "robot": robot.name, **stats_json(robot, result.stats),
               "runtime_s": result.runtime_s, "iterations": result.iterations,
               "samples": result.samples, "output": str(args.output),
               "parameters": [p._asdict() for p in result.named_parameters(robot)]}
        if args.method == "consistent":
            out["min_pseudo_inertia_eig"] = eig
        if pre is not None:
            out["presliding"] = _presliding_json(robot, pre)
        if lag is not None:
            out["command_lag_s"] = lag.lag_s
        print(json.dumps(out, indent=2))
    else:
        _print_stats(robot, result.stats, f"{args.method} on {args.recording} "
                                          f"({result.runtime_s:.1f} s, {result.iterations} it.)")
        print("  min pseudo-inertia eigenvalue per link [kg·m²]: "
              + ", ".join(f"{v:.3g}" for v in eig.values()))
        if pre is not None:
            print(f"  presliding test ({pre.pairs.first.size} rest pairs): z0 [1e-4 rad] "
                  + ", ".join(f"{1e4 * z:.2f}" for z in pre.presliding)
                  + "; relaxation at rest [1/s] "
                  + ", ".join(f"{r:.3f}" for r in pre.relaxation)
                  + "; level at rest [N·m] " + ", ".join(f"{g:.3g}" for g in pre.level))
        if lag is not None:
            print(f"  command lag {1e3 * lag.lag_s:.1f} ms (the recording's commands to its "
                  f"positions; sampled every {1e3 * lag.period_s:.1f} ms)")
        print(f"parameters written to {args.output}"
              + (f", URDF to {args.urdf_out}" if args.urdf_out is not None else ""))
    return 0


def _companion(args: argparse.Namespace, name: str, rec: Recording, robot: Robot
               ) -> Recording | None:
    """The recording of option ``--name`` (a friction experiment), checked to come from the
    same robot as the identification recording ``rec``."""
    path = getattr(args, name)
    if path is None:
        return None
    other = load_recording(path, args.columns)
    other.check_joint_range(robot)
    if other.sim_seed != rec.sim_seed:
        raise DataError("recorded on another robot than the identification data", source=path,
                        field="sim_seed", value=other.sim_seed,
                        expected=f"{rec.sim_seed} (that of {args.recording})")
    return other


def _presliding_json(robot: Robot, fit: PreslidingFit) -> dict[str, Any]:
    """The presliding fit per joint, for --json."""
    joints = {jn: {"z0_rad": float(fit.presliding[k]),
                   "z0_std_rad": float(fit.presliding_std[k]),
                   "relaxation_per_s": float(fit.relaxation[k]),
                   "relaxation_std_per_s": float(fit.relaxation_std[k]),
                   "level_Nm": float(fit.level[k]), "rms_Nm": float(fit.rms[k])}
              for k, jn in enumerate(robot.joint_names)}
    return {"pairs": int(fit.pairs.first.size), "joints": joints}


def run_validate(args: argparse.Namespace) -> int:
    """Execute ``leadthrough validate``."""
    import time

    robot = load_robot(args.robot)
    pf = load_params(args.params, robot)
    rec = _load(args, robot)
    t0 = time.perf_counter()
    stats = evaluate(pf.params, robot, rec, _identify_config(args))
    eig = min_pseudo_inertia_eigenvalues(pf.params.phi)
    if args.json:
        print(json.dumps({"method": pf.method, "robot": robot.name, **stats_json(robot, stats),
                          "min_pseudo_inertia_eig": dict(zip(robot.joint_names,
                                                             map(float, eig), strict=True)),
                          "runtime_s": time.perf_counter() - t0}, indent=2))
    else:
        _print_stats(robot, stats, f"{pf.method} parameters on {args.recording}")
    return 0
