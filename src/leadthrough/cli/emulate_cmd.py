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
import gc
import math
import signal
import threading
from typing import Any

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
"""


def _window(text: str) -> Window:
    try:
        start, end = text.split(":")
        return Window(float(start), float(end) if end else math.inf)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}") from e


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
    p.add_argument("--seed", type=int, default=0, help="seeds the simulator and the faults")
    p.add_argument("--port", type=int, default=None,
                   help=f"listening port (J519, RTDE) or the client's (RSI); {DEFAULT_PORTS}")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (J519, RTDE) or the client's address (RSI)")
    p.add_argument("--cycle-ms", type=int, choices=(2, 4, 8, 12), default=None,
                   help="controller cycle (default: J519 8, RTDE 2 (CB3 8), RSI 4)")
    p.add_argument("--cb3", action="store_true", help="RTDE: a CB3 controller (125 Hz)")
    p.add_argument("--q0", type=float, nargs="+", metavar="RAD",
                   help="start pose, one value per joint in radians, within the robot file's "
                        "joint limits (default: the robot's neutral pose); for kuka-rsi, "
                        "where the KRL program moved the robot before RSI_ON")
    p.add_argument("--watchdog", type=float, default=None,
                   help="silence tolerated before the controller stops [s]")
    p.add_argument("--duration", type=float, default=None, help="stop after this long [s]")
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
    o.add_argument("--operator-seed", type=int, default=0,
                   help="seed of the operator's random pushes (random)")
    o.add_argument("--operator-delay", type=float, default=3.0, metavar="S",
                   help="from the stream's first command to the operator's start [s] "
                        "(default 3)")
    f = p.add_argument_group("faults")
    f.add_argument("--loss-rate", type=float, default=0.0, help="outgoing packets lost, 0..1")
    f.add_argument("--loss-burst", type=_window, action="append", default=[],
                   help="every outgoing packet lost in the window")
    f.add_argument("--late", type=_window, action="append", default=[],
                   help="outgoing packets leave --late-by late in the window")
    f.add_argument("--late-by", type=float, default=0.05, help="delay of late packets [s]")
    f.add_argument("--nan", type=_window, action="append", default=[],
                   help="reported joint positions are NaN in the window")
    f.add_argument("--close-at", type=float, default=None, help="close the sockets [s]")
    f.add_argument("--estop-at", type=float, default=None, help="emergency stop [s]")
    f.add_argument("--protective-stop-at", type=float, default=None,
                   help="protective stop [s]")
    p.set_defaults(func=run)


def _options(args: argparse.Namespace) -> EmulatorOptions:
    faults = FaultPlan(
        loss_rate=args.loss_rate, loss_bursts=tuple(args.loss_burst), late=tuple(args.late),
        late_by=args.late_by, close_at=args.close_at, nan_q=tuple(args.nan),
        estop_at=args.estop_at, protective_stop_at=args.protective_stop_at)
    return EmulatorOptions(
        host=args.host, cycle_ms=args.cycle_ms, watchdog=args.watchdog,
        inputs=InputSchedule(enable=tuple(args.enable), mark=tuple(args.mark),
                             reset=tuple(args.reset)), faults=faults,
        q0=tuple(args.q0) if args.q0 else None, generation="cb3" if args.cb3 else "e-series",
        operator=None if args.operator is None else OperatorPlan(
            args.operator, seed=args.operator_seed, delay_s=args.operator_delay))


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
    robot = load_robot(args.robot)
    check_start_pose(args.q0, robot)
    emulator = make_emulator(args.kind, robot, args.seed, args.port, _options(args))
    try:
        emulator.open()
    except OSError as e:
        raise SimulationError(f"cannot open the emulator's sockets: {e}", field="--port",
                              value=args.port if args.port is not None
                              else DEFAULT_PORTS[args.kind],
                              expected="a free port (or --port 0)") from e
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
