"""``leadthrough guide --driver D --host H [--port P] --params P --enable-input I
--mark-input I``: hand guiding a robot through its controller's streaming interface (issue 25),
until the user stops it.

1. Optional real-time set-up (:mod:`leadthrough.session.realtime`), each step reported.
2. Set-up before the link opens: the estimator, controller and interpolator are built and
   their compiled code loaded (compiled on a first run) with a progress line; then the
   controller is connected (``with driver``: joint count, units and the stream checked
   at open: a mismatch, a refused stream or no answer is a clear error, exit 2).
3. The loop (:func:`~leadthrough.session.loop.run_session`) at the controller's cycle, the
   guiding controller at the multiple of it nearest 10 ms; guiding only on a fresh press of the
   enabling input; marks from the mark input; a fault reset from the reset input
   (``--reset-input``: a fresh press, once the fault's cause has cleared and the robot is at
   rest; guiding then needs a fresh press of the enabling device); the recording streamed
   to ``-o`` in chunks (:class:`~leadthrough.session.session_file.SessionFileSink`).
4. Ctrl-C (SIGINT) or SIGTERM: a stop request (a commanded stop at the acceleration limit, the
   loop ends at rest), then the driver closes the stream; a second Ctrl-C aborts.

Exit (:data:`~leadthrough.cli.record_robot.EXIT_OK` ...): 0 when the session ended on the
user's stop (or ``--duration``) and no fault was latched in it; 1 when it ended on a lost link
or a stop that did not come to rest, or the controller could not be reached or refused the
stream (a :class:`~leadthrough.errors.DriverError`); 2 for bad input (nothing run); 3 when a
fault was latched during the session (a non-finite input, a controller state flag such as an
E-stop, stale feedback, a limit...), even one reset from the reset input later: the session is
not a clean one. The recording is written either way, with the causes in its events.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np

from leadthrough.cli.arg_checks import check_rt_priority
from leadthrough.cli.record_robot import (
    EXIT_FAULT,
    EXIT_LINK,
    EXIT_OK,
    add_connection_arguments,
    refuse_settings,
)
from leadthrough.control.guiding_types import GuidingConfig
from leadthrough.drivers.controllers import connect
from leadthrough.errors import ControlError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.progress import Progress
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import REALTIME_NOTE, EndCause, LoopResult, run_session
from leadthrough.session.loop_config import (
    LoopConfig,
    LoopOptions,
    LoopParts,
    build_loop,
    controller_cycle,
    warm_up_parts,
)
from leadthrough.session.realtime import RealtimeRequest
from leadthrough.session.requests import LoopRequests
from leadthrough.session.session_file import SessionFileSink
from leadthrough.session_format import SessionEvent

__all__ = ["DEFAULT_WATCHDOG_S", "add_input_arguments", "add_robot_arguments", "guide_on_robot",
           "latched_faults", "loop_options", "require_enable_input"]

_SIM_ONLY = ("operator", "seed", "operator_seed", "run")
#: ``--watchdog``'s default [s].
DEFAULT_WATCHDOG_S = 0.05
#: CPU numbers ``--cpus`` takes: Linux's default CPU mask size (``sched_setaffinity(2)``); a
#: CPU in range that this machine lacks is the OS's refusal, reported as the loop starts.
MAX_CPUS = 1024


def add_robot_arguments(p: argparse.ArgumentParser) -> None:
    """``--driver``, ``--host``, ``--port``, ``--enable-input``, ``--mark-input`` and the
    real-time options."""
    g = p.add_argument_group("on a robot controller")
    add_connection_arguments(g)
    add_input_arguments(g)
    g.add_argument("--rt-priority", type=int, default=None, metavar="P",
                   help="run the loop with SCHED_FIFO priority P (1-99; needs CAP_SYS_NICE)")
    g.add_argument("--lock-memory", action="store_true", default=None,
                   help="mlockall the process (no page faults in the loop)")
    g.add_argument("--cpus", type=int, nargs="+", default=None, metavar="CPU",
                   help="run on these CPUs only")


def add_input_arguments(g: Any) -> None:
    """``--enable-input``, ``--mark-input``, ``--reset-input`` and ``--watchdog`` (into an
    argument group or parser): the controller's inputs and the loop's watchdog, read by
    :func:`loop_options`."""
    g.add_argument("--enable-input", type=int, default=None, metavar="I",
                   help="the controller's digital input wired to the enabling device (bit I "
                        "of the driver's inputs: J519 DI[1+I], UR DI I, KUKA $IN[1+I]); "
                        "required with --driver")
    g.add_argument("--mark-input", type=int, default=None, metavar="I",
                   help="the digital input of the 'mark point' button")
    g.add_argument("--reset-input", type=int, default=None, metavar="I",
                   help="the digital input of the fault reset button: a fresh press resets a "
                        "latched fault once its cause has cleared and the robot is at rest "
                        "(then press the enabling device again to guide)")
    g.add_argument("--watchdog", type=float, default=None, metavar="S",
                   help="a driver exchange longer than this is a fault (a commanded stop) "
                        "[s]; one blocked over max(1 s, S) is aborted (default 0.05)")


def require_enable_input(args: argparse.Namespace) -> None:
    """A robot is guided only with its enabling device: ``--enable-input`` given.

    Raises:
        ControlError: Naming ``--enable-input`` (exit code 2).
    """
    if args.enable_input is None:
        raise ControlError("no enabling device: a robot is guided only while its enabling "
                           "device is pressed", field="--enable-input", value=None,
                           expected="the controller's digital input wired to the enabling "
                                    "device")


def loop_options(args: argparse.Namespace,
                 realtime: RealtimeRequest | None = None) -> LoopOptions:
    """The loop's options from :func:`add_input_arguments`' options (``--watchdog`` default
    :data:`DEFAULT_WATCHDOG_S`; an exchange blocked over max(1 s, watchdog) is aborted).

    Raises:
        ControlError: Two options on one input, or a watchdog not finite and > 0 (exit
            code 2).
    """
    watchdog = DEFAULT_WATCHDOG_S if args.watchdog is None else args.watchdog
    return LoopOptions(enable_input=args.enable_input, mark_input=args.mark_input,
                       reset_input=args.reset_input, watchdog_s=watchdog,
                       abort_s=max(1.0, watchdog),
                       realtime=RealtimeRequest() if realtime is None else realtime)


def guide_on_robot(args: argparse.Namespace, robot: Robot, pf: ParamsFile,
                   guiding: GuidingConfig) -> int:
    """Run ``leadthrough guide --driver`` (see the module doc)."""
    _check_args(args)
    # the inputs checked before anything is built (a clash of two inputs: exit 2 at once)
    options = loop_options(args, RealtimeRequest(args.rt_priority, bool(args.lock_memory),
                                                 tuple(args.cpus) if args.cpus else None))
    # the session writer's process first: started after the real-time set-up (the loop's,
    # as it starts), it would inherit the loop's CPUs and SCHED_FIFO (it leaves the policy
    # itself, not the CPUs), and its shared chunks are mapped before mlockall; closed on every
    # way out
    settings: dict[str, object] = {"driver": args.driver, "host": args.host,
                                   "port": args.port, "enable_input": args.enable_input,
                                   "mark_input": args.mark_input,
                                   "reset_input": args.reset_input}
    with SessionFileSink(args.output, robot.n, robot=robot.name, settings=settings) as sink:
        driver = connect(args.driver, robot, args.host, args.port,
                         getattr(args, "robot_address", None))
        # everything built and compiled before the link opens: a controller streams from the
        # open on, and cycles it is not answered in count against the session (RSI's late count)
        parts = _loop_parts(robot, pf, guiding, driver.dt)
        requests = LoopRequests()
        dt = driver.dt
        # Ctrl-C: a stop request while the loop runs, and nothing more once it has ended (the
        # stream's own end and the file are written); a second one aborts
        with requests.stop_on_interrupt(), _stop_on_term(requests), driver:
            if driver.dt != dt:    # the cycle the controller reported at open (UR CB3: 8 ms)
                parts = _loop_parts(robot, pf, guiding, driver.dt)
            print(f"leadthrough: guiding {robot.name} on {args.driver} at {args.host} "
                  f"({1e3 * driver.dt:g} ms cycle, controller every "
                  f"{1e3 * parts.controller.config.dt:g} ms); press the enabling device to "
                  f"guide, Ctrl-C to stop", file=sys.stderr, flush=True)
            result = run_session(driver, *parts, args.duration, options=options,
                                 requests=requests, settings=settings, sink=sink)
    for event in sink.events:
        if event.kind == "loop" and event.label == REALTIME_NOTE:
            print(f"leadthrough: {event.cause}", file=sys.stderr, flush=True)
    return _report(args, result, getattr(driver, "late_answers", 0),
                   latched_faults(sink.events))


def _check_args(args: argparse.Namespace) -> None:
    refuse_settings(args, _SIM_ONLY, "a simulator setting given for a robot",
                    "no simulator settings with --driver")
    if args.realtime:
        raise ControlError("a simulator setting given for a robot", field="--realtime",
                           value=True, expected="none: the controller paces the loop")
    require_enable_input(args)
    check_rt_priority(args.rt_priority)
    bad_cpus = [c for c in args.cpus or () if not 0 <= c < MAX_CPUS]
    if bad_cpus:
        raise ControlError("out of range", field="--cpus", value=bad_cpus[0],
                           expected=f"CPU numbers 0..{MAX_CPUS - 1} (this machine has "
                                    f"{os.cpu_count()})")


def _loop_parts(robot: Robot, pf: ParamsFile, guiding: GuidingConfig, dt: float) -> LoopParts:
    """The loop's parts at servo period ``dt``, their compiled code loaded (compiled on a first
    run, with a progress line) on copies of their state: the first controller cycle runs at
    full speed."""
    bar = Progress("compiling the loop", 4, lines=True)
    parts = build_loop(robot, pf, LoopConfig(guiding=replace(
        guiding, dt=controller_cycle(dt))), dt)
    bar(1)
    warm_up_parts(parts, guide_start_pose(robot), lambda k: bar(k + 1))
    bar.close()
    return parts


@contextmanager
def _stop_on_term(requests: LoopRequests) -> Iterator[None]:
    """SIGTERM requests a stop too (a service manager's stop)."""
    previous = signal.signal(signal.SIGTERM, lambda *_: requests.stop())
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def latched_faults(events: list[SessionEvent]) -> list[str]:
    """The faults latched during a session, in order, each once (the names of
    :class:`~leadthrough.control.safety_states.Fault` that its transitions carry as
    ``cause:FAULT``)."""
    return list(dict.fromkeys(e.cause.split(":", 1)[1] for e in events
                              if e.kind == "transition" and ":" in e.cause))


def _report(args: argparse.Namespace, result: LoopResult, late_answers: int,
            faults: list[str]) -> int:
    """The session's summary and exit code (``late_answers``: answers the controller counted
    late; ``faults``: those latched during the session)."""
    end, us = result.end, result.cycle_us
    p99 = float(np.percentile(us, 99)) if us.size else math.nan
    # the first controller cycle against the steady state (the kept cycles: the last ten
    # minutes at most, so the first is only there in a session that short)
    first = float(us[0]) if us.size and result.cycles == us.size else math.nan
    out: dict[str, Any] = {
        "end": str(end.cause), "end_detail": end.detail, "t_end_s": end.t,
        "state": end.state.name, "fault": end.fault.name,
        "late_periods": result.late_periods, "late_answers": late_answers,
        "periods": result.periods,
        "cycle_us_first": first, "cycle_us_median": float(np.median(us)) if us.size
        else math.nan, "cycle_us_p99": p99, "cycle_us_max": float(us.max()) if us.size
        else math.nan, "faults": faults, "output": str(args.output)}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"session ended: {end.cause}{' (' + end.detail + ')' if end.detail else ''}; "
              f"state {end.state.name}, fault {end.fault.name}; {result.late_periods} late "
              f"periods, {late_answers} answers late; controller cycle p99 "
              f"{out['cycle_us_p99']:.0f} µs -> {args.output}")
    if end.cause not in (EndCause.STOP_REQUESTED, EndCause.DURATION):
        return EXIT_LINK
    if faults or end.fault.name != "NONE":
        print(f"leadthrough: a fault was latched in the session "
              f"({', '.join(faults or [end.fault.name])}): exit code {EXIT_FAULT}",
              file=sys.stderr, flush=True)
        return EXIT_FAULT
    return EXIT_OK
