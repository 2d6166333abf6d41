"""``leadthrough excite --sweep``, ``excite --friction-check`` and ``excite --presliding``: the
friction experiments, designed around one configuration (the guiding start pose or
``--start``)."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.excitation.friction_sweep import (
    FRICTION_CHECK,
    FrictionSweepConfig,
    design_friction_sweep,
)
from leadthrough.excitation.presliding import PreslidingTestConfig, design_presliding_test
from leadthrough.excitation.trajectory_file import save_trajectory
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose

__all__ = ["excite_friction_experiment"]


def _start(args: argparse.Namespace, robot: Robot) -> NDArray[np.float64]:
    q0 = guide_start_pose(robot) if args.start is None else np.array(args.start, dtype=float)
    if q0.shape != (robot.n,):
        raise DataError("wrong number of joint positions", field="--start", value=args.start,
                        expected=f"{robot.n} values [rad]")
    return q0


def excite_friction_experiment(args: argparse.Namespace, robot: Robot) -> int:
    """Design the experiment ``args`` asks for (``--sweep`` or ``--presliding``), write it to
    ``args.output`` and report it (``--json``: one object).

    Raises:
        DataError: Both experiments asked for, or a bad ``--start``.
    """
    given = [name for name, on in (("--sweep", args.sweep), ("--presliding", args.presliding),
                                    ("--friction-check", args.friction_check)) if on]
    if len(given) > 1:
        raise DataError("choose one of the friction experiments", field=" and ".join(given),
                        value=True,
                        expected="--sweep or --presliding or --friction-check, one of them")
    q0 = _start(args, robot)
    out: dict[str, Any] = {"robot": robot.name}
    if args.sweep or args.friction_check:
        kind = "friction check" if args.friction_check else "friction sweep"
        layout = FRICTION_CHECK if args.friction_check else FrictionSweepConfig()
        sweep = design_friction_sweep(robot, q0, layout)
        samples, meta = sweep.samples, {"kind": kind,
                                        "speeds": " ".join(f"{v:g}" for v in layout.speeds)}
        out |= {"kind": kind, "duration_s": sweep.duration_s,
                "speeds_rad_s": sweep.speeds.tolist()}
        text = (f"{kind}: {sweep.speeds.shape[0]} speeds out and back, "
                f"{sweep.duration_s:.1f} s")
    else:
        config = PreslidingTestConfig()
        test = design_presliding_test(robot, q0, config)
        samples, meta = test.samples, {"kind": "presliding test",
                                       "amplitudes": " ".join(f"{a:g}"
                                                              for a in config.amplitudes)}
        out |= {"kind": "presliding test", "duration_s": test.duration_s,
                "amplitudes_rad": list(config.amplitudes), "trials": int(test.amplitude.size)}
        text = (f"presliding test: {test.amplitude.size} excursions out and back at rest, "
                f"{test.duration_s:.1f} s")
    save_trajectory(args.output, samples, robot.name, meta)
    out |= {"q_start": q0.tolist(), "output": str(args.output)}
    print(json.dumps(out, indent=2) if args.json else f"{text}; written to {args.output}")
    return 0
