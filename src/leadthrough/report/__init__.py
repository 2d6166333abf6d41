"""Report writer for ``leadthrough demo``: one content model, two outputs.

* ``report.html``: a self-contained page (inline CSS, PNG figures embedded as base64 data URIs,
  no scripts, no external resources) with a table of contents and right-aligned numeric columns;
* ``report.md``: GitHub-flavoured Markdown with pipe tables and relative image links.

Figures are PNG files that already lie in the report folder (save them there first). All text is
plain text and is escaped by the writers. Both writers check the whole report before writing and
write atomically, so a bad input raises :class:`~leadthrough.errors.DataError` and leaves no file.

Example::

    from pathlib import Path
    from leadthrough.report import Figure, Report, Section, Table, write_html, write_markdown

    out = Path("leadthrough-report")          # already holds fig3.png
    report = Report(
        title="leadthrough demo", subtitle="Sensorless hand guiding, simulated robot",
        robot="er20", seed=1,
        sections=[Section(
            "Calibration (Table II, Fig. 3)",
            paragraphs=["Three methods on the same recordings."],
            tables=[Table("Table II: held-out fit", ["method", "J [N·m]"],
                          [["ols", "1.23"], ["proposed", "0.95"]], notes="J: RMS error.")],
            figures=[Figure(Path("fig3.png"), "Fig. 3: measured vs model torque",
                            alt="joint torques, measured and three models")],
        )],
    )
    write_html(report, out)                   # out/report.html
    write_markdown(report, out)               # out/report.md
"""

from leadthrough.report.html import render_html, write_html
from leadthrough.report.markdown import escape_markdown, render_markdown, write_markdown
from leadthrough.report.model import (
    Figure,
    Report,
    Section,
    Table,
    check_report,
    is_number_cell,
    numeric_columns,
)

__all__ = [
    "Figure",
    "Report",
    "Section",
    "Table",
    "check_report",
    "escape_markdown",
    "is_number_cell",
    "numeric_columns",
    "render_html",
    "render_markdown",
    "write_html",
    "write_markdown",
]
