"""The report as one self-contained HTML page (``report.html``).

Figures are embedded as ``data:image/png;base64`` URIs and the style sheet is inline, so the file
can be mailed or archived on its own. The page has no scripts and a Content-Security-Policy that
allows nothing but inline styles and data-URI images: it never loads anything from elsewhere.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

from leadthrough import __version__
from leadthrough.fileio import atomic_write_text
from leadthrough.report.model import (
    FigureFile,
    Layout,
    Report,
    Section,
    Table,
    check_report,
    numeric_columns,
)

__all__ = ["CONTENT_SECURITY_POLICY", "HTML_NAME", "render_html", "write_html"]

HTML_NAME = "report.html"
CONTENT_SECURITY_POLICY = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

_CSS = """
:root { color-scheme: light; --fg: #1f2328; --muted: #59636e; --line: #d1d9e0;
  --accent: #0b5cad; --stripe: #f6f8fa; }
* { box-sizing: border-box; }
body { margin: 0; background: #fff; color: var(--fg);
  font: 16px/1.55 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial,
    sans-serif; }
.page { max-width: 64rem; margin: 0 auto; padding: 2rem 1.5rem 3rem; }
header { border-bottom: 2px solid var(--line); margin-bottom: 1.5rem; }
h1 { font-size: 1.9rem; line-height: 1.2; margin: 0 0 .3rem; }
h2 { font-size: 1.4rem; line-height: 1.3; margin: 2.2rem 0 1rem; padding-bottom: .3rem;
  border-bottom: 1px solid var(--line); }
p { margin: 0 0 1rem; }
a { color: var(--accent); text-decoration: none; }
a:hover { text-decoration: underline; }
.subtitle { font-size: 1.1rem; color: var(--muted); margin: 0 0 .4rem; }
.meta { font-size: .9rem; color: var(--muted); margin: 0 0 1rem; }
nav.toc { display: inline-block; min-width: 18rem; margin: 0 0 1rem; padding: .7rem 1.4rem .8rem;
  background: var(--stripe); border: 1px solid var(--line); border-radius: 6px; }
nav.toc h2 { font-size: 1rem; margin: 0 0 .3rem; padding: 0; border: 0; }
nav.toc ol { margin: 0; padding-left: 1.3rem; }
.table-wrap { overflow-x: auto; margin: 0 0 1.6rem; }
table { border-collapse: collapse; font-size: .92rem; }
caption { caption-side: top; text-align: left; font-weight: 600; padding: 0 0 .5rem; }
th, td { padding: .35rem .8rem; text-align: left; vertical-align: top;
  border-bottom: 1px solid var(--line); }
thead th { border-bottom: 2px solid var(--fg); white-space: nowrap; }
tbody tr:nth-child(even) { background: var(--stripe); }
th.num, td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.notes { font-size: .85rem; color: var(--muted); margin: .45rem 0 0; }
figure { margin: 0 0 2rem; }
figure img { display: block; max-width: 100%; height: auto; margin: 0 auto;
  border: 1px solid var(--line); }
figcaption { font-size: .9rem; color: var(--muted); margin: .5rem auto 0; max-width: 48rem;
  text-align: center; }
footer { margin-top: 3rem; padding-top: 1rem; border-top: 1px solid var(--line);
  font-size: .85rem; color: var(--muted); }
@media print {
  body { font-size: 11pt; }
  .page { max-width: none; padding: 0; }
  nav.toc { display: none; }
  figure, .table-wrap { break-inside: avoid; }
}
"""


def _e(text: str) -> str:
    """Escape plain text for HTML element content and attribute values."""
    return html.escape(text, quote=True)


def _cell(text: str) -> str:
    return "<br>".join(_e(line) for line in text.split("\n"))


def _table(table: Table) -> list[str]:
    numeric = numeric_columns(table)

    def cls(j: int) -> str:
        return ' class="num"' if numeric[j] else ""

    out = ['<div class="table-wrap">', "<table>"]
    if table.caption:
        out.append(f"<caption>{_e(table.caption)}</caption>")
    out.append("<thead><tr>" + "".join(f'<th scope="col"{cls(j)}>{_cell(h)}</th>'
                                        for j, h in enumerate(table.header)) + "</tr></thead>")
    out.append("<tbody>")
    for row in table.rows:
        out.append("<tr>" + "".join(f"<td{cls(j)}>{_cell(c)}</td>" for j, c in enumerate(row))
                   + "</tr>")
    out.append("</tbody>")
    out.append("</table>")
    if table.notes:
        out.append(f'<p class="notes">{_e(table.notes)}</p>')
    out.append("</div>")
    return out


def _figure(caption: str, alt: str, file: FigureFile) -> list[str]:
    src = "data:image/png;base64," + base64.b64encode(file.data).decode("ascii")
    out = ["<figure>",
           f'<img src="{src}" alt="{_e(alt or caption)}" width="{file.width}" '
           f'height="{file.height}" data-file="{_e(file.relative)}">']
    if caption:
        out.append(f"<figcaption>{_e(caption)}</figcaption>")
    out.append("</figure>")
    return out


def _section(section: Section, anchor: str, files: list[FigureFile]) -> list[str]:
    out = [f'<section id="{_e(anchor)}">', f"<h2>{_e(section.title)}</h2>"]
    out += [f"<p>{_e(p)}</p>" for p in section.paragraphs if p.strip()]
    for table in section.tables:
        out += _table(table)
    for figure, file in zip(section.figures, files, strict=True):
        out += _figure(figure.caption, figure.alt, file)
    out.append("</section>")
    return out


def _page(report: Report, layout: Layout) -> str:
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f'<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f'<meta name="generator" content="leadthrough {_e(__version__)}">',
           f"<title>{_e(report.title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>",
           '<div class="page">', "<header>", f"<h1>{_e(report.title)}</h1>"]
    if report.subtitle:
        out.append(f'<p class="subtitle">{_e(report.subtitle)}</p>')
    if report.meta_line():
        out.append(f'<p class="meta">{_e(report.meta_line())}</p>')
    out.append("</header>")
    if report.sections:
        out += ['<nav class="toc" aria-label="Contents">', "<h2>Contents</h2>", "<ol>"]
        out += [f'<li><a href="#{_e(a)}">{_e(s.title)}</a></li>'
                for s, a in zip(report.sections, layout.anchors, strict=True)]
        out += ["</ol>", "</nav>"]
    out.append("<main>")
    for section, anchor, files in zip(report.sections, layout.anchors, layout.figures,
                                      strict=True):
        out += _section(section, anchor, files)
    out += ["</main>", f"<footer><p>{_e(report.footer_line())}</p></footer>", "</div>",
            "</body>", "</html>", ""]
    return "\n".join(out)


def render_html(report: Report, out_dir: str | Path) -> str:
    """The report as a self-contained HTML page (nothing is written).

    Args:
        report: The report.
        out_dir: The report folder holding the figures.

    Returns:
        The HTML text.

    Raises:
        DataError: The report or a figure is invalid (see :func:`check_report`).
    """
    return _page(report, check_report(report, out_dir))


def write_html(report: Report, out_dir: str | Path) -> Path:
    """Write ``report.html`` into the report folder, atomically.

    Everything is checked and rendered before the file is created, so on an error no file (and
    no partial file) is left behind and an existing report.html is kept unchanged.

    Args:
        report: The report.
        out_dir: The report folder; must exist and hold the figures.

    Returns:
        The path of report.html.

    Raises:
        DataError: The folder is missing, or the report or a figure is invalid (the message
            names the field, e.g. ``sections[0].figures[1].path``, the value and what was
            expected).
    """
    text = render_html(report, out_dir)
    return atomic_write_text(Path(out_dir) / HTML_NAME, text)
