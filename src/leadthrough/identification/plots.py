"""Figures of calibration results (the paper's Fig. 3: measured vs model torque per joint)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from leadthrough.data.preprocess import ProcessedData
from leadthrough.dynamics.model import DriveModelParameters, model_torque
from leadthrough.fileio import atomic_write
from leadthrough.robot.description import Robot

__all__ = ["plot_torque_fit"]


def plot_torque_fit(
    path: str | Path,
    robot: Robot,
    data: ProcessedData,
    params: Mapping[str, DriveModelParameters],
    title: str = "",
    window_s: float | None = 20.0,
) -> Path:
    """Measured vs model joint torque, one panel per joint, one line per method (Fig. 3).

    Args:
        path: Output PNG.
        robot: The robot.
        data: Processed data to plot.
        params: Identified parameters by method name.
        title: Figure title.
        window_s: Plot only the first seconds (None: all).

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = data.time - data.time[0]
    sel = np.ones(t.size, dtype=bool) if window_s is None else t <= window_s
    n = robot.n
    cols = 2
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(12, 2.6 * rows), sharex=True, squeeze=False)
    models = {m: model_torque(robot, p, data.q, data.qd, data.qdd) for m, p in params.items()}
    for j in range(n):
        ax = axes[j // cols][j % cols]
        ax.plot(t[sel], data.torque[sel, j], color="0.2", lw=1.4, label="measured")
        for m, tau in models.items():
            ax.plot(t[sel], tau[sel, j], lw=0.9, label=m)
        ax.set_title(f"{robot.joint_names[j]} (max {robot.max_torque[j]:g} N·m)", fontsize=9)
        ax.set_ylabel("torque [N·m]", fontsize=8)
        ax.grid(alpha=0.3)
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    axes[0][0].legend(fontsize=8, loc="upper right")
    fig.suptitle(title or f"{robot.name}: measured vs model joint torque")
    fig.tight_layout()

    def write(tmp: Path) -> None:
        fig.savefig(tmp, dpi=110, format="png")

    try:
        return atomic_write(path, write)
    finally:
        plt.close(fig)
