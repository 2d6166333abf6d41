"""The welding line P1 → P2: a straight line fitted to the guided TCP positions between two marks.

* Fit: total least squares (principal axis) through the TCP positions recorded between the two
  mark instants: the line passes through their centroid c along the first right-singular
  vector d of the centred points, which minimises the sum of squared *perpendicular* distances
  (ordinary least squares on one coordinate would not be invariant to the seam's direction).
* Endpoints: the TCP position averaged over a short window around each mark (± ``window_s``,
  default 50 ms, which smooths encoder noise and the hand's tremor while the operator presses the
  button), projected onto the line: p = c + ((m − c)·d)·d. The direction is oriented P1 → P2.
* Stray: perpendicular distances of the fitted positions from the line, max and RMS [mm].

All positions are in the robot base frame [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import TeachError
from leadthrough.teach.path import TcpPath

__all__ = ["Line3", "WeldingLine", "fit_line", "fit_welding_line"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Line3:
    """An infinite straight line in the base frame.

    Attributes:
        point_base: A point on the line (the centroid of the fitted points) [m], shape (3,).
        direction_base: Unit direction, shape (3,).
    """

    point_base: Array
    direction_base: Array

    def project(self, points_base: Array) -> Array:
        """Feet of the perpendiculars from points onto the line.

        Args:
            points_base: Points [m], shape (3,) or (N, 3).

        Returns:
            The projections [m], same shape.
        """
        p = np.asarray(points_base, dtype=float)
        s = (p - self.point_base) @ self.direction_base
        return self.point_base + np.multiply.outer(s, self.direction_base)

    def distance(self, points_base: Array) -> Array:
        """Perpendicular distances of points from the line [m].

        Args:
            points_base: Points [m], shape (N, 3).

        Returns:
            Distances [m], shape (N,).
        """
        p = np.atleast_2d(np.asarray(points_base, dtype=float))
        return np.asarray(np.linalg.norm(p - self.project(p), axis=1))


def fit_line(points_base: Array) -> Line3:
    """Total-least-squares line through 3D points.

    Args:
        points_base: Points [m], shape (N, 3), N ≥ 2, not all equal.

    Returns:
        The line through the centroid along the principal axis (sign: arbitrary).

    Raises:
        TeachError: Fewer than two points, non-finite points, or all points equal.
    """
    p = np.asarray(points_base, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
        raise TeachError("too few points to fit a line", field="points", value=p.shape,
                         expected="at least 2 points of shape (N, 3)")
    if not np.all(np.isfinite(p)):
        raise TeachError("non-finite point", field="points", expected="finite positions")
    c = p.mean(axis=0)
    _, sing, vt = np.linalg.svd(p - c, full_matrices=False)
    if sing[0] <= 1e-12:
        raise TeachError("all points coincide; no line direction", field="points",
                         expected="points spread along a line")
    return Line3(point_base=c, direction_base=vt[0] / np.linalg.norm(vt[0]))


@dataclass(frozen=True)
class WeldingLine:
    """The welding line between two marks.

    Attributes:
        start_label: Mark at the start, e.g. ``"P1"``.
        end_label: Mark at the end, e.g. ``"P2"``.
        p1_base: Start point on the line, base frame [m], shape (3,).
        p2_base: End point on the line, base frame [m], shape (3,).
        direction_base: Unit direction P1 → P2, shape (3,).
        length_m: |P2 − P1| [m].
        max_deviation_mm: Largest perpendicular distance of the guided path from the line [mm].
        rms_deviation_mm: RMS perpendicular distance of the guided path from the line [mm].
        mark_p1_base: Window-averaged TCP at the start mark before projection [m], shape (3,).
        mark_p2_base: Window-averaged TCP at the end mark before projection [m], shape (3,).
        samples: Number of recorded positions fitted.
    """

    start_label: str
    end_label: str
    p1_base: Array
    p2_base: Array
    direction_base: Array
    length_m: float
    max_deviation_mm: float
    rms_deviation_mm: float
    mark_p1_base: Array
    mark_p2_base: Array
    samples: int


def _window_mean(path: TcpPath, t: float, window_s: float) -> Array:
    sel = np.abs(path.time - t) <= window_s
    if not np.any(sel):
        return np.asarray(path.tcp_position_base[path.nearest(t)], dtype=float).copy()
    return np.asarray(path.tcp_position_base[sel].mean(axis=0), dtype=float)


def fit_welding_line(path: TcpPath, t_start: float, t_end: float, *,
                     labels: tuple[str, str] = ("P1", "P2"), window_s: float = 0.05,
                     min_length_m: float = 0.005, source: str | None = None) -> WeldingLine:
    """Fit the welding line to the guided path between two mark instants.

    Args:
        path: Measured TCP path covering both marks and ± ``window_s`` around them.
        t_start: Time of the start mark (P1) [s].
        t_end: Time of the end mark (P2) [s] (may precede ``t_start``: the line still runs
            from the start mark's point to the end mark's point).
        labels: Names of the two marks, for results and messages.
        window_s: Half-width of the averaging window around each mark [s], ≥ 0.
        min_length_m: Shortest accepted line [m]; P1 and P2 closer than this are an error.
        source: Session file, for messages.

    Returns:
        The fitted line with its endpoints and the path's deviation from it.

    Raises:
        TeachError: Bad window, fewer than two positions between the marks, or a line shorter
            than ``min_length_m``.
    """
    if not (math.isfinite(window_s) and window_s >= 0.0):
        raise TeachError("out of range", field="window_s", value=window_s,
                         expected="a finite averaging half-window ≥ 0 s")
    lo, hi = min(t_start, t_end), max(t_start, t_end)
    between = (path.time >= lo) & (path.time <= hi)
    pts = path.tcp_position_base[between]
    if pts.shape[0] < 2:
        raise TeachError(f"fewer than 2 recorded positions between {labels[0]} and {labels[1]}",
                         source=source, field="marks", value=pts.shape[0],
                         expected="marks pressed at least two samples apart")
    m1 = _window_mean(path, t_start, window_s)
    m2 = _window_mean(path, t_end, window_s)
    span = float(np.linalg.norm(m2 - m1))
    if span < min_length_m:
        raise TeachError(f"{labels[0]} and {labels[1]} are only {span * 1e3:.2f} mm apart",
                         source=source, field="marks", value=f"{labels[0]}->{labels[1]}",
                         expected=f"a welding line at least {min_length_m * 1e3:.1f} mm long")
    line = fit_line(pts)
    d = line.direction_base if float((m2 - m1) @ line.direction_base) >= 0.0 \
        else -line.direction_base
    p1, p2 = line.project(m1), line.project(m2)
    dist = line.distance(pts)
    return WeldingLine(
        start_label=labels[0], end_label=labels[1], p1_base=p1, p2_base=p2, direction_base=d,
        length_m=float(np.linalg.norm(p2 - p1)),
        max_deviation_mm=float(dist.max() * 1e3),
        rms_deviation_mm=float(np.sqrt(np.mean(dist**2)) * 1e3),
        mark_p1_base=m1, mark_p2_base=m2, samples=int(pts.shape[0]))
