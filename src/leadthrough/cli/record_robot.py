"""``leadthrough record --driver D --host H [--port P]``: a trajectory run on a robot controller,
logged in the same recording format as the simulator's (see
:mod:`leadthrough.session.trajectory_recording`).

The exit codes of ``record`` and ``guide`` (:data:`EXIT_OK` ...): 0 a clean session, 1 the link to
the controller failed (cannot connect, refused, lost mid-session) or an internal error, 2 bad
input (nothing run), 3 a fault stopped the run or was latched in the session (a non-finite
sample, an E-stop, a following error, ...; a fault reset later in the session counts too),
130 interrupted (``record``: no recording is written).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.data.io import save_recording
from leadthrough.drivers.controllers import CONTROLLERS, connect
from leadthrough.drivers.kuka_rsi.driver import KukaRsiDriver
from leadthrough.errors import ControlError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.progress import Progress
from leadthrough.robot.description import Robot
from leadthrough.session.trajectory_recording import (
    TrajectoryAbortedError,
    TrajectoryRunConfig,
    record_trajectory,
)

__all__ = ["EXIT_BAD_INPUT", "EXIT_CODES_HELP", "EXIT_FAULT", "EXIT_INTERRUPTED", "EXIT_LINK",
           "EXIT_OK", "add_connection_arguments", "add_driver_arguments", "check_rsi_reach",
           "record_on_robot", "refuse_settings"]

#: A clean session.
EXIT_OK = 0
#: The link to the controller failed (cannot connect, refused, lost), or an internal error.
EXIT_LINK = 1
#: Bad input: nothing was run (a LeadthroughError other than the link's).
EXIT_BAD_INPUT = 2
#: A fault stopped the run or was latched during the session (even if reset later).
EXIT_FAULT = 3
#: Interrupted by the user (Ctrl-C) where that is not the normal end.
EXIT_INTERRUPTED = 130
#: The exit codes in words, for the commands' help.
EXIT_CODES_HELP = (
    "exit codes: 0 a clean session; 1 the link to the controller failed (cannot connect, "
    "refused, lost) or an internal error; 2 bad input, nothing run; 3 a fault was latched (a "
    "non-finite sample, an E-stop, a following error, stale feedback...: the session "
    "file records it; a fault reset later counts too); 130 interrupted")

_SIM_ONLY = ("seed", "run", "plant", "warm_up", "payload_mass", "payload_com")


#: ``--approach``'s default: share of the joint limits for the move to the start.
DEFAULT_APPROACH = 0.1


def add_driver_arguments(p: argparse.ArgumentParser) -> None:
    """``--driver``, ``--host``, ``--port`` and ``--approach``."""
    g = p.add_argument_group("on a robot controller")
    add_connection_arguments(g)
    g.add_argument("--approach", type=float, default=None, metavar="F",
                   help="share of the joint speed and acceleration limits for the move to the "
                        "trajectory's start (0: the robot must already be there; default 0.1)")


def refuse_settings(args: argparse.Namespace, names: tuple[str, ...], message: str,
                    expected: str) -> None:
    """Raise :class:`ControlError` naming the first of ``names`` given (not None)."""
    for name in names:
        if getattr(args, name) is not None:
            raise ControlError(message, field=f"--{name.replace('_', '-')}",
                               value=getattr(args, name), expected=expected)


def check_rsi_reach(driver: KukaRsiDriver, traj: TrajectorySamples, source: Path) -> None:
    """Every sample of ``traj`` within RSI's correction range from where RSI started
    (:meth:`KukaRsiDriver.reach`); the approach's straight joint path from there to the first
    sample then is too.

    Raises:
        ControlError: Naming the first sample and axis out of range (exit code 2), before
            the robot moves.
    """
    lo, hi = driver.reach()
    out = (traj.q < lo) | (traj.q > hi)
    if not out.any():
        return
    row, j = (int(x) for x in np.argwhere(out)[0])
    start = (driver.client.reference or (float("nan"),) * 6)[j]
    q = np.degrees(traj.q[:, j])
    span, reach = float(np.ptp(q)), float(np.degrees(hi[j] - lo[j]))
    advice = (f"the trajectory spans {span:.1f} deg on A{j + 1}, more than that range: no "
              "start pose reaches all of it" if span > reach else
              "let the KRL program move the robot before RSI_ON to a pose from which all of "
              f"it is in reach (the trajectory's start, or the middle of its A{j + 1} range, "
              f"{(q.min() + q.max()) / 2:.1f} deg)")
    raise ControlError(
        f"the trajectory leaves RSI's correction range in row {row}: RSI corrects A{j + 1} "
        f"only within {np.degrees(lo[j]):.1f} .. {np.degrees(hi[j]):.1f} deg (the shipped "
        f"context's range from where RSI started, {start:.1f} deg); {advice}", source=source,
        field=f"q{j + 1}", value=round(float(q[row]), 2),
        expected=f"{np.degrees(lo[j]):.1f} .. {np.degrees(hi[j]):.1f} deg")


def aborted_exit_code(e: TrajectoryAbortedError) -> int:
    """The exit code of a run that stopped early: :data:`EXIT_INTERRUPTED` for Ctrl-C (the
    stop made inside its handling), :data:`EXIT_LINK` for a controller that went silent or
    never sent a first sample, :data:`EXIT_FAULT` for every other commanded stop (a controller
    state flag such as an E-stop, a non-finite sample, a following error, commands not
    taken, cycles without a command)."""
    if isinstance(e.__context__, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if not e.message.startswith("stopped during") or "no fresh sample" in e.message:
        return EXIT_LINK
    return EXIT_FAULT


def add_connection_arguments(g: Any) -> None:
    """``--driver``, ``--host`` and ``--port`` (into an argument group or parser)."""
    g.add_argument("--driver", default=None, choices=sorted(CONTROLLERS),
                   help="the controller's interface (default: the simulated robot)")
    g.add_argument("--host", default=None,
                   help="the controller's address (kuka-rsi: this PC's address to listen on)")
    g.add_argument("--port", type=int, default=None,
                   help="the interface's port (default: its own: 60015, 30004, 49152)")
    g.add_argument("--robot-address", default=None, metavar="HOST[:PORT]",
                   help="kuka-rsi: the robot's address (and port): documents from any other "
                   "sender are dropped (default: the first valid document's sender is taken "
                   "for the robot; give this on a shared network or computer)")


def record_on_robot(args: argparse.Namespace, robot: Robot, traj: TrajectorySamples) -> int:
    """Run ``traj`` on the controller of ``args.driver`` and write the recording."""
    refuse_settings(args, _SIM_ONLY, "a simulator setting given for a robot",
                    "no simulator settings with --driver")
    config = TrajectoryRunConfig(approach_fraction=DEFAULT_APPROACH if args.approach is None
                                 else args.approach)
    driver = connect(args.driver, robot, args.host, args.port,
                     getattr(args, "robot_address", None))
    bar = Progress(f"recording on {args.driver} at {args.host}", 1, lines=True)
    try:
        with driver:
            if isinstance(driver, KukaRsiDriver):  # before any motion
                check_rsi_reach(driver, traj, args.trajectory)
            done = record_trajectory(driver, robot, traj, config, progress=bar)
    except TrajectoryAbortedError as e:
        code = aborted_exit_code(e)
        if code == EXIT_LINK:
            raise
        bar.close()
        print(f"leadthrough: error: {e}", file=sys.stderr)
        return code
    bar.close()
    save_recording(done.recording, args.output)
    rec = done.recording
    out: dict[str, Any] = {
        "robot": robot.name, "driver": args.driver, "samples": rec.samples,
        "duration_s": rec.duration, "cycle_s": driver.dt, "approach_s": done.approach_s,
        "stale_cycles": done.stale, "signal": "current" if rec.current is not None else "torque",
        "max_following_error_rad": done.max_following_error, "output": str(args.output)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"recorded {rec.duration:.1f} s ({rec.samples} samples at "
              f"{1e3 * driver.dt:g} ms, {done.stale} cycles stale, following error "
              f"<= {np.degrees(done.max_following_error):.3f}°) to {args.output}")
    return 0
