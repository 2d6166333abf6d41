"""Trajectory files: sampled joint trajectories as CSV with a header of units.

::

    # leadthrough trajectory
    # robot: er20
    # condition_number: 34.2
    time [s],q1 [rad],...,qd1 [rad/s],...,qdd1 [rad/s²],...
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.fileio import atomic_write, read_comment_header, require_file

__all__ = ["load_trajectory", "save_trajectory"]


def save_trajectory(path: str | Path, traj: TrajectorySamples, robot: str,
                    notes: dict[str, str] | None = None) -> Path:
    """Write a trajectory CSV atomically.

    Args:
        path: Output file (.csv).
        traj: The samples.
        robot: Robot name.
        notes: Extra ``key: value`` header lines.
    """
    n = traj.q.shape[1]
    header = ["time [s]"] + [f"q{j + 1} [rad]" for j in range(n)] + \
        [f"qd{j + 1} [rad/s]" for j in range(n)] + [f"qdd{j + 1} [rad/s²]" for j in range(n)]
    data = np.column_stack([traj.time, traj.q, traj.qd, traj.qdd])

    def write(tmp: Path) -> None:
        with tmp.open("w", encoding="utf-8") as f:
            f.write("# leadthrough trajectory\n")
            f.write(f"# robot: {robot}\n")
            for k, v in (notes or {}).items():
                f.write(f"# {k}: {v}\n")
            np.savetxt(f, data, delimiter=",", header=",".join(header), comments="",
                       fmt="%.17g")

    return atomic_write(path, write)


def _check_samples(path: Path, data: NDArray[np.float64]) -> None:
    """At least two rows of time + 3·n finite columns, time strictly increasing; the first
    bad value named by its row (1-based, after the header) and column."""
    if data.shape[0] < 2:
        raise DataError("too few samples", source=path, field="rows", value=data.shape[0],
                        expected="at least 2 rows after the header")
    if data.shape[1] < 4 or (data.shape[1] - 1) % 3:
        raise DataError("wrong number of columns", source=path, field="columns",
                        value=data.shape[1], expected="time + 3·n columns (q, qd, qdd)")
    n = (data.shape[1] - 1) // 3
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = (int(x) for x in np.argwhere(bad)[0])
        names = ["time"] + [f"{kind}{j + 1}" for kind in ("q", "qd", "qdd") for j in range(n)]
        raise DataError(f"a value that is not finite in row {row + 1}", source=path,
                        field=names[col], value=float(data[row, col]),
                        expected="finite numbers")
    back = np.flatnonzero(np.diff(data[:, 0]) <= 0)
    if back.size:
        row = int(back[0]) + 1
        raise DataError(f"time does not increase in row {row + 1}", source=path, field="time",
                        value=float(data[row, 0]),
                        expected=f"> {data[row - 1, 0]:g} (the row before): strictly "
                                 "increasing time")


def _check_header(path: Path, header: str, columns: int) -> None:
    """The header line names the columns :func:`save_trajectory` writes, in its order: ``time``,
    ``qJ``, ``qdJ``, ``qddJ``, each with its unit (``time [s]``) or none (``time``); a renamed,
    unknown, missing or misplaced column is refused (its data would be read as another's)."""
    names = [c.strip() for c in header.split(",")]
    if columns < 4 or (columns - 1) % 3:
        return          # the count is the samples' check
    if len(names) != columns:
        raise DataError("the header names another number of columns than the rows hold",
                        source=path, field="header", value=len(names),
                        expected=f"{columns} column names (time + 3·n)")
    n = (columns - 1) // 3
    expected = [("time", "[s]")] + [(f"{kind}{j + 1}", unit) for kind, unit in (
        ("q", "[rad]"), ("qd", "[rad/s]"), ("qdd", "[rad/s²]")) for j in range(n)]
    known = {name for name, _ in expected}
    for k, (got, (name, unit)) in enumerate(zip(names, expected, strict=True)):
        if got in (name, f"{name} {unit}"):
            continue
        bare = got.split(" [")[0]
        problem = ("unknown column" if bare not in known else
                   f"column {name} with another unit" if bare == name else
                   f"column {k + 1} is {bare}, out of order")
        raise DataError(f"{problem} in the header: missing '{name} {unit}'", source=path,
                        field=f"column {k + 1}", value=got,
                        expected=f"'{name} {unit}' (the header 'time [s],q1 [rad],..,"
                                 "qd1 [rad/s],..,qdd1 [rad/s²],..' that excite writes)")


def load_trajectory(path: str | Path) -> tuple[TrajectorySamples, str | None]:
    """Read a trajectory CSV.

    Returns:
        The samples and the robot name from the header (None if absent).

    Raises:
        DataError: Missing file or malformed content: too few rows, a value that is not
            finite, time that does not increase, or a header whose columns are not the
            trajectory's (renamed, unknown, missing or out of order).
    """
    path = Path(path)
    require_file(path, "trajectory", "an existing CSV file")
    skip, meta = read_comment_header(path)
    robot = meta.get("robot") or None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)    # numpy's "empty input file"
            data = np.loadtxt(path, delimiter=",", skiprows=skip + 1, ndmin=2)
    except ValueError as e:
        raise DataError(f"malformed trajectory: {str(e).split('; use `usecols`')[0]}",
                        source=path, expected="rows of numbers, each time + 3·n columns"
                        ) from e
    _check_samples(path, data)
    with path.open("r", encoding="utf-8", errors="replace") as f:
        for _ in range(skip):
            f.readline()
        _check_header(path, f.readline(), data.shape[1])
    n = (data.shape[1] - 1) // 3
    return TrajectorySamples(time=data[:, 0], q=data[:, 1:1 + n], qd=data[:, 1 + n:1 + 2 * n],
                             qdd=data[:, 1 + 2 * n:]), robot
