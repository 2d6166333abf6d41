"""Command-line interface: ``leadthrough <command> ...``.

Exit codes:

* 0: done; for ``guide`` and ``record``, a clean session (no fault latched in it).
* 1: an internal error; for ``guide`` and ``record``, also the link to the controller (it could
  not be reached, refused the stream, or was lost mid-session: a
  :class:`~leadthrough.errors.DriverError`, printed as one line).
* 2: bad input (a :class:`~leadthrough.errors.LeadthroughError`, printed as one line without a
  traceback); nothing was run or written.
* 3: ``guide`` and ``record``: a fault was latched during the session (a non-finite input, an
  E-stop or other controller state flag, stale feedback, a following error or limit), even one
  reset later in the session; the session file (``guide``) records it.
* 130: interrupted (Ctrl-C where it is not a session's normal end).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from typing import TextIO

from leadthrough import __version__
from leadthrough.cli import (
    calibration_cmds,
    demo_cmd,
    emulate_cmd,
    friction_refresh_cmd,
    guide_cmd,
    identify_cmd,
    payload_cmd,
    pendant_cmd,
    recover_cmd,
    robots_cmd,
    teach_cmd,
)
from leadthrough.errors import DataWarning, DriverError, LeadthroughError

__all__ = ["build_parser", "main"]

_EPILOG = """examples:
  leadthrough demo                      run the whole pipeline on the simulated ER20-class robot
  leadthrough robots                    list built-in robots with their base-parameter counts
  leadthrough robots --robot my.toml    check your own robot (URDF + drive TOML)
  leadthrough excite --robot er20 -o traj.csv
  leadthrough record --robot er20 --trajectory traj.csv -o rec.parquet
  leadthrough identify rec.parquet --robot er20 --method proposed -o params.toml
  leadthrough validate params.toml heldout.parquet --robot er20
  leadthrough payload loaded.parquet --robot er20 --params params.toml
  leadthrough drive-gains known.parquet --reference unloaded.parquet --params params.toml
      --mass 20 --com 0 0 0.08 -o gains.toml   drive gains from a known mass
  leadthrough payload loaded.parquet --params params.toml --reference unloaded.parquet
      --drive-gains gains.toml              a payload through them
  leadthrough guide --robot er20 --params params.toml --operator seam -o session.parquet
  leadthrough teach seam.parquet -o seam.json --csv seam.csv
  leadthrough emulate ur-rtde --robot ur5 --seed 1   an emulated controller on its real protocol
  leadthrough pendant                   the live browser pendant on the simulated robot
  leadthrough recover s.parquet.partial -o s.parquet   a session cut short (killed), readable

exit codes: 0 done (guide, record: a clean session); 1 internal error, or (guide, record) the
link to the controller failed; 2 bad input, nothing run; 3 (guide, record) a fault was latched
in the session, even one reset later; 130 interrupted
"""


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors with exit code 2 and one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with all subcommands."""
    parser = _Parser(
        prog="leadthrough",
        description="Sensorless hand guiding for industrial robots: identify the robot's "
                    "dynamics from motor currents, estimate the operator's force, and follow it.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"leadthrough {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    robots_cmd.register(sub)
    calibration_cmds.register(sub)
    identify_cmd.register(sub)
    friction_refresh_cmd.register(sub)
    payload_cmd.register(sub)
    guide_cmd.register(sub)
    teach_cmd.register(sub)
    recover_cmd.register(sub)
    pendant_cmd.register(sub)
    demo_cmd.register(sub)
    emulate_cmd.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    shown = warnings.showwarning

    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: TextIO | None = None, line: str | None = None) -> None:
        # warnings about the user's data as one line, without Python's source line
        if issubclass(category, DataWarning):
            print(f"leadthrough: warning: {message}", file=file if file is not None else sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        return int(args.func(args))
    except LeadthroughError as e:
        print(f"leadthrough: error: {e}", file=sys.stderr)
        # guide and record: the controller's link is not the input's fault (exit 1)
        return int(getattr(args, "link_error_exit", 2)) if isinstance(e, DriverError) else 2
    except KeyboardInterrupt:
        print("leadthrough: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown
