"""The demo's report (``report.html``, ``report.md``) and ``summary.json`` from its results."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from leadthrough.demo.guiding_steps import PAPER_WORST
from leadthrough.demo.run import GUIDING_METHOD, DemoResult
from leadthrough.fileio import atomic_write_text
from leadthrough.identification.comparison import table2_markdown
from leadthrough.report import Figure, Report, Section, Table, write_html, write_markdown
from leadthrough.sim.session import PUSH_MASS_KG

__all__ = ["summary_dict", "write_demo_report"]


def summary_dict(res: DemoResult) -> dict[str, Any]:
    """The JSON summary."""
    g = res.guiding
    line = res.program.welding_line if res.program is not None else None
    return {
        "robot": res.robot, "seed": res.seed, "quick": res.quick, "checks": res.checks,
        "excitation_condition_number": res.condition_number,
        "table2": res.table2_ratios, "runtime_s": res.runtimes_s,
        "table3": {m: [{"true_N": r.true_n, "estimated_N": r.estimated_n,
                        "error_pct": r.error_pct} for r in rows]
                   for m, rows in res.payload.items()},
        "guiding": {} if g is None else {k: s.summary.to_json() for k, s in g.sessions.items()},
        "teach": None if line is None else {
            "length_m": line.length_m, "max_deviation_mm": line.max_deviation_mm,
            "rms_deviation_mm": line.rms_deviation_mm,
            "waypoints": len(res.program.waypoints) if res.program else 0,
            "endpoint_errors_mm": res.seam_target_errors_mm},
        "teach_error": res.teach_error or None,
        "files": {k: str(v) for k, v in res.files.items()},
        "total_s": res.total_s,
    }


def _figure(res: DemoResult, key: str, caption: str) -> list[Figure]:
    path = res.files.get(key)
    return [Figure(path, caption)] if path is not None else []


def write_demo_report(res: DemoResult, out: Path) -> dict[str, Path]:
    """Write summary.json, table2.md, report.html and report.md into ``out``."""
    files = {"summary": atomic_write_text(out / "summary.json",
                                          json.dumps(summary_dict(res), indent=2))}
    files["table2"] = atomic_write_text(
        out / "table2.md", f"# Table II (simulated {res.robot}, seed {res.seed})\n\n"
                           f"{table2_markdown(res.table2)}\n")
    ratios = res.table2_ratios
    ratio_text = "; ".join(f"{label}: J(proposed)/J(ols-cv) = {r['proposed/ols-cv']:.2f}"
                           for label, r in ratios.items())
    payload_rows = []
    methods = list(res.payload)
    if methods:
        for k, row in enumerate(res.payload[methods[0]]):
            cells = [f"{row.true_n:.2f}"]
            for m in methods:
                r = res.payload[m][k]
                cells += [f"{r.estimated_n:.2f}", f"{r.error_pct:+.2f}"]
            payload_rows.append(cells)
    header = ["true [N]"] + [h for m in methods for h in (f"{m} [N]", f"{m} error [%]")]
    sections = [
        Section("Calibration (Table II, Fig. 3)", paragraphs=[
            f"Excitation: optimised Fourier trajectory, condition number "
            f"{res.condition_number:.1f}. Methods fitted on the identification recording and "
            f"evaluated on a held-out trajectory. {ratio_text} (paper: 0.77).",
            "Runtime: " + ", ".join(f"{m} {t:.1f} s" for m, t in res.runtimes_s.items()) + "."],
            tables=[Table("Table II: residual mean [N·m], std as % of max torque, J [N·m]",
                          res.table2.header, res.table2.rows)],
            figures=_figure(res, "fig3", "Fig. 3: measured vs model torque on the held-out "
                                         "trajectory")),
        Section("Payload (Table III)", paragraphs=[
            "Weight from motion (held-out trajectory) with the unloaded robot's identified "
            f"model. Paper: {PAPER_WORST}."],
            tables=[Table("Table III: estimated payload weight", header, payload_rows)]
            if payload_rows else []),
    ]
    g = res.guiding
    if g is not None:
        rows = []
        for name, s in g.sessions.items():
            sm = s.summary
            rows.append([name, f"{sm.max_linear_speed:.3f}", f"{sm.max_linear_acc:.3f}",
                         "—" if sm.rest_drift_m is None else f"{1e3 * sm.rest_drift_m:.2f}",
                         ", ".join(sm.faults) or "none", f"{sm.cycle_time_us.median:.0f}",
                         f"{sm.cycle_time_us.p99:.0f}"])
        sections.append(Section(
            "Guiding (Fig. 4, Fig. 5)",
            paragraphs=[f"Scripted operators push the simulated robot; the force is estimated "
                        f"from currents with the {GUIDING_METHOD} parameters identified with "
                        "the friction sweep; virtual mass 1000 kg (push +x: "
                        f"{PUSH_MASS_KG:g} kg, so that 40 N reaches the 0.2 m/s cap), friction "
                        "15 N, stopping friction 50 N (Table IV)."],
            tables=[Table("Sessions", ["operator/controller", "max v [m/s]", "max a [m/s²]",
                                       "rest drift [mm]", "faults", "cycle median [µs]",
                                       "cycle p99 [µs]"], rows)],
            figures=_figure(res, "fig4", "Fig. 4: push +x, force and commanded velocity, "
                                         "virtual friction vs velocity control")
            + _figure(res, "fig5", "Fig. 5: TCP paths with the operator's force")))
    teach_par = [res.teach_error] if res.teach_error else []
    if res.program is not None and res.program.welding_line is not None:
        line = res.program.welding_line
        errs = "" if res.seam_target_errors_mm is None else (
            f" Endpoints vs the operator's targets: P1 {res.seam_target_errors_mm[0]:.1f} mm, "
            f"P2 {res.seam_target_errors_mm[1]:.1f} mm.")
        teach_par.append(f"Welding line {line.start_label}→{line.end_label}: "
                         f"{1e3 * line.length_m:.1f} mm, max deviation of the guided path "
                         f"{line.max_deviation_mm:.2f} mm (RMS {line.rms_deviation_mm:.2f} mm),"
                         f" {len(res.program.waypoints)} waypoints.{errs} Exported to "
                         "path.json and path.csv.")
    sections.append(Section("Teach-in (Fig. 6)", paragraphs=teach_par,
                            figures=_figure(res, "fig6", "Fig. 6: taught welding line")))
    report = Report(title="leadthrough demo",
                    subtitle="Sensorless hand guiding on the simulated robot (Zhang et al., "
                             "IEEE TII)",
                    robot=res.robot, seed=res.seed, sections=sections)
    files["html"] = write_html(report, out)
    files["md"] = write_markdown(report, out)
    return files
