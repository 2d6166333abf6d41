"""``leadthrough emulate {fanuc-j519,ur-rtde,kuka-rsi} --robot R --seed N [--port P]``: an
emulated robot controller behind its real wire protocol, until Ctrl-C.

The simulated robot is stepped at 1 ms in real time behind the controller's cycle, watchdog,
limit checks, E-stop and protective stop (:mod:`leadthrough.sim.emulators`). Digital inputs
(enabling device, mark button) and faults are scripted with time windows ``START:END`` in
seconds since the start (``END`` may be ``inf``). One line ``leadthrough: emulating ...`` on
stdout says it is ready; on Ctrl-C (or SIGTERM) it prints its report: commands taken and
refused, executed targets that broke a limit (always none), why the arm stopped, and the
answers timed against the actual sends (``timing.*``:
:mod:`leadthrough.sim.emulators.answer_timing`).
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import gc
import math
import signal
import socket
import threading
from typing import Any, NamedTuple, NoReturn

from leadthrough.cli.arg_checks import MAX_DURATION_S, check_bindable
from leadthrough.errors import SimulationError
from leadthrough.robot import Robot, load_robot
from leadthrough.sim.emulators import (
    DEFAULT_PORTS,
    EMULATORS,
    EmulatorOptions,
    FaultPlan,
    InputSchedule,
    Window,
    make_emulator,
)
from leadthrough.sim.emulators.operator import OperatorPlan
from leadthrough.sim.operator_scripts import OPERATOR_NAMES

__all__ = ["register", "run"]

_EPILOG = """examples (two terminals):
  leadthrough emulate ur-rtde --robot ur5 --seed 1 --enable 2:inf
  leadthrough emulate fanuc-j519 --robot er20 --seed 1 --loss-rate 0.01 --estop-at 60
  leadthrough emulate kuka-rsi --robot er20 --seed 1 --port 49152   (sends to 127.0.0.1:49152)
ports: J519 60015 and RTDE 30004 (+ secondary interface 30002, where the servo URScript
program is sent) are listened on; the KUKA robot sends its RSI documents to --host:--port.
inputs: J519 DI[1] / UR DI0 / KUKA $IN[1] = enabling device, DI[2] / DI1 / $IN[2] = mark,
DI[3] / DI2 / $IN[3] = fault reset.
UR RTDE, as a real controller does for any client: input recipes numbered per connection
from 1, the guide's standard inputs (registers, speed slider, digital / analog outputs), input
packages taken before START, input registers readable as outputs; ur_rtde's RTDEIOInterface
works against it. No dashboard server (29999) and no URScript interpreter: ur_rtde's
RTDEControlInterface is not served. J519 status time stamps: milliseconds, 2 ms steps.
"""


_WINDOW_OPTIONS = ("enable", "mark", "reset", "loss_burst", "late", "nan")
_TIME_OPTIONS = ("close_at", "estop_at", "protective_stop_at")
#: The controller cycles [ms] of each kind (UR: e-Series; a CB3, ``--cb3``, runs 8 ms).
CYCLES_MS = {"fanuc-j519": (8, 4), "ur-rtde": (2,), "kuka-rsi": (4, 12)}


class _WindowArg(NamedTuple):
    """A window option as given: its text and its parsed ends (checked by :func:`_windows`)."""

    text: str
    start: float
    end: float


def _window(text: str) -> _WindowArg:
    """``START:END`` [s], ``END`` empty or ``inf`` for no end (its range: :func:`_windows`)."""
    try:
        start, end = text.split(":")
        return _WindowArg(text, float(start), float(end) if end.strip() else math.inf)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}") from e


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def _windows(given: list[_WindowArg], name: str) -> tuple[Window, ...]:
    """The windows of option ``name`` (its dest).

    Raises:
        SimulationError: Naming the option, the window as given and the expected range.
    """
    for w in given:
        if not (math.isfinite(w.start) and w.start >= 0.0 and w.end > w.start):
            raise SimulationError("bad time window", field=_option(name), value=w.text,
                                  expected="START:END in seconds since the start, "
                                           "0 <= START < END (END may be inf)")
    return tuple(Window(w.start, w.end) for w in given)


def _check_range(name: str, value: float | None, ok: bool, expected: str) -> None:
    if value is not None and not ok:
        raise SimulationError("out of range", field=_option(name), value=value,
                              expected=expected)


def _refuse(option: str, value: Any, message: str, expected: str) -> NoReturn:
    raise SimulationError(message, field=option, value=value, expected=expected)


def port_range(kind: str) -> tuple[frozenset[int], range, str]:
    """The ``--port`` values of ``kind``: the special ones, the range, both in words."""
    if kind == "kuka-rsi":
        return frozenset(), range(1, 65536), "1-65535 (the client's port)"
    if kind == "ur-rtde":
        return frozenset({0}), range(3, 65536), (
            "0 (free ports) or 3-65535 (the secondary interface listens on --port - 2)")
    return frozenset({0}), range(1, 65536), "0 (a free port) or 1-65535"


def check_arguments(args: argparse.Namespace) -> None:
    """Every argument of ``emulate`` that needs no robot and no network, before any work:
    ranges, and options that contradict each other or the controller kind.

    Raises:
        SimulationError: Naming the option(s), the value and what is expected (exit code 2).
    """
    kind = args.kind
    if args.port is not None:
        special, ports, words = port_range(kind)
        if args.port not in special and args.port not in ports:
            _refuse("--port", args.port, "out of range", f"{words} for {kind}")
    for name in ("seed", "operator_seed"):
        n = getattr(args, name)
        _check_range(name, n, n is not None and n >= 0, "an integer >= 0")
    d = args.duration
    _check_range("duration", d, d is not None and math.isfinite(d) and 0.0 < d <= MAX_DURATION_S,
                 f"finite, > 0 and <= {MAX_DURATION_S:g} s; omit it to run until Ctrl-C")
    w = args.watchdog
    _check_range("watchdog", w, w is not None and 0.0 < w <= 10.0, "0 < seconds <= 10")
    r = args.loss_rate
    _check_range("loss_rate", r, 0.0 <= r <= 1.0, "0 <= rate <= 1")
    b = args.late_by
    _check_range("late_by", b, b is not None and 0.0 <= b <= 1.0, "0 <= seconds <= 1")
    o = args.operator_delay
    _check_range("operator_delay", o, o is not None and 0.0 <= o <= 600.0,
                 "0 <= seconds <= 600")
    for name in _TIME_OPTIONS:
        t = getattr(args, name)
        _check_range(name, t, t is not None and math.isfinite(t) and t >= 0.0,
                     "finite seconds >= 0 since the start")
    for name in _WINDOW_OPTIONS:
        _windows(getattr(args, name), name)
    if args.cb3 and kind != "ur-rtde":
        _refuse("--cb3", True, f"--cb3 is a UR controller's generation, given for {kind}",
                "--cb3 only with ur-rtde")
    if args.cb3 and args.cycle_ms not in (None, 8):
        _refuse("--cycle-ms", args.cycle_ms, "a CB3 controller (--cb3) runs at 125 Hz",
                "--cycle-ms 8 or none with --cb3")
    if not args.cb3 and args.cycle_ms is not None and args.cycle_ms not in CYCLES_MS[kind]:
        cb3 = "; 8 with --cb3" if kind == "ur-rtde" else ""
        _refuse("--cycle-ms", args.cycle_ms, f"not a cycle of {kind}",
                " or ".join(map(str, CYCLES_MS[kind])) + f" ms for {kind}{cb3}")
    if args.late_by is not None and not args.late:
        _refuse("--late-by", args.late_by, "--late-by given without --late",
                "--late START:END with it, or no --late-by")
    if args.operator is None:
        for name in ("operator_seed", "operator_delay"):
            if getattr(args, name) is not None:
                _refuse(_option(name), getattr(args, name),
                        f"{_option(name)} given without --operator",
                        "--operator NAME with it, or no " + _option(name))


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "emulate", help="serve an emulated robot controller (J519, RTDE, RSI) until Ctrl-C",
        description="An emulated robot controller behind its real wire protocol: the simulated "
                    "robot stepped at 1 ms in real time behind the controller's cycle, "
                    "watchdog, limit checks, E-stop and protective stop, with scripted digital "
                    "inputs and faults (windows START:END in seconds since the start; END may "
                    "be inf). A line 'leadthrough: emulating ...' says it is ready; Ctrl-C "
                    "prints its report.", epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind", choices=sorted(EMULATORS))
    p.add_argument("--robot", default="er20", help="built-in name or robot TOML path (6 joints)")
    p.add_argument("--seed", type=int, default=0,
                   help="seeds the simulator and the faults (>= 0)")
    p.add_argument("--port", type=int, default=None,
                   help="listening port (J519, RTDE; 0: a free port; RTDE's secondary "
                        "interface listens on --port - 2) or the client's (RSI); "
                        f"{DEFAULT_PORTS}")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (J519, RTDE) or the client's address (RSI)")
    p.add_argument("--cycle-ms", type=int, choices=(2, 4, 8, 12), default=None,
                   help="controller cycle (J519 8 (default) or 4; RTDE 2, CB3 8; RSI 4 "
                        "(default) or 12)")
    p.add_argument("--cb3", action="store_true",
                   help="ur-rtde only: a CB3 controller (125 Hz: --cycle-ms 8)")
    p.add_argument("--q0", type=float, nargs="+", metavar="RAD",
                   help="start pose, one value per joint in radians, within the robot file's "
                        "joint limits (default: the robot's neutral pose); for kuka-rsi, "
                        "where the KRL program moved the robot before RSI_ON")
    p.add_argument("--watchdog", type=float, default=None,
                   help="silence tolerated before the controller stops [s] (0 < s <= 10)")
    p.add_argument("--duration", type=float, default=None,
                   help="stop after this long [s] (default: until Ctrl-C)")
    g = p.add_argument_group("digital inputs (windows START:END [s])")
    g.add_argument("--enable", type=_window, action="append", default=[],
                   help="enabling device held")
    g.add_argument("--mark", type=_window, action="append", default=[],
                   help="mark button pressed")
    g.add_argument("--reset", type=_window, action="append", default=[],
                   help="fault reset button pressed")
    o = p.add_argument_group("an operator at the robot")
    o.add_argument("--operator", default=None, choices=OPERATOR_NAMES,
                   help="a scripted operator who holds the enabling device, pushes the tool "
                        "and presses the mark button, starting --operator-delay after the "
                        "stream's first command")
    o.add_argument("--operator-seed", type=int, default=None,
                   help="with --operator: seed of the operator's random pushes (random; "
                        "default 0)")
    o.add_argument("--operator-delay", type=float, default=None, metavar="S",
                   help="with --operator: from the stream's first command to the operator's "
                        "start [s] (default 3)")
    f = p.add_argument_group("faults")
    f.add_argument("--loss-rate", type=float, default=0.0, help="outgoing packets lost, 0..1")
    f.add_argument("--loss-burst", type=_window, action="append", default=[],
                   help="every outgoing packet lost in the window")
    f.add_argument("--late", type=_window, action="append", default=[],
                   help="outgoing packets leave --late-by late in the window")
    f.add_argument("--late-by", type=float, default=None,
                   help="with --late: delay of late packets [s] (0..1, default 0.05)")
    f.add_argument("--nan", type=_window, action="append", default=[],
                   help="reported joint positions are NaN in the window")
    f.add_argument("--close-at", type=float, default=None, help="close the sockets [s]")
    f.add_argument("--estop-at", type=float, default=None, help="emergency stop [s]")
    f.add_argument("--protective-stop-at", type=float, default=None,
                   help="protective stop [s]")
    p.set_defaults(func=run)


def _options(args: argparse.Namespace) -> EmulatorOptions:
    faults = FaultPlan(
        loss_rate=args.loss_rate, loss_bursts=_windows(args.loss_burst, "loss_burst"),
        late=_windows(args.late, "late"),
        late_by=0.05 if args.late_by is None else args.late_by, close_at=args.close_at,
        nan_q=_windows(args.nan, "nan"), estop_at=args.estop_at,
        protective_stop_at=args.protective_stop_at)
    return EmulatorOptions(
        host=args.host, cycle_ms=args.cycle_ms, watchdog=args.watchdog,
        inputs=InputSchedule(enable=_windows(args.enable, "enable"),
                             mark=_windows(args.mark, "mark"),
                             reset=_windows(args.reset, "reset")), faults=faults,
        q0=tuple(args.q0) if args.q0 else None, generation="cb3" if args.cb3 else "e-series",
        operator=None if args.operator is None else OperatorPlan(
            args.operator, seed=args.operator_seed or 0,
            delay_s=3.0 if args.operator_delay is None else args.operator_delay))


def check_start_pose(q0: list[float] | None, robot: Robot) -> None:
    """``--q0``: one finite value per joint [rad], each within the robot file's limits.

    Raises:
        SimulationError: Naming ``--q0``, the value and the expected range (exit code 2).
    """
    if q0 is None:
        return
    if len(q0) != robot.n or not all(math.isfinite(x) for x in q0):
        raise SimulationError("bad start pose", field="--q0", value=q0,
                              expected=f"{robot.n} finite joint positions [rad] "
                                       f"({robot.name})")
    for j, x in enumerate(q0):
        lo, hi = float(robot.lower_limits[j]), float(robot.upper_limits[j])
        if not lo <= x <= hi:
            raise SimulationError(f"start pose outside joint {j + 1}'s limits",
                                  field=f"--q0 (joint {j + 1})", value=x,
                                  expected=f"{lo:.4g} .. {hi:.4g} rad ({robot.name}; "
                                           "--q0 is in radians)")


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough emulate``."""
    check_arguments(args)
    # every emulator binds its IPv4 UDP or TCP sockets to --host
    check_bindable(args.host, "--host", family=socket.AF_INET, kind=socket.SOCK_DGRAM)
    robot = load_robot(args.robot)
    check_start_pose(args.q0, robot)
    emulator = make_emulator(args.kind, robot, args.seed, args.port, _options(args))
    try:
        emulator.open()
    except OSError as e:
        if isinstance(e, socket.gaierror) or e.errno == errno.EADDRNOTAVAIL:
            raise SimulationError(f"cannot bind it: {e.strerror or e}", field="--host",
                                  value=args.host,
                                  expected="an address of this machine") from e
        secondary = (" and --port - 2 (the secondary interface)" if args.kind == "ur-rtde"
                     else "")
        raise SimulationError(f"cannot open the emulator's sockets: {e.strerror or e}",
                              field="--port",
                              value=args.port if args.port is not None
                              else DEFAULT_PORTS[args.kind],
                              expected=f"a free port{secondary} (or --port 0)") from e
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if args.duration is not None:
        threading.Timer(args.duration, stop.set).start()
    where = "sending to" if args.kind == "kuka-rsi" else "listening on"
    extra = (f", secondary interface {args.host}:{emulator.script_port}"  # type: ignore[attr-defined]
             if args.kind == "ur-rtde" else "")
    print(f"leadthrough: emulating {args.kind} ({emulator.robot.name}, seed {args.seed}) "
          f"{where} {args.host}:{emulator.port}{extra}; Ctrl-C to stop", flush=True)
    # the objects of the set-up (MuJoCo, Pinocchio, NumPy, ...) out of the collector's sight:
    # its full passes over them would stall the 1 ms loop by tens of milliseconds
    gc.collect()
    gc.freeze()
    report = emulator.run(stop)
    for key, value in dataclasses.asdict(report).items():
        for name, item in (value.items() if isinstance(value, dict) else [("", value)]):
            print(f"{key}{'.' if name else ''}{name}: {item}")  # timing.late: ...
    return 0
