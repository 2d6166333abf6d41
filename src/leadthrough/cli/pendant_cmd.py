"""``leadthrough pendant``: the live browser pendant on the simulated robot or on a robot."""

from __future__ import annotations

import argparse
import math
import os
import signal
import socket
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn

from leadthrough.cli.arg_checks import (
    MAX_DURATION_S,
    check_bindable,
    check_rt_priority,
    require_sweep,
)
from leadthrough.cli.guide_robot import add_input_arguments, loop_options, require_enable_input
from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.hand_release import HandReleaseConfig
from leadthrough.drivers.controllers import CONTROLLERS, DEFAULT_PORTS
from leadthrough.errors import ControlError, DataError, MissingPackageError
from leadthrough.identification.params_file import load_params
from leadthrough.pendant.access import (
    DEFAULT_MAX_CLIENTS,
    MAX_CLIENTS_LIMIT,
    MAX_MESSAGE_BYTES,
    is_loopback,
    read_token_file,
)
from leadthrough.pendant.backend import LiveSession
from leadthrough.pendant.loop_process import DriverRecipe
from leadthrough.robot.description import Robot, load_robot
from leadthrough.session.loop_config import LoopOptions

__all__ = ["check_access", "check_address", "check_arguments", "check_export_folder",
           "check_robot_arguments", "register", "remote_warning"]

#: The robot session's options that are the simulator's only.
_SIM_ONLY = ("seed", "hand_release")
#: The options of a robot session only.
_ROBOT_ONLY = ("host", "controller_port", "robot_address", "enable_input", "mark_input",
               "reset_input", "watchdog")

#: The page's port without ``--port`` (the next free one if taken; with ``--port``: that one).
DEFAULT_PORT = 8080
_PORT_EXPECTED = (f"a free port; or --port 0 for any free one, or no --port for {DEFAULT_PORT} "
                  "or the next free one")
#: Longest ``--record-s`` [s]: the recording is kept in shared memory, about 50 MB per 100 s.
MAX_RECORD_S = 3600.0
#: Suffixes of files, not folders: an ``-o`` with one is a file name given for the folder.
_FILE_SUFFIXES = (".parquet", ".pq", ".csv", ".json", ".toml", ".txt", ".urdf", ".yaml",
                  ".yml", ".npz", ".html", ".md", ".png", ".script", ".src", ".dat", ".ls",
                  ".mod")

_DESCRIPTION = """\
Serve the live pendant: a web page for the person at the robot (a tablet's browser) with the
robot in 3D, its TCP path, the estimated force, the speed and the safety state in large type,
and the operator's actions: arm guiding, mark P1 / P2 / waypoints, clear a fault, switch frame
and axes, set the virtual mass and friction within the controller's operator limits, edit the
taught points, and export (session.parquet, points.json, path.json / path.csv).

One page controls (the first to press "Take control"); every other page is read-only, and a
page asking for control gets it when the page in control confirms or disconnects. Labels are
1-32 letters, digits, '_', '-', '.' or spaces; a bad label, a number that is not finite or
out of range is refused to that page and never reaches the loop. Exports: one at a time,
5 s apart, at most 50 a run.

On the simulator (the default) the page also provides the enabling device, hold-to-run:
pressed only while held (released on letting go, on the page losing focus, or 200 ms
without its heartbeat), and lets you push the tool with the mouse: drag the handle at the
tool; the force (10 N per cm, at most 80 N)
goes into the simulated robot, the estimator sees it only through the motor currents, and the
robot follows. The guiding loop runs in its own process; the page never holds it up.

On a robot (--driver {drivers} --host H --params P --enable-input I) the loop is the
one `leadthrough guide --driver` runs, with its faults (the link, stale feedback, the
controller's own state such as an E-stop, the watchdog: each a commanded stop, shown on the
page with its cause): the enabling device is the controller's input I, wired to the robot's
own enabling switch, and guiding starts only on a fresh press of it (the page cannot enable
guiding); --mark-input marks P1, P2 ... from a button, --reset-input clears a fault from one
(the page's "Clear fault" does too). The controller's port is --controller-port (--port is
the page's). Stopping the pendant (Ctrl-C) brings the robot to rest, then ends the stream.

Access: the page's URL carries a secret token, new on every run (or the one in
--token-file), printed on the terminal: open that URL. Every request without the token, or
whose Host or Origin is not the served address (another site's page in the browser, a
DNS-rebinding name), is refused (403) and logged. At most --max-clients pages are connected
at once (default {clients}; another is refused, 503), and a message from a page larger than
{kb} kB closes that page's connection only.

The page is served on 127.0.0.1 only (this machine). Serving it to the network (a tablet:
--bind 0.0.0.0 or an address of this machine) needs --allow-remote: anyone on the network who
has the URL can then move the robot, and the page travels unencrypted (http), so anyone who
can read the network's traffic can read the token.
"""


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser("pendant", help="live browser pendant (simulator or robot)",
                       description=_DESCRIPTION.format(clients=DEFAULT_MAX_CLIENTS,
                                                       kb=MAX_MESSAGE_BYTES // 1024,
                                                       drivers="{" + ",".join(
                                                           sorted(CONTROLLERS)) + "}"),
                       epilog="examples:\n  leadthrough pendant\n"
                              "  leadthrough pendant --bind 0.0.0.0 --allow-remote --port 8080 "
                              "-o taught\n"
                              "  leadthrough pendant --params params_guiding.toml\n"
                              "  leadthrough pendant --driver ur-rtde --host 192.168.0.10 "
                              "--params params_guiding.toml --enable-input 0 --mark-input 1",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    where = p.add_mutually_exclusive_group()
    where.add_argument("--sim", action="store_true",
                       help="the simulated robot (the default)")
    where.add_argument("--driver", default=None, choices=sorted(CONTROLLERS),
                       help="a real controller's streaming interface (needs --host, --params "
                            "and --enable-input)")
    g = p.add_argument_group("on a robot controller")
    g.add_argument("--host", default=None, metavar="H",
                   help="the controller's address (kuka-rsi: this PC's address to listen on)")
    g.add_argument("--controller-port", type=int, default=None, metavar="P",
                   help="the controller interface's port (default: its own: " + ", ".join(
                       f"{DEFAULT_PORTS[d]} {d}" for d in sorted(DEFAULT_PORTS)) + "); "
                        "--port is the page's")
    g.add_argument("--robot-address", default=None, metavar="HOST[:PORT]",
                   help="kuka-rsi: the robot's address (and port): documents from any other "
                        "sender are dropped (default: the first valid document's sender)")
    add_input_arguments(g)
    p.add_argument("--robot", default="er20", help="robot (default: er20)")
    p.add_argument("--params", type=Path, default=None,
                   help="identified parameters (required on a robot; default on the "
                        "simulator: the shipped identification of the simulated er20)")
    p.add_argument("--seed", type=int, default=None,
                   help="simulated robot instance, >= 0 (default: the parameters' own)")
    p.add_argument("--allow-no-sweep", action="store_true",
                   help="guide with --params identified without a friction sweep (refused "
                        "otherwise, as by `guide`: their friction is 15-24 %% low at guiding "
                        "speeds, which reads as a 20-50 N force against the motion)")
    p.add_argument("--bind", default="127.0.0.1",
                   help="address of this machine to serve the page on (default 127.0.0.1; "
                        "any other needs --allow-remote)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a --bind other than this machine's loopback address: anyone on "
                        "the network with the URL can then move the robot, over unencrypted "
                        "http")
    p.add_argument("--token-file", type=Path, default=None, metavar="F",
                   help="the URL's token from file F (one line of 32-128 characters A-Z a-z "
                        "0-9 _ -; default: a new random token on every run)")
    p.add_argument("--max-clients", type=int, default=DEFAULT_MAX_CLIENTS, metavar="N",
                   help=f"pages connected at once, 1-{MAX_CLIENTS_LIMIT} (default "
                        f"{DEFAULT_MAX_CLIENTS}); another is refused")
    p.add_argument("--port", type=int, default=None,
                   help=f"the page's port, 1-65535, refused if in use; 0: any free port "
                        f"(default: "
                        f"{DEFAULT_PORT}, or the next free one if taken)")
    p.add_argument("-o", "--output", type=Path, default=Path("leadthrough-pendant"),
                   help="folder of the exports, made on the first export if missing (its "
                        "parent must exist); each export goes into a new OUT/export-NNN "
                        "(default: leadthrough-pendant)")
    p.add_argument("--record-s", type=float, default=600.0, metavar="S",
                   help=f"seconds of the session kept for the export, 0 < S <= "
                        f"{MAX_RECORD_S:g} (default 600)")
    p.add_argument("--rt-priority", type=int, default=None, metavar="P",
                   help="run the loop's process under SCHED_FIFO at priority P (1-99; Linux, "
                        "needs root or CAP_SYS_NICE); see the README on the loop's isolation")
    p.add_argument("--hand-release", action="store_true",
                   help="on the simulator: stop at the acceleration limit when the hand lets go "
                        "of the tool, whatever the force estimate says, as `guide "
                        "--hand-release` (off by default: it brakes a hand that eases off; "
                        "without it the paper's law may move the tool again at rest after a "
                        "release)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds, finite and > 0 (default: run until Ctrl-C)")
    p.set_defaults(func=run)


def _refuse(option: str, value: object, message: str, expected: str) -> NoReturn:
    raise DataError(message, field=option, value=value, expected=expected)


def check_arguments(args: argparse.Namespace) -> None:
    """Every argument of ``pendant`` that needs no robot and no network, before any work.

    Raises:
        DataError, ControlError: Naming the option, the value and the expected range (exit
            code 2).
    """
    if args.port is not None and not 0 <= args.port <= 65535:
        _refuse("--port", args.port, "out of range",
                f"1-65535, or 0 for any free port; omit it for {DEFAULT_PORT} or the next free one")
    d = args.duration
    if d is not None and not (math.isfinite(d) and 0.0 < d <= MAX_DURATION_S):
        _refuse("--duration", d, "out of range",
                f"finite, > 0 and <= {MAX_DURATION_S:g} s; omit it to run until Ctrl-C")
    r = args.record_s
    if not (math.isfinite(r) and 0.0 < r <= MAX_RECORD_S):
        _refuse("--record-s", r, "out of range", f"0 < seconds <= {MAX_RECORD_S:g}")
    if args.seed is not None and args.seed < 0:
        _refuse("--seed", args.seed, "out of range", "an integer >= 0")
    check_rt_priority(args.rt_priority)
    check_export_folder(args.output)
    if not 1 <= args.max_clients <= MAX_CLIENTS_LIMIT:
        _refuse("--max-clients", args.max_clients, "out of range",
                f"an integer 1-{MAX_CLIENTS_LIMIT}")
    check_access(args.bind, args.allow_remote)
    if args.driver is None:
        for name in _ROBOT_ONLY:
            if getattr(args, name) is not None:
                option = f"--{name.replace('_', '-')}"
                raise ControlError(f"{option} is a setting of a robot session",
                                   field=option, value=getattr(args, name),
                                   expected=f"--driver {{{','.join(sorted(CONTROLLERS))}}} "
                                            f"--host H ... {option} ..., or no {option} on "
                                            "the simulator (the page is its enabling device)")
    args.options = None if args.driver is None else check_robot_arguments(args)
    args.token = None if args.token_file is None else read_token_file(args.token_file)


def check_robot_arguments(args: argparse.Namespace) -> LoopOptions:
    """The options of a robot session (``--driver``) that need no network: ``--host`` and
    ``--params`` given, ``--enable-input`` (as ``guide --driver``), no simulator setting, the
    inputs, the watchdog and the controller's port; returns the loop's options.

    Raises:
        ControlError: Naming the option, the value and what is expected (exit code 2).
    """
    for name in _SIM_ONLY:
        value = getattr(args, name)
        if value not in (None, False):
            option = f"--{name.replace('_', '-')}"
            raise ControlError(f"{option} is a setting of the simulated session",
                               field=option, value=value,
                               expected=f"no {option} with --driver" + (
                                   "; on a robot: leadthrough guide --driver D --hand-release"
                                   if name == "hand_release" else ""))
    if args.host is None:
        raise ControlError("a robot needs its controller's address", field="--host",
                           value=None, expected="--host H: the controller's address "
                                                "(kuka-rsi: this PC's address to listen on)")
    if args.params is None:
        raise ControlError("a robot needs its identified parameters", field="--params",
                           value=None, expected="--params params_guiding.toml (leadthrough "
                                                "identify on this robot)")
    require_enable_input(args)
    port = args.controller_port
    lowest = 0 if args.driver == "kuka-rsi" else 1    # the PC listens: 0 takes a free port
    if port is not None and not lowest <= port <= 65535:
        raise ControlError("out of range", field="--controller-port", value=port,
                           expected=f"{lowest}-65535, or no --controller-port for "
                                    f"{DEFAULT_PORTS[args.driver]}")
    if args.robot_address is not None and args.driver != "kuka-rsi":
        raise ControlError("only for kuka-rsi", field="--robot-address",
                           value=args.robot_address,
                           expected=f"no --robot-address with --driver {args.driver} (it "
                                    "connects to --host)")
    return loop_options(args)


def check_access(bind: str, allow_remote: bool) -> None:
    """``--bind``: an address of this machine (:func:`~leadthrough.cli.arg_checks.
    check_bindable`), and a loopback one unless ``--allow-remote``.

    Raises:
        DataError: Naming ``--bind``, the value and why (exit code 2).
    """
    check_bindable(bind, "--bind")
    if not allow_remote and not is_loopback(bind):
        _refuse("--bind", bind, "serves the page to the network, where anyone who has its URL "
                "can move the robot", "127.0.0.1 (this machine only), or add --allow-remote "
                "to serve it to the network (unencrypted http)")


def remote_warning(bind: str, port: int, token: str = "<token>") -> str | None:
    """What the command says on start when the page is served beyond this machine (None on
    loopback): who can move the robot, and the page's URL for another machine (on all
    addresses: by this machine's name)."""
    if is_loopback(bind):
        return None
    host = bind.strip("[]")
    if host in ("0.0.0.0", "::"):
        host = socket.gethostname()
    elif ":" in host:
        host = f"[{host}]"
    return (f"WARNING: the pendant is served to the network on {bind}:{port}: anyone on the "
            "network who has the URL can move the robot, and the page travels unencrypted "
            "(http), so anyone who can read the network's traffic can read the token. Stop it "
            f"(Ctrl-C) unless this network is trusted. From another machine: "
            f"http://{host}:{port}/{token}/")


def check_export_folder(out: Path) -> None:
    """``-o``: the exports' folder (made on the first export): an existing, writable folder,
    or a new one (not a file's name) in an existing, writable folder.

    Raises:
        DataError: Naming ``-o``, the path and what is expected.
    """
    given = str(out)
    if out.exists() and not out.is_dir():
        _refuse("-o", given, "not a folder (an existing file)",
                "a folder for the exports (each goes into OUT/export-NNN), e.g. -o taught")
    if not out.exists() and out.suffix.lower() in _FILE_SUFFIXES:
        _refuse("-o", given, f"a file name ({out.suffix}) given for the exports' folder",
                "a folder for the exports (each goes into OUT/export-NNN), e.g. -o taught")
    parent = out.parent if str(out.parent) else Path(".")
    if not out.exists() and not parent.is_dir():
        _refuse("-o", given, "its parent folder does not exist",
                f"a folder whose parent exists ({parent} does not)")
    where = out if out.exists() else parent
    if not os.access(where, os.W_OK | os.X_OK):
        _refuse("-o", given, f"{where} is not writable", "a writable folder")


def check_address(bind: str, port: int | None) -> None:
    """``--bind`` and an explicit ``--port`` (:func:`~leadthrough.cli.arg_checks.
    check_bindable`: the page's server listens there).

    Raises:
        DataError: Naming ``--bind`` or ``--port``, the value and why (exit code 2).
    """
    check_bindable(bind, "--bind", port=port, port_expected=_PORT_EXPECTED)


def _robot_session(args: argparse.Namespace, robot: Robot) -> tuple[LiveSession, str]:
    """A live session on a real controller through the same backend as the simulator's: the
    loop of ``guide --driver`` (:class:`~leadthrough.pendant.loop_process.DriverRecipe`)."""
    params = require_sweep(load_params(args.params, robot), args.allow_no_sweep)
    options = args.options if getattr(args, "options", None) is not None else (
        check_robot_arguments(args))
    recipe = DriverRecipe(robot, params, args.driver, args.host, port=args.controller_port,
                          robot_address=args.robot_address, options=options)
    return (LiveSession(recipe, robot, record_s=args.record_s, rt_priority=args.rt_priority),
            f"{args.params} ({params.method}); {args.driver} at {args.host}, enabling input "
            f"{options.enable_input}")


def _sessions(args: argparse.Namespace, robot: Robot, simulated_session: Any
              ) -> tuple[LiveSession, Any, str]:
    """The live session (not started), the simulated hand (None on a robot) and the
    parameters' note."""
    if args.driver is not None:
        live, note = _robot_session(args, robot)
        return live, None, note
    params = None if args.params is None else require_sweep(load_params(args.params, robot),
                                                            args.allow_no_sweep)
    guiding = None
    if args.hand_release:
        # (simulated_session sets the push demonstrations' translational mass on it)
        guiding = replace(GuidingConfig(), hand_release=HandReleaseConfig(enabled=True))
    sim = simulated_session(robot, params, seed=args.seed, record_s=args.record_s,
                            guiding=guiding, rt_priority=args.rt_priority)
    return sim.live, sim.hand, sim.params_note


def _serve(pendant_class: Any, live: LiveSession, hand: Any, note: str,
           args: argparse.Namespace) -> Any:
    """The pendant's page (a ``pendant_class``), served on ``--bind``: on ``--port`` exactly
    if given."""
    port = DEFAULT_PORT if args.port is None else args.port
    pendant = pendant_class(live, args.output, hand=hand, bind=args.bind, port=port,
                            params_note=note, token=getattr(args, "token", None),
                            allow_remote=args.allow_remote, max_clients=args.max_clients)
    if args.port not in (None, 0) and pendant.server.get_port() != args.port:
        pendant.stop()    # taken between the check and the start: viser moved on
        raise DataError(f"port in use on {args.bind}", field="--port", value=args.port,
                        expected=_PORT_EXPECTED)
    return pendant


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough pendant``."""
    check_arguments(args)
    try:  # the web stack is an extra: the rest of the CLI works without it
        from leadthrough.pendant.app import Pendant
        from leadthrough.pendant.simulated import simulated_session
    except ImportError as e:
        raise MissingPackageError(f"the pendant's web stack is not installed ({e.name})",
                                  field="extra", value="pendant",
                                  expected="pip install 'leadthrough[pendant]'") from e
    robot = load_robot(args.robot)
    live, hand, note = _sessions(args, robot, simulated_session)
    try:
        check_address(args.bind, args.port)     # just before the start: viser would hang
        print("starting the loop in its own process ...", flush=True)
        live.start(progress=lambda step: print(f"  {step} ...", flush=True))
        pendant = _serve(Pendant, live, hand, note, args)
        pendant.start()
        print(f"pendant: {pendant.url}  (exports to {args.output}; Ctrl-C stops)", flush=True)
        warning = remote_warning(args.bind, pendant.server.get_port(), pendant.gate.token)
        if warning is not None:
            print(warning, flush=True)
        done = threading.Event()
        signal.signal(signal.SIGINT, lambda *_: done.set())
        signal.signal(signal.SIGTERM, lambda *_: done.set())
        deadline = None if args.duration is None else time.monotonic() + args.duration
        while not done.wait(0.2):
            if deadline is not None and time.monotonic() >= deadline:
                break
            if not live.running:
                break
        pendant.stop()
        live.stop()
        snap = live.snapshot()
    finally:
        live.close()
    if snap is not None and snap.error not in (None, "stopped"):
        print(f"the loop stopped: {snap.error}")
        return 1
    return 0
