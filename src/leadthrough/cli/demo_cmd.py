"""``leadthrough demo``: the whole paper on the built-in simulated robot, in one command.

On the simulated ER20-class robot with a fixed seed it runs, showing progress:
1. the excitation trajectory design (after checking the dynamic model and the simulator);
2. its recording, and a held-out one, at 1 kHz;
3. calibration with all methods: Table II and Fig. 3;
4. the payload test: Table III;
5. guiding sessions with both controllers: Fig. 4 and Fig. 5;
6. a welding-seam session taught and exported: Fig. 6, path.json and path.csv.
It prints a short summary and writes a report folder (default ./leadthrough-report):
report.html (self-contained), report.md, summary.json, table2.md, the params files, the
recordings, the guiding sessions and the exported path.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

from leadthrough.demo.report_builder import summary_dict, write_demo_report
from leadthrough.demo.run import run_demo
from leadthrough.errors import DataError
from leadthrough.robot.description import load_robot

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    """Add the subcommand."""
    p = sub.add_parser(
        "demo",
        help="run the whole pipeline on the built-in simulated robot",
        description=__doc__,
        epilog="examples:\n  leadthrough demo\n  leadthrough demo --quick --out /tmp/report",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--robot", default="er20", choices=DEMO_ROBOTS,
                   help="robot (default: er20; the demo's excitation, poses and guiding "
                        "scripts are laid out for the paper's robot)")
    p.add_argument("--seed", type=int, default=1, help="simulated robot instance (default: 1)")
    p.add_argument("--out", type=Path, default=Path("leadthrough-report"),
                   help="report folder (default: ./leadthrough-report)")
    p.add_argument("--quick", action="store_true", help="shorter recordings and searches")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


#: Robots the demo is laid out for (start poses, the excitation's floor, the guiding scripts'
#: workspace); another robot goes through the pipeline one command at a time.
DEMO_ROBOTS = ("er20",)


def run(args: argparse.Namespace) -> int:
    """Execute ``leadthrough demo``."""
    if args.seed < 0:
        raise DataError("must be >= 0", field="--seed", value=args.seed, expected="an integer >= 0")
    robot = load_robot(args.robot)
    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise DataError("not a folder", source=out, field="--out", expected="a folder")
    if not out.parent.is_dir():
        raise DataError("parent folder does not exist", source=out, field="--out",
                        expected="a folder whose parent exists")
    try:
        out.mkdir(exist_ok=True)
    except OSError as e:
        raise DataError(f"cannot create the report folder ({e.strerror})", source=out,
                        field="--out", expected="a writable location") from e
    if not os.access(out, os.W_OK | os.X_OK):
        raise DataError("report folder is not writable", source=out, field="--out",
                        expected="a writable folder")
    say = (lambda s: None) if args.json else (lambda s: print(s, flush=True))
    say(f"leadthrough demo on '{robot.name}' (seed {args.seed}{', quick' if args.quick else ''})")
    res = run_demo(robot, args.seed, out, bool(args.quick), say)
    files = write_demo_report(res, out)
    say(f"\nreport: {files['html']} (also report.md, summary.json); {res.total_s:.0f} s")
    if args.json:
        print(json.dumps(summary_dict(res), indent=2))
    return 0
