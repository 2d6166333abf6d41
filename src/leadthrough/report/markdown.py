"""The report as GitHub-flavoured Markdown (``report.md``).

Tables are GFM pipe tables (numeric columns right-aligned); figures are relative image links to
the PNGs in the report folder, so report.md renders on GitHub and in editors next to its figures.
All text is escaped: ``*``, ``_``, ``|``, ``<`` and friends show up literally.
"""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import quote

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

__all__ = ["MARKDOWN_NAME", "escape_markdown", "render_markdown", "write_markdown"]

MARKDOWN_NAME = "report.md"

# CommonMark lets any ASCII punctuation be backslash-escaped. Escaped anywhere in a line: what
# can start emphasis, code, links, inline HTML, table cells, strikethrough, entity references,
# and a trailing "#" run (which would close an ATX heading).
_INLINE = re.compile(r"([\\`*_\[\]<|~]|&(?=#?\w+;)|#(?=#*$))")
# Escaped at the start of a line only: bullets ("- ", "+ "), thematic breaks and setext
# underlines ("---", "==="), headings ("# "), block quotes (">"), and ordered lists ("1. ").
_LINE_START = re.compile(r"[-+](?=\s|$)|[-=][-=\s]*$|#{1,6}(?=\s|$)|>")
_ORDERED = re.compile(r"\d{1,9}(?=[.)](?:\s|$))")


def escape_markdown(text: str) -> str:
    """Escape plain text so that Markdown shows it literally (one line per input line).

    Args:
        text: Plain text.

    Returns:
        The text with Markdown punctuation backslash-escaped and leading indentation removed.
    """
    lines = []
    for line in text.split("\n"):
        line = _INLINE.sub(r"\\\1", line.strip())
        if _LINE_START.match(line):
            line = "\\" + line
        elif match := _ORDERED.match(line):
            line = line[:match.end()] + "\\" + line[match.end():]
        lines.append(line)
    return "\n".join(lines)


def _paragraph(text: str) -> str:
    # One paragraph, as in HTML: blank lines inside the text would split it.
    return "\n".join(line for line in escape_markdown(text).split("\n") if line)


def _cell(text: str) -> str:
    return "<br>".join(escape_markdown(line) for line in text.split("\n"))


def _table(table: Table) -> list[str]:
    numeric = numeric_columns(table)
    blocks = []
    if table.caption:
        blocks.append(f"**{_paragraph(table.caption)}**")
    lines = ["| " + " | ".join(_cell(h) or " " for h in table.header) + " |",
             "|" + "|".join("---:" if n else "---" for n in numeric) + "|"]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in table.rows]
    blocks.append("\n".join(lines))
    if table.notes:
        blocks.append(_paragraph(table.notes))
    return blocks


def _figure(caption: str, alt: str, file: FigureFile) -> list[str]:
    blocks = [f"![{_paragraph(alt or caption)}]({quote(file.relative, safe='/')})"]
    if caption:
        blocks.append(f"*{_paragraph(caption)}*")
    return blocks


def _section(section: Section, files: list[FigureFile]) -> list[str]:
    blocks = [f"## {_paragraph(section.title)}"]
    blocks += [_paragraph(p) for p in section.paragraphs if p.strip()]
    for table in section.tables:
        blocks += _table(table)
    for figure, file in zip(section.figures, files, strict=True):
        blocks += _figure(figure.caption, figure.alt, file)
    return blocks


def _document(report: Report, layout: Layout) -> str:
    blocks = [f"# {_paragraph(report.title)}"]
    if report.subtitle:
        blocks.append(_paragraph(report.subtitle))
    if report.meta_line():
        blocks.append(_paragraph(report.meta_line()))
    if report.sections:
        blocks.append("## Contents")
        blocks.append("\n".join(f"{i}. [{_paragraph(s.title)}](#{a})" for i, (s, a) in
                                enumerate(zip(report.sections, layout.anchors, strict=True), 1)))
    for section, files in zip(report.sections, layout.figures, strict=True):
        blocks += _section(section, files)
    blocks += ["---", _paragraph(report.footer_line())]
    return "\n\n".join(blocks) + "\n"


def render_markdown(report: Report, out_dir: str | Path) -> str:
    """The report as GitHub-flavoured Markdown (nothing is written).

    Args:
        report: The report.
        out_dir: The report folder holding the figures (image links are relative to it).

    Returns:
        The Markdown text.

    Raises:
        DataError: The report or a figure is invalid (see :func:`check_report`).
    """
    return _document(report, check_report(report, out_dir))


def write_markdown(report: Report, out_dir: str | Path) -> Path:
    """Write ``report.md`` into the report folder, atomically.

    Everything is checked and rendered before the file is created, so on an error no file (and
    no partial file) is left behind and an existing report.md is kept unchanged.

    Args:
        report: The report.
        out_dir: The report folder; must exist and hold the figures.

    Returns:
        The path of report.md.

    Raises:
        DataError: The folder is missing, or the report or a figure is invalid (the message
            names the field, the value and what was expected).
    """
    text = render_markdown(report, out_dir)
    return atomic_write_text(Path(out_dir) / MARKDOWN_NAME, text)
