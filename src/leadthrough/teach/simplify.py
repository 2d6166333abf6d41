"""Ramer–Douglas–Peucker simplification of a 3D polyline.

No dependency of the package provides it for 3D points (``shapely``'s ``simplify`` works in the
plane; the ``rdp`` package is recursive pure Python and not a dependency), so it is implemented
here, iteratively with an explicit stack so that a path of any length cannot exhaust the
recursion limit. Distances are to the *segment* between the two kept ends (not to the infinite
line through them), so a path that turns back on itself keeps its turning point.

Guarantee: every dropped point lies within ``tolerance`` of the simplified polyline's segment
that replaces it; the first and last points and any ``keep`` indices are always kept.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import TeachError

__all__ = ["rdp_indices", "segment_distances"]

Array = NDArray[np.float64]


def segment_distances(points: Array, a: Array, b: Array) -> Array:
    """Distances from points to the segment [a, b].

    Args:
        points: Points, shape (N, d).
        a: Segment start, shape (d,).
        b: Segment end, shape (d,) (may equal ``a``: distances to that point).

    Returns:
        Distances, shape (N,), in the points' unit.
    """
    ab = b - a
    ap = points - a
    denom = float(ab @ ab)
    if denom <= 0.0:
        return np.asarray(np.linalg.norm(ap, axis=1))
    s = np.clip(ap @ ab / denom, 0.0, 1.0)
    return np.asarray(np.linalg.norm(ap - np.multiply.outer(s, ab), axis=1))


def rdp_indices(points: Array, tolerance: float, keep: Iterable[int] = ()) -> NDArray[np.int64]:
    """Indices of the points kept by Ramer–Douglas–Peucker.

    Args:
        points: Polyline vertices in order, shape (N, d) (here TCP positions [m], d = 3).
        tolerance: Largest distance of a dropped point from the simplified polyline, in the
            points' unit (≥ 0; 0 keeps every point that is not exactly on a kept segment).
        keep: Indices that must be kept (e.g. the operator's marks); they split the polyline
            into pieces simplified independently.

    Returns:
        Sorted kept indices, shape (K,), starting with 0 and ending with N − 1 (empty for an
        empty polyline).

    Raises:
        TeachError: Bad shape, non-finite points, negative or non-finite tolerance, or a
            ``keep`` index outside the polyline.
    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2:
        raise TeachError("polyline must be a 2-D array", field="points", value=p.shape,
                         expected="shape (N, d)")
    if not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise TeachError("out of range", field="tolerance", value=tolerance,
                         expected="a finite distance ≥ 0")
    n = p.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.all(np.isfinite(p)):
        raise TeachError("non-finite point", field="points", expected="finite coordinates")
    forced = sorted({int(k) for k in keep})
    if forced and (forced[0] < 0 or forced[-1] >= n):
        raise TeachError("index outside the polyline", field="keep",
                         value=forced[0] if forced[0] < 0 else forced[-1],
                         expected=f"indices in [0, {n - 1}]")
    kept = np.zeros(n, dtype=bool)
    kept[[0, n - 1, *forced]] = True
    anchors = np.flatnonzero(kept)
    stack: list[tuple[int, int]] = [(int(i), int(j)) for i, j in itertools.pairwise(anchors)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        d = segment_distances(p[i + 1:j], p[i], p[j])
        k = int(np.argmax(d))
        if d[k] > tolerance:
            m = i + 1 + k
            kept[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return np.flatnonzero(kept).astype(np.int64)
