"""``leadthrough recover PARTIAL -o SESSION``: a session cut short (``guide --driver`` killed,
SIGKILL or a crash of its process) written as a normal session file that ``teach`` reads
(:func:`~leadthrough.session.session_file.recover_session`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from leadthrough.session.session_file import SIDECAR_SUFFIX, recover_session

__all__ = ["register"]


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "recover", help="turn a session cut short (<session>.parquet.partial) into a session",
        description="A guiding session whose process was killed leaves its rows in "
                    "<session>.parquet.partial (closed by the session's writer process) and its "
                    f"metadata and events, marks included, in <session>.parquet.partial"
                    f"{SIDECAR_SUFFIX}. This joins them into a session file that reads like "
                    "one finished normally (teach, the plots); its settings note the recovery. "
                    "The partial files are removed once the session file is in place; nothing "
                    "is written when anything is wrong.",
        epilog="examples:\n  leadthrough recover session.parquet.partial -o session.parquet\n"
               "  leadthrough recover s.parquet.partial --robot er20 -o s.parquet   (its "
               f"{SIDECAR_SUFFIX} sidecar lost: no events)\n\nexit codes: 0 recovered; 2 "
               "nothing written (a partial file whose writer was killed too has no index and "
               "cannot be read; a malformed sidecar)",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("partial", type=Path, help="the <session>.parquet.partial file")
    p.add_argument("-o", "--output", type=Path, required=True, help="session .parquet")
    p.add_argument("--robot", default=None,
                   help="the session's robot (only needed when the sidecar is missing)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough recover``."""
    done = recover_session(args.partial, args.output, args.robot)
    out = {"session": str(done.path), "robot": done.robot, "rows": done.rows,
           "events": done.events, "marks": done.marks, "sidecar": done.sidecar,
           "dropped_last_line": done.dropped_line, "dropped_events": done.dropped_events}
    if done.dropped_events:
        print(f"leadthrough: warning: {len(done.dropped_events)} events after the last row "
              f"recovered dropped ({', '.join(done.dropped_events)}): the rows of their time "
              "were lost with the process", file=sys.stderr)
    if not done.sidecar:
        print(f"leadthrough: warning: no sidecar {args.partial}{SIDECAR_SUFFIX}: the session "
              "has its rows but no events (no marks)", file=sys.stderr)
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"recovered {done.rows} rows, {done.events} events ({done.marks} marks) of "
              f"{done.robot} -> {done.path}")
    return 0
