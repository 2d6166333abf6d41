"""The report's content model (:class:`Report`, :class:`Section`, :class:`Table`, :class:`Figure`)
and the checks both writers run before writing anything.

All text is plain text: the writers escape it for HTML and Markdown, so ``<``, ``&``, ``*`` or
``|`` in a caption show up literally. Numbers are formatted by the caller (table cells are
strings); a column whose non-blank cells all look like numbers is right-aligned.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from leadthrough import __version__
from leadthrough.errors import DataError
from leadthrough.fileio import require_file

__all__ = [
    "PNG_SIGNATURE",
    "Figure",
    "FigureFile",
    "Layout",
    "Report",
    "Section",
    "Table",
    "check_report",
    "is_number_cell",
    "numeric_columns",
    "slugify",
]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

# A cell counts as a number when it is a (signed, decimal or scientific) number, optionally
# followed by a short unit: "0.77", "-1.2e-3", "−3", "1,234.5", "12.3 %", "5 N", "0.8 N·m".
_NUMBER = re.compile(
    r"[+\-−±]?(?:\d+(?:[.,]\d+)*|\.\d+)(?:[eE][+\-−]?\d+)?"
    r"(?:\s*(?:%|×|[A-Za-zµμΩ°][A-Za-zµμΩ°·/²³]{0,7}))?"
)
# Cells that neither make a column numeric nor stop it from being numeric.
_BLANK_CELLS = frozenset({"", "-", "–", "—", "n/a", "na", "nan", "inf", "-inf", "+inf", "∞"})


@dataclass(frozen=True)
class Table:
    """A table of preformatted cells.

    Attributes:
        caption: Shown above the table (e.g. ``"Table II: calibration results"``); may be empty.
        header: Column names (at least one).
        rows: Body rows; every row has exactly ``len(header)`` string cells.
        notes: Small print below the table (units, sources); may be empty.
    """

    caption: str
    header: list[str]
    rows: list[list[str]]
    notes: str = ""


@dataclass(frozen=True)
class Figure:
    """A PNG image that already lies in the report folder.

    Attributes:
        path: The PNG. Absolute, or relative to the report folder (a relative path that is not
            found there is tried relative to the working directory); either way it must resolve
            to a file inside the report folder.
        caption: Shown below the image (e.g. ``"Fig. 3: measured vs model torque"``); may be empty.
        alt: Text alternative for screen readers and broken images (empty: the caption).
    """

    path: Path
    caption: str
    alt: str = ""


@dataclass(frozen=True)
class Section:
    """A titled part of the report: paragraphs, then tables, then figures.

    Attributes:
        title: Heading (non-empty); also the table-of-contents entry.
        paragraphs: Plain-text paragraphs.
        tables: Tables, in order.
        figures: Figures, in order.
    """

    title: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)


@dataclass(frozen=True)
class Report:
    """A whole report.

    Attributes:
        title: Main heading and page title (non-empty).
        subtitle: One line below the title; may be empty.
        robot: Robot name, shown in the meta line when not empty.
        seed: Simulation seed, shown in the meta line when not None.
        created_by: Footer line (empty: ``"Created by leadthrough <version>"``).
        sections: The sections, in order.
    """

    title: str
    subtitle: str = ""
    robot: str = ""
    seed: int | None = None
    created_by: str = ""
    sections: list[Section] = field(default_factory=list)

    def meta_line(self) -> str:
        """Robot and seed as one line (``"Robot: er20 · Seed: 1"``), or ``""`` if neither is set."""
        parts = []
        if self.robot:
            parts.append(f"Robot: {self.robot}")
        if self.seed is not None:
            parts.append(f"Seed: {self.seed}")
        return " · ".join(parts)

    def footer_line(self) -> str:
        """The created-by line, with the default filled in."""
        if self.created_by:
            return self.created_by
        return f"Created by leadthrough {__version__}"


@dataclass(frozen=True)
class FigureFile:
    """A checked figure file.

    Attributes:
        path: Resolved absolute path.
        relative: Path relative to the report folder, POSIX style (for links).
        data: The PNG bytes.
        width: Image width [px] from the PNG header.
        height: Image height [px] from the PNG header.
    """

    path: Path
    relative: str
    data: bytes
    width: int
    height: int


@dataclass(frozen=True)
class Layout:
    """What the writers need beyond the report itself, computed by :func:`check_report`.

    Attributes:
        root: Resolved report folder.
        anchors: One unique anchor per section (GitHub-style heading slugs).
        figures: Checked figure files, per section, in order.
    """

    root: Path
    anchors: list[str]
    figures: list[list[FigureFile]]


def slugify(text: str, seen: dict[str, int]) -> str:
    """GitHub-style heading anchor, made unique against ``seen`` (which is updated).

    Lower case, punctuation dropped, spaces to hyphens; repeats get ``-1``, ``-2``, ... as on
    GitHub, so the same anchors work in report.html and in report.md rendered by GitHub.
    """
    base = re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-") or "section"
    slug = base
    while slug in seen:
        seen[base] += 1
        slug = f"{base}-{seen[base]}"
    seen.setdefault(slug, 0)
    return slug


def is_number_cell(cell: str) -> bool:
    """Whether a table cell reads as a number (possibly with a short unit)."""
    return _NUMBER.fullmatch(cell.strip()) is not None


def numeric_columns(table: Table) -> list[bool]:
    """Per column: True if it has a number and all its non-blank body cells are numbers."""
    flags = []
    for j in range(len(table.header)):
        cells = [row[j].strip() for row in table.rows]
        filled = [c for c in cells if c.lower() not in _BLANK_CELLS]
        flags.append(bool(filled) and all(is_number_cell(c) for c in filled))
    return flags


def _require_text(value: Any, name: str, *, nonempty: bool = False) -> None:
    if not isinstance(value, str):
        raise DataError("not a string", field=name, value=value,
                        expected="a str (format numbers first, e.g. f'{x:.3f}')")
    if nonempty and not value.strip():
        raise DataError("is empty", field=name, value=value, expected="a non-empty string")


def _require_list(value: Any, name: str, what: str) -> None:
    if not isinstance(value, list | tuple):
        raise DataError("not a list", field=name, value=value, expected=f"a list of {what}")


def _check_table(table: Any, name: str) -> None:
    if not isinstance(table, Table):
        raise DataError("not a Table", field=name, value=table, expected="a Table")
    _require_text(table.caption, f"{name}.caption")
    _require_text(table.notes, f"{name}.notes")
    _require_list(table.header, f"{name}.header", "column names")
    if not table.header:
        raise DataError("has no columns", field=f"{name}.header", value=table.header,
                        expected="at least one column name")
    for j, cell in enumerate(table.header):
        _require_text(cell, f"{name}.header[{j}]")
    _require_list(table.rows, f"{name}.rows", "rows")
    for i, row in enumerate(table.rows):
        _require_list(row, f"{name}.rows[{i}]", "cells")
        if len(row) != len(table.header):
            raise DataError(f"has {len(row)} cells", field=f"{name}.rows[{i}]", value=list(row),
                            expected=f"{len(table.header)} cells, one per header column "
                            f"{list(table.header)}")
        for j, cell in enumerate(row):
            _require_text(cell, f"{name}.rows[{i}][{j}]")


def _png_size(data: bytes, path: Path, name: str) -> tuple[int, int]:
    if len(data) < 24 or not data.startswith(PNG_SIGNATURE) or data[12:16] != b"IHDR":
        raise DataError("is not a PNG image", source=path, field=f"{name}.path",
                        value=str(path), expected="a PNG file (e.g. saved by matplotlib)")
    width = int.from_bytes(data[16:20], "big")
    height = int.from_bytes(data[20:24], "big")
    if width <= 0 or height <= 0:
        raise DataError(f"PNG has size {width}x{height}", source=path, field=f"{name}.path",
                        value=str(path), expected="a non-empty image")
    return width, height


def _check_figure(figure: Any, name: str, root: Path) -> FigureFile:
    if not isinstance(figure, Figure):
        raise DataError("not a Figure", field=name, value=figure, expected="a Figure")
    _require_text(figure.caption, f"{name}.caption")
    _require_text(figure.alt, f"{name}.alt")
    if not isinstance(figure.path, str | Path) or not str(figure.path):
        raise DataError("not a file path", field=f"{name}.path", value=figure.path,
                        expected="a Path to a PNG inside the report folder")
    given = Path(figure.path)
    candidate = given if given.is_absolute() else root / given
    if not given.is_absolute() and not candidate.exists() and given.exists():
        candidate = given  # relative to the working directory, e.g. Path("report/fig3.png")
    path = candidate.resolve()
    if not path.is_relative_to(root):
        raise DataError("lies outside the report folder", field=f"{name}.path",
                        value=str(figure.path),
                        expected=f"a PNG inside {root} (save the figure there first)")
    require_file(path, "figure file", f"an existing PNG inside {root}", field=f"{name}.path",
                 value=str(figure.path))
    try:
        data = path.read_bytes()
    except OSError as e:
        raise DataError(f"cannot read figure: {e.strerror or e}", source=path,
                        field=f"{name}.path", value=str(figure.path),
                        expected="a readable PNG") from e
    width, height = _png_size(data, path, name)
    return FigureFile(path=path, relative=path.relative_to(root).as_posix(), data=data,
                      width=width, height=height)


def check_report(report: Report, out_dir: str | Path) -> Layout:
    """Check a report against its folder before anything is written.

    Args:
        report: The report.
        out_dir: The report folder (must exist; figures must lie inside it).

    Returns:
        Section anchors and the checked figure files.

    Raises:
        DataError: Naming the offending field (e.g. ``sections[1].tables[0].rows[2]``), its
            value and what was expected: a missing folder, an empty title, a table row with the
            wrong number of cells, a non-string cell, a missing or non-PNG figure, or a figure
            outside the report folder.
    """
    folder = Path(out_dir)
    if not folder.is_dir():
        raise DataError("report folder does not exist", source=folder,
                        expected="an existing folder holding the report's figures")
    root = folder.resolve()
    if not isinstance(report, Report):
        raise DataError("not a Report", field="report", value=report, expected="a Report")
    _require_text(report.title, "title", nonempty=True)
    for name in ("subtitle", "robot", "created_by"):
        _require_text(getattr(report, name), name)
    if report.seed is not None and (isinstance(report.seed, bool)
                                    or not isinstance(report.seed, int)):
        raise DataError("not an integer", field="seed", value=report.seed,
                        expected="an int or None")
    _require_list(report.sections, "sections", "Section")
    seen: dict[str, int] = {}
    slugify(report.title, seen)  # the page's own headings come first, as GitHub counts them
    if report.sections:
        slugify("Contents", seen)
    anchors: list[str] = []
    figures: list[list[FigureFile]] = []
    for s, section in enumerate(report.sections):
        name = f"sections[{s}]"
        if not isinstance(section, Section):
            raise DataError("not a Section", field=name, value=section, expected="a Section")
        _require_text(section.title, f"{name}.title", nonempty=True)
        _require_list(section.paragraphs, f"{name}.paragraphs", "strings")
        for p, text in enumerate(section.paragraphs):
            _require_text(text, f"{name}.paragraphs[{p}]")
        _require_list(section.tables, f"{name}.tables", "Table")
        for t, table in enumerate(section.tables):
            _check_table(table, f"{name}.tables[{t}]")
        _require_list(section.figures, f"{name}.figures", "Figure")
        figures.append([_check_figure(f, f"{name}.figures[{k}]", root)
                        for k, f in enumerate(section.figures)])
        anchors.append(slugify(section.title, seen))
    return Layout(root=root, anchors=anchors, figures=figures)
