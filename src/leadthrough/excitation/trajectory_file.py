"""Trajectory files: sampled joint trajectories as CSV with a header of units.

::

    # leadthrough trajectory
    # robot: er20
    # condition_number: 34.2
    time [s],q1 [rad],...,qd1 [rad/s],...,qdd1 [rad/s²],...
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

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


def load_trajectory(path: str | Path) -> tuple[TrajectorySamples, str | None]:
    """Read a trajectory CSV.

    Returns:
        The samples and the robot name from the header (None if absent).

    Raises:
        DataError: Missing file or malformed content.
    """
    path = Path(path)
    require_file(path, "trajectory", "an existing CSV file")
    skip, meta = read_comment_header(path)
    robot = meta.get("robot") or None
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=skip + 1, ndmin=2)
    except ValueError as e:
        raise DataError(f"malformed trajectory: {e}", source=path) from e
    if data.shape[1] < 4 or (data.shape[1] - 1) % 3:
        raise DataError("wrong number of columns", source=path, field="columns",
                        value=data.shape[1], expected="time + 3·n columns (q, qd, qdd)")
    if not np.all(np.isfinite(data)) or data.shape[0] < 2 or np.any(np.diff(data[:, 0]) <= 0):
        raise DataError("trajectory must be finite with increasing time", source=path,
                        field="time", expected="finite values, strictly increasing time")
    n = (data.shape[1] - 1) // 3
    return TrajectorySamples(time=data[:, 0], q=data[:, 1:1 + n], qd=data[:, 1 + n:1 + 2 * n],
                             qdd=data[:, 1 + 2 * n:]), robot
