"""Figures of guiding sessions: the paper's Fig. 4 (force and velocity against time, two
controllers) and Fig. 5 (the TCP path in 3D with the operator's force as arrows)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from leadthrough.fileio import atomic_write
from leadthrough.session_format import SessionLog

__all__ = ["plot_force_velocity", "plot_path_3d"]


def plot_force_velocity(sessions: Mapping[str, SessionLog], path: str | Path,
                        axis: int = 0) -> Path:
    """Fig. 4: applied and estimated force and commanded TCP velocity along one base axis.

    Args:
        sessions: Label → session (e.g. one per controller), same operator script.
        path: Output PNG.
        axis: Base axis (0 x, 1 y, 2 z).

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = "xyz"[axis]
    fig, (ax_f, ax_v) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    first = True
    for label, log in sessions.items():
        if first and log.wrench_applied_base is not None:
            ax_f.plot(log.time, log.wrench_applied_base[:, axis], "k-", lw=2,
                      label="applied (sim truth)")
        first = False
        ax_f.plot(log.time, log.wrench_base[:, axis], lw=1, label=f"estimated, {label}")
        ax_v.plot(log.time, log.twist_cmd_base[:, axis], lw=1.5, label=label)
    ax_f.set_ylabel(f"F{name} [N]")
    ax_f.legend(fontsize=8)
    ax_f.grid(alpha=0.3)
    ax_v.set_ylabel(f"v{name} commanded [m/s]")
    ax_v.set_xlabel("time [s]")
    ax_v.legend(fontsize=8)
    ax_v.grid(alpha=0.3)
    fig.suptitle("Force following: virtual friction vs velocity control (paper Fig. 4)")
    fig.tight_layout()
    return _save(fig, path)


def plot_path_3d(sessions: Mapping[str, SessionLog], path: str | Path,
                 arrows: int = 15, targets: Mapping[str, np.ndarray] | None = None,
                 scale_m_per_n: float = 0.0005) -> Path:
    """Fig. 5: commanded TCP path in the base frame, with the applied force as arrows.

    Args:
        sessions: Label → session.
        path: Output PNG.
        arrows: Number of force arrows per session (where a force is applied).
        targets: Named points to mark (e.g. the operator's P1 and P2) [m], shape (3,) each.
        scale_m_per_n: Arrow length per newton [m/N].

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    for label, log in sessions.items():
        p = log.tcp_cmd_base
        ax.plot(p[:, 0], p[:, 1], p[:, 2], lw=1.5, label=label)
        force = log.wrench_applied_base if log.wrench_applied_base is not None \
            else log.wrench_base
        pushed = np.flatnonzero(np.linalg.norm(force[:, :3], axis=1) > 1.0)
        if pushed.size:
            idx = pushed[np.linspace(0, pushed.size - 1, min(arrows, pushed.size)).astype(int)]
            f = force[idx, :3] * scale_m_per_n
            ax.quiver(p[idx, 0], p[idx, 1], p[idx, 2], f[:, 0], f[:, 1], f[:, 2],
                      color="tab:red", lw=0.8, arrow_length_ratio=0.2)
    for name, point in (targets or {}).items():
        ax.scatter(*point, marker="x", s=60, color="k")
        ax.text(*point, f" {name}", fontsize=9)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(fontsize=8)
    ax.set_title(f"TCP path and operator force (red, {1e3 * scale_m_per_n:g} mm/N) "
                 "(paper Fig. 5)")
    fig.tight_layout()
    return _save(fig, path)


def _save(fig: object, path: str | Path) -> Path:
    import matplotlib.pyplot as plt

    def write(tmp: Path) -> None:
        fig.savefig(tmp, dpi=110)  # type: ignore[attr-defined]

    try:
        return atomic_write(path, write)
    finally:
        plt.close(fig)  # type: ignore[arg-type]
