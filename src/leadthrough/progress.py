"""Progress reporting for long steps: a bar on a terminal, plain lines otherwise (or nothing)."""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """Report progress of a long step.

    On a terminal it draws a one-line bar; otherwise it prints nothing unless ``lines`` is set,
    in which case it prints one plain line at the start and one at the end.

    Args:
        label: What is running.
        total: Number of units of work.
        stream: Where to write (default stderr).
        lines: Print plain start/end lines when not on a terminal.
    """

    def __init__(self, label: str, total: int, stream: TextIO | None = None,
                 lines: bool = False) -> None:
        self.label = label
        self.total = max(1, int(total))
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.lines = lines
        self._last = -1
        if not self.tty and self.lines:
            print(f"{label} ...", file=self.stream, flush=True)

    def __call__(self, done: int, total: int | None = None) -> None:
        """Update to ``done`` units (of ``total`` if given)."""
        if total is not None:
            self.total = max(1, int(total))
        if not self.tty:
            return
        pct = int(100 * min(done, self.total) / self.total)
        if pct == self._last:
            return
        self._last = pct
        width = 30
        fill = width * pct // 100
        self.stream.write(f"\r{self.label} [{'#' * fill}{'.' * (width - fill)}] {pct:3d}%")
        self.stream.flush()

    def close(self, message: str = "done") -> None:
        """Finish the bar (or print the end line)."""
        if self.tty:
            self.stream.write(f"\r{self.label} {message}{' ' * 40}\n")
            self.stream.flush()
        elif self.lines:
            print(f"{self.label} {message}", file=self.stream, flush=True)
