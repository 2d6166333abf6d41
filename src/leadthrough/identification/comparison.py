"""Compare calibration methods as the paper's Table II does, and measure the noise floor.

Table II layout: for each method, per joint the mean of τ_ω [N·m] and its std as a percentage of
the joint's max torque, and J; here on the identification recording and on held-out ones.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from leadthrough.data.preprocess import ProcessedData, preprocess
from leadthrough.data.recording import Recording
from leadthrough.identification.api import (
    IdentificationResult,
    IdentifyConfig,
    evaluate,
    identify,
)
from leadthrough.identification.metrics import ResidualStats, residual_stats
from leadthrough.robot.description import Robot

__all__ = [
    "MethodComparison",
    "Table2",
    "compare_methods",
    "format_table2",
    "noise_floor",
    "ratio_summary",
    "table2",
    "table2_markdown",
]


@dataclass(frozen=True)
class MethodComparison:
    """Results of several methods on shared data.

    Attributes:
        robot: Robot name.
        joint_names: Joint names.
        results: Identification result per method (in the order run).
        validation: Per method, residual statistics per held-out data set (by label).
        identification_label: Label of the identification data.
    """

    robot: str
    joint_names: tuple[str, ...]
    results: dict[str, IdentificationResult]
    validation: dict[str, dict[str, ResidualStats]]
    identification_label: str

    def stats(self, method: str, label: str) -> ResidualStats:
        """Statistics of ``method`` on the data set ``label``."""
        if label == self.identification_label:
            return self.results[method].stats
        return self.validation[method][label]

    @property
    def labels(self) -> list[str]:
        """Data set labels, identification first."""
        first = next(iter(self.validation.values()), {})
        return [self.identification_label, *first.keys()]


def compare_methods(
    robot: Robot,
    identification: Recording | ProcessedData,
    held_out: dict[str, Recording | ProcessedData],
    methods: Sequence[str],
    config: IdentifyConfig | None = None,
    identification_label: str = "identification",
    progress: Callable[[str], None] | None = None,
) -> MethodComparison:
    """Identify with each method and evaluate on held-out data.

    Args:
        robot: The robot.
        identification: Excitation recording.
        held_out: Held-out recordings by label.
        methods: Method names.
        config: Shared settings.
        identification_label: Label of the identification data in tables.
        progress: Called with a line of text as each method finishes.

    Returns:
        All results.
    """
    cfg = config if config is not None else IdentifyConfig()
    data = identification if isinstance(identification, ProcessedData) else \
        preprocess(identification, robot, cfg.preprocess)
    held = {k: v if isinstance(v, ProcessedData) else preprocess(v, robot, cfg.preprocess)
            for k, v in held_out.items()}
    results: dict[str, IdentificationResult] = {}
    validation: dict[str, dict[str, ResidualStats]] = {}
    for m in methods:
        res = identify(data, robot, m, cfg)
        results[m] = res
        validation[m] = {k: evaluate(res.params, robot, v, cfg) for k, v in held.items()}
        if progress is not None:
            progress(f"{m}: J = {res.J:.2f} ({res.runtime_s:.1f} s)")
    return MethodComparison(robot=robot.name, joint_names=robot.joint_names, results=results,
                            validation=validation, identification_label=identification_label)


def noise_floor(
    robot: Robot, measured: Recording, true: Recording, config: IdentifyConfig | None = None
) -> ResidualStats:
    """J of the true drive torque against the measured one (simulator only).

    Both recordings are processed identically; the standstill mask of the measured data is used,
    as for the methods.

    Args:
        robot: The robot.
        measured: The recording with measured currents.
        true: The same samples with the true (noise-free) currents.
        config: Pre-processing and K_ω.

    Returns:
        Residual statistics of measured − true.
    """
    cfg = config if config is not None else IdentifyConfig()
    m = preprocess(measured, robot, cfg.preprocess)
    t = preprocess(true, robot, cfg.preprocess)
    return residual_stats(m.torque, t.torque, m.moving, robot.max_torque, cfg.k_omega)


class Table2(NamedTuple):
    """Table II as cells.

    Attributes:
        header: Column names with units.
        rows: One row of formatted cells per data set and method (and noise floor).
    """

    header: list[str]
    rows: list[list[str]]


def table2(comp: MethodComparison, floors: dict[str, ResidualStats] | None = None) -> Table2:
    """Table II in the paper's layout (mean [N·m], std/max [%], J) per data set.

    Args:
        comp: The comparison.
        floors: Optional noise floor per data-set label, listed beside the methods.

    Returns:
        Header and formatted rows.
    """
    n = len(comp.joint_names)
    header = (["data", "method"] + [f"mean{j + 1} [N·m]" for j in range(n)]
              + [f"std{j + 1}/max [%]" for j in range(n)] + ["J [N·m]"])

    def row(label: str, name: str, s: ResidualStats) -> list[str]:
        return ([label, name] + [f"{v:.2f}" for v in s.mean]
                + [f"{v:.2f}" for v in s.std_pct_max] + [f"{s.J:.2f}"])

    rows = []
    for label in comp.labels:
        for m in comp.results:
            rows.append(row(label, m, comp.stats(m, label)))
        if floors and label in floors:
            rows.append(row(label, "noise floor", floors[label]))
    return Table2(header, rows)


def format_table2(comp: MethodComparison, floors: dict[str, ResidualStats] | None = None) -> str:
    """Table II (:func:`table2`) as a plain-text, Markdown-compatible table."""
    return table2_markdown(table2(comp, floors))


def table2_markdown(t: Table2) -> str:
    """Table II cells as a plain-text, Markdown-compatible table."""
    lines = ["| " + " | ".join(t.header) + " |", "|" + "---|" * len(t.header)]
    lines += ["| " + " | ".join(r) + " |" for r in t.rows]
    return "\n".join(lines)


def ratio_summary(comp: MethodComparison, floors: dict[str, ResidualStats] | None = None
                  ) -> dict[str, dict[str, float]]:
    """J per method and data set, plus ratios to ols-cv and to the floor where available."""
    out: dict[str, dict[str, float]] = {}
    for label in comp.labels:
        row: dict[str, float] = {m: comp.stats(m, label).J for m in comp.results}
        if "ols-cv" in row:
            for m in comp.results:
                row[f"{m}/ols-cv"] = row[m] / row["ols-cv"]
        if floors and label in floors:
            row["floor"] = floors[label].J
            for m in comp.results:
                row[f"{m}/floor"] = row[m] / floors[label].J
        out[label] = {k: float(np.round(v, 6)) for k, v in row.items()}
    return out
