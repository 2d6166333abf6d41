"""The session writer process's entry point (started by
:class:`~leadthrough.session.session_file.SessionFileSink`, not by users).

    python -P -m leadthrough.session.writer_process --fd FD --joints N --rows R [--truth] \
        -- PARTIAL PATH

It first leaves any real-time scheduling it inherited (``sched_setscheduler(2)`` to
``SCHED_OTHER``) and lowers its priority (``nice`` 10): the loop's process runs at SCHED_FIFO
where the user asked for it, and the writer must never take a CPU from it or from the
controller's link (its CPU affinity is left as inherited: the loop's process starts it before
pinning itself). It runs in a session of its own and ignores SIGINT, SIGTERM and SIGHUP: a
Ctrl-C, or a service manager's stop, is the loop's stop request, after which the loop's process
finishes the file through this process; it ends with its link. Only then does it load NumPy
and Arrow and serve the link (:func:`~leadthrough.session.session_writer.serve_writer`). It
exits when the file is finished or when the loop's process is gone (the rows written are then
closed into the partial file).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import socket
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]


def _background() -> None:
    """Leave real-time scheduling and lower the priority, where the OS allows."""
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass    # not Linux, or nothing to leave
    with contextlib.suppress(OSError):
        os.nice(10)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the writer (see the module doc); the exit code."""
    _background()
    for stop in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(stop, signal.SIG_IGN)
    parser = argparse.ArgumentParser(prog="leadthrough-session-writer")
    parser.add_argument("--fd", type=int, required=True)
    parser.add_argument("--joints", type=int, required=True)
    parser.add_argument("--rows", type=int, required=True)
    parser.add_argument("--truth", action="store_true")
    parser.add_argument("partial", type=Path)
    parser.add_argument("path", type=Path)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="leadthrough (session writer): %(message)s")
    # NumPy, Arrow and the session's columns only now, at the lowered priority
    from leadthrough.session.session_writer import serve_writer
    sock = socket.socket(fileno=args.fd)
    with sock:
        return serve_writer(sock, args.partial, args.path, args.joints, args.truth, args.rows)


if __name__ == "__main__":
    sys.exit(main())
