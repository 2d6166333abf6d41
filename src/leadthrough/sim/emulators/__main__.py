"""``python -m leadthrough.sim.emulators {fanuc-j519,ur-rtde,kuka-rsi} --robot R --seed N
[--port P] [--host H] [--cycle-ms C] [--cb3]``: serve an emulated controller until Ctrl-C,
then print its report (the arguments the CLI's ``leadthrough emulate`` will take)."""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading

from leadthrough.errors import LeadthroughError
from leadthrough.sim.emulators.runner import DEFAULT_PORTS, EMULATORS, serve
from leadthrough.sim.emulators.scenario import EmulatorOptions


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments, serve, print the report; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m leadthrough.sim.emulators",
                                     description="Serve an emulated robot controller.")
    parser.add_argument("kind", choices=sorted(EMULATORS))
    parser.add_argument("--robot", default="er20", help="built-in name or robot TOML path")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--port", type=int, default=None,
                        help="listening port (J519, RTDE) or the client's port (RSI); "
                        f"defaults {DEFAULT_PORTS}")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (J519, RTDE) or the client's (RSI)")
    parser.add_argument("--cycle-ms", type=int, default=None)
    parser.add_argument("--cb3", action="store_true", help="RTDE: a CB3 controller (125 Hz)")
    args = parser.parse_args(argv)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    options = EmulatorOptions(host=args.host, cycle_ms=args.cycle_ms,
                              generation="cb3" if args.cb3 else "e-series")
    try:
        report = serve(args.kind, args.robot, args.seed, args.port, options, stop)
    except LeadthroughError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for key, value in dataclasses.asdict(report).items():
        print(f"{key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
