"""The operator's list of taught points: marked at the robot, then deleted or reordered.

The loop records each mark (name, time, measured joints; :class:`~leadthrough.pendant.backend.
MarkedPoint`); this list is the operator's view of them. Marking a name again (``P1``) replaces
the earlier point of that name where it stood; ``Waypoint`` takes the next free ``W1``, ``W2``,
... . The operator may delete points and move them up or down: the order is that of the point
program (``points.json``); the taught path and its welding line (``path.json``) follow the
path in time between the first and the last mark, whatever the list order.

The interface's callbacks may run on several threads (viser runs them in a pool): every method
takes the list's lock. The loop never touches it.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Sequence

from leadthrough.errors import TeachError
from leadthrough.pendant.backend import MarkedPoint

__all__ = ["TaughtPoints"]

_WAYPOINT = re.compile(r"W(\d+)$")


class TaughtPoints:
    """The taught points, in the operator's order."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._points: list[MarkedPoint] = []
        self._seen = 0

    def sync(self, marks: Sequence[MarkedPoint]) -> bool:
        """Take the loop's new marks (``marks`` as published, oldest first).

        Returns:
            Whether the list changed.
        """
        with self._lock:
            new = list(marks[self._seen:])
            self._seen = len(marks)
            for point in new:
                same = [k for k, p in enumerate(self._points) if p.label == point.label]
                if same:
                    self._points[same[0]] = point
                else:
                    self._points.append(point)
            return bool(new)

    @property
    def points(self) -> tuple[MarkedPoint, ...]:
        """The points, in the operator's order."""
        with self._lock:
            return tuple(self._points)

    def next_waypoint(self) -> str:
        """The next free waypoint name: ``W1``, ``W2``, ... ."""
        with self._lock:
            used = [int(m.group(1)) for p in self._points if (m := _WAYPOINT.match(p.label))]
            return f"W{max(used, default=0) + 1}"

    def delete(self, label: str) -> None:
        """Remove the point named ``label``.

        Raises:
            TeachError: No such point.
        """
        with self._lock:
            self._points.pop(self._index(label))

    def move(self, label: str, step: int) -> None:
        """Move the point named ``label`` by ``step`` places (−1: up), within the list.

        Raises:
            TeachError: No such point.
        """
        with self._lock:
            k = self._index(label)
            j = min(max(k + step, 0), len(self._points) - 1)
            self._points.insert(j, self._points.pop(k))

    def _index(self, label: str) -> int:
        for k, p in enumerate(self._points):
            if p.label == label:
                return k
        raise TeachError("no such taught point", field="point", value=label,
                         expected=", ".join(p.label for p in self._points) or "a marked point")
