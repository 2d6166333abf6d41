"""Fig. 6 equivalent: the guided TCP path, the taught waypoints and the fitted welding line."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leadthrough.fileio import atomic_write
from leadthrough.teach.path import TcpPath
from leadthrough.teach.program import TaughtProgram

__all__ = ["plot_taught_path"]


def plot_taught_path(path: TcpPath, program: TaughtProgram, out: str | Path,
                     targets: Mapping[str, NDArray[np.float64]] | None = None) -> Path:
    """3D plot (base frame) of the measured TCP path, the RDP waypoints and the welding line.

    Args:
        path: The measured TCP path of the session (:func:`~leadthrough.teach.tcp_path`).
        program: The teach-in result.
        out: Output PNG.
        targets: Named reference points (the operator's P1, P2 in simulation) [m].

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    p = path.tcp_position_base
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.6", lw=1, label="guided TCP path (measured)")
    w = program.waypoints.tcp_position_base
    ax.plot(w[:, 0], w[:, 1], w[:, 2], "o-", color="tab:blue", ms=4, lw=1,
            label=f"waypoints ({len(program.waypoints)}, RDP {program.tolerance_mm:g} mm)")
    line = program.welding_line
    if line is not None:
        seg = np.vstack([line.p1_base, line.p2_base])
        ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color="tab:red", lw=3,
                label=f"welding line {line.start_label}→{line.end_label} "
                      f"(max dev. {line.max_deviation_mm:.2f} mm)")
    for name, point in (targets or {}).items():
        ax.scatter(*point, marker="x", s=70, color="k")
        ax.text(*point, f" {name} (target)", fontsize=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("Teach-in: guided path, waypoints and welding line (paper Fig. 6)")
    fig.tight_layout()

    def write(tmp: Path) -> None:
        fig.savefig(tmp, dpi=110)

    try:
        return atomic_write(out, write)
    finally:
        plt.close(fig)
