"""Report writer: self-contained report.html, GitHub-flavoured report.md, input checks, and a
headless-Chromium check that the page renders all figures (skipped without Chromium; failed
without it when CI is set)."""

from __future__ import annotations

import base64
import hashlib
import os
import re
import shutil
import subprocess
import time
from collections.abc import Callable
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pytest

from leadthrough.errors import DataError
from leadthrough.report import (
    Figure,
    Report,
    Section,
    Table,
    escape_markdown,
    is_number_cell,
    render_html,
    render_markdown,
    write_html,
    write_markdown,
)

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source",
        "track", "wbr"}
NASTY = '<script>alert("x")</script> & \'q\' *b* _i_ | `c` [l](u) # h'
# Figure colours the screenshot test looks for (one per figure, large filled areas).
COLOURS = {"fig_force.png": (255, 0, 255), "fig_path.png": (0, 176, 0),
           "fig_bars.png": (255, 128, 0)}


# ---------------------------------------------------------------- helpers and fixtures


def _save(fig: object, path: Path) -> None:
    import matplotlib.pyplot as plt

    fig.tight_layout()  # type: ignore[attr-defined]
    fig.savefig(path, dpi=80)  # type: ignore[attr-defined]
    plt.close(fig)  # type: ignore[arg-type]


def make_figures(folder: Path) -> dict[str, Path]:
    """Three small matplotlib PNGs (480x240, 400x320, 320x240 px), each with a big patch of
    its own colour from COLOURS."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 10.0, 200)
    hexes = {k: "#{:02x}{:02x}{:02x}".format(*v) for k, v in COLOURS.items()}
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.fill_between(t, 0, 30 * np.sin(t) ** 2 + 5, color=hexes["fig_force.png"])
    ax.set_xlabel("time [s]")
    ax.set_ylabel("force [N]")
    _save(fig, folder / "fig_force.png")
    fig = plt.figure(figsize=(5, 4))
    ax3 = fig.add_subplot(projection="3d")
    ax3.plot(np.sin(t), np.cos(t), t, color=hexes["fig_path.png"], lw=12)
    _save(fig, folder / "fig_path.png")
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.bar(["ols", "ols-cv", "proposed"], [3.4, 3.1, 2.4], color=hexes["fig_bars.png"])
    _save(fig, folder / "fig_bars.png")
    return {name: folder / name for name in COLOURS}


@pytest.fixture(scope="module")
def figure_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The three PNGs, made once per module."""
    return make_figures(tmp_path_factory.mktemp("figures"))


@pytest.fixture()
def out_dir(tmp_path: Path, figure_files: dict[str, Path]) -> Path:
    """A report folder holding copies of the three PNGs (fig_bars.png in a sub-folder)."""
    out = tmp_path / "report"
    (out / "sub dir").mkdir(parents=True)
    shutil.copy(figure_files["fig_force.png"], out / "fig_force.png")
    shutil.copy(figure_files["fig_path.png"], out / "fig_path.png")
    shutil.copy(figure_files["fig_bars.png"], out / "sub dir" / "fig_bars.png")
    return out


def sample_report(out: Path) -> Report:
    """Two sections: text and a table; three figures (relative, absolute, in a sub-folder)."""
    table = Table("Table II: held-out fit", ["method", "joint", "J [N·m]", "std/max [%]"],
                  [["ols", "J1", "3.45", "1.2 %"], ["ols-cv", "J1", "3.10", "—"],
                   ["proposed", "J1", "-2.4e-1", "0.9 %"]], notes="J: RMS torque error.")
    return Report(
        title="leadthrough demo", subtitle="simulated robot", robot="er20", seed=7,
        sections=[
            Section("Calibration (Table II)", ["Three methods.", "Same recordings."], [table]),
            Section("Guiding sessions", ["Two controllers."], figures=[
                Figure(Path("fig_force.png"), "Fig. 4: force vs time", alt="force plot"),
                Figure(out / "fig_path.png", "Fig. 5: TCP path"),
            ]),
            Section("Taught path", [], figures=[
                Figure(Path("sub dir/fig_bars.png"), "Fig. 6: bars", alt="bar chart")]),
        ])


class Page(HTMLParser):
    """Collects what the tests check, and whether tags nest properly."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.tags: list[tuple[str, dict[str, str]]] = []
        self.text: list[str] = []
        self.tables: list[list[list[tuple[str, str]]]] = []  # rows of (class, text) cells
        self._cell: list[str] | None = None
        self._cell_class = ""
        self.decl = ""

    def handle_decl(self, decl: str) -> None:
        self.decl = decl

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, {k: v or "" for k, v in attrs}))
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell, self._cell_class = [], dict(attrs).get("class") or ""
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1:] or 'nothing'}")
            return
        self.stack.pop()
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append((self._cell_class, "".join(self._cell)))
            self._cell = None

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)

    def find(self, tag: str) -> list[dict[str, str]]:
        return [attrs for t, attrs in self.tags if t == tag]


def parse(text: str) -> Page:
    page = Page()
    page.feed(text)
    page.close()
    return page


def md_cells(line: str) -> list[str]:
    """Cells of a GFM table row (split at unescaped pipes)."""
    assert line.startswith("| ") and line.endswith(" |"), line
    return [c.strip() for c in re.split(r"(?<!\\)\|", line[1:-1])]


# ---------------------------------------------------------------- HTML


def test_html_is_well_formed_and_self_contained(out_dir: Path) -> None:
    path = write_html(sample_report(out_dir), out_dir)
    assert path == out_dir / "report.html"
    page = parse(path.read_text(encoding="utf-8"))
    assert page.decl.lower() == "doctype html"
    assert page.errors == []
    assert page.stack == []
    tags = [t for t, _ in page.tags]
    assert "script" not in tags and "link" not in tags and "iframe" not in tags
    assert tags.count("style") == 1
    csp = [a for a in page.find("meta") if a.get("http-equiv") == "Content-Security-Policy"]
    assert csp and "default-src 'none'" in csp[0]["content"]
    # Every reference is either a data URI or an in-page anchor.
    refs = [v for _, attrs in page.tags for k, v in attrs.items() if k in ("src", "href")]
    assert refs and all(r.startswith(("data:", "#")) for r in refs)
    ids = {a["id"] for _, a in page.tags if "id" in a}
    assert {r[1:] for r in refs if r.startswith("#")} <= ids


def test_html_embeds_every_figure_byte_for_byte(out_dir: Path) -> None:
    report = sample_report(out_dir)
    page = parse(write_html(report, out_dir).read_text(encoding="utf-8"))
    imgs = page.find("img")
    expected = [out_dir / "fig_force.png", out_dir / "fig_path.png",
                out_dir / "sub dir" / "fig_bars.png"]
    assert len(imgs) == len(expected)
    sizes = {"fig_force.png": (480, 240), "fig_path.png": (400, 320), "fig_bars.png": (320, 240)}
    for img, source in zip(imgs, expected, strict=True):
        prefix = "data:image/png;base64,"
        assert img["src"].startswith(prefix)
        data = base64.b64decode(img["src"][len(prefix):], validate=True)
        assert data.startswith(b"\x89PNG\r\n\x1a\n")
        assert len(data) == source.stat().st_size
        assert data == source.read_bytes()
        assert (int(img["width"]), int(img["height"])) == sizes[source.name]
    assert [i["alt"] for i in imgs] == ["force plot", "Fig. 5: TCP path", "bar chart"]
    captions = "".join(page.text)
    for fig in ("Fig. 4: force vs time", "Fig. 5: TCP path", "Fig. 6: bars"):
        assert fig in captions


def test_html_tables_have_rows_columns_and_alignment(out_dir: Path) -> None:
    page = parse(render_html(sample_report(out_dir), out_dir))
    assert len(page.tables) == 1
    rows = page.tables[0]
    assert len(rows) == 4 and all(len(r) == 4 for r in rows)
    assert [text for _, text in rows[0]] == ["method", "joint", "J [N·m]", "std/max [%]"]
    assert [text for _, text in rows[3]] == ["proposed", "J1", "-2.4e-1", "0.9 %"]
    # Text columns left, number columns right-aligned (header included).
    for row in rows:
        assert [cls for cls, _ in row] == ["", "", "num", "num"]
    text = "".join(page.text)
    assert "Table II: held-out fit" in text and "J: RMS torque error." in text


def test_html_escapes_all_text(out_dir: Path) -> None:
    report = Report(
        title=NASTY, subtitle=NASTY, robot=NASTY, created_by=NASTY,
        sections=[Section(NASTY, [NASTY], [Table(NASTY, [NASTY, "n"], [[NASTY, "1"]], NASTY)],
                          [Figure(Path("fig_force.png"), NASTY, alt=NASTY)])])
    text = render_html(report, out_dir)
    page = parse(text)
    assert page.errors == [] and page.stack == []
    assert [t for t, _ in page.tags].count("script") == 0
    assert "<script>" not in text
    data = page.text
    # title, h1, subtitle, TOC entry, h2, paragraph, caption, th, td, notes, figcaption, footer
    assert sum(d == NASTY for d in data) >= 11
    assert "Robot: " + NASTY in data
    assert page.find("img")[0]["alt"] == NASTY
    assert page.find("title") and "<title>&lt;script&gt;" in text


def test_html_toc_anchors_are_unique_and_match_sections(out_dir: Path) -> None:
    report = Report("T", sections=[Section("Results"), Section("Results"), Section("Fig. 4 (a)"),
                                   Section("Contents")])
    page = parse(render_html(report, out_dir))
    section_ids = [a["id"] for t, a in page.tags if t == "section"]
    assert section_ids == ["results", "results-1", "fig-4-a", "contents-1"]
    toc = [a["href"] for a in page.find("a")]
    assert toc == ["#" + i for i in section_ids]


def test_html_header_and_footer(out_dir: Path) -> None:
    from leadthrough import __version__

    text = "".join(parse(render_html(sample_report(out_dir), out_dir)).text)
    assert "Robot: er20 · Seed: 7" in text
    assert f"Created by leadthrough {__version__}" in text
    bare = parse(render_html(Report("Only a title", created_by="demo, 2024-01-01"), out_dir))
    assert [t for t, _ in bare.tags].count("nav") == 0  # no sections, no contents
    assert "demo, 2024-01-01" in bare.text
    assert not any("Robot:" in d or "Seed:" in d for d in bare.text)


# ---------------------------------------------------------------- Markdown


def test_markdown_tables_and_relative_figure_links(out_dir: Path) -> None:
    path = write_markdown(sample_report(out_dir), out_dir)
    assert path == out_dir / "report.md"
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "# leadthrough demo"
    start = lines.index("| method | joint | J \\[N·m\\] | std/max \\[%\\] |")
    assert lines[start - 2] == "**Table II: held-out fit**"
    assert lines[start + 1] == "|---|---|---:|---:|"
    assert [md_cells(x) for x in lines[start + 2:start + 5]] == [
        ["ols", "J1", "3.45", "1.2 %"], ["ols-cv", "J1", "3.10", "—"],
        ["proposed", "J1", "-2.4e-1", "0.9 %"]]
    assert lines[start + 5] == "" and lines[start + 6] == "J: RMS torque error."
    links = re.findall(r"^!\[([^\]]*)\]\(([^)]+)\)$", "\n".join(lines), flags=re.M)
    assert links == [("force plot", "fig_force.png"), ("Fig. 5: TCP path", "fig_path.png"),
                     ("bar chart", "sub%20dir/fig_bars.png")]
    for _, link in links:
        assert (out_dir / unquote(link)).is_file()
    assert "*Fig. 4: force vs time*" in lines
    toc = [x for x in lines if re.match(r"\d+\. \[", x)]
    assert toc == ["1. [Calibration (Table II)](#calibration-table-ii)",
                   "2. [Guiding sessions](#guiding-sessions)", "3. [Taught path](#taught-path)"]


def test_markdown_escapes_text_and_keeps_table_shape(out_dir: Path) -> None:
    table = Table("a|b", ["x|y", "n"], [["*bold* | <b>", "2"], ["multi\nline", "3"]])
    report = Report("T *x*", sections=[Section("# not a heading", ["- not a list", "1. no"],
                                               [table])])
    text = render_markdown(report, out_dir)
    lines = text.splitlines()
    assert lines[0] == "# T \\*x\\*"
    assert "## \\# not a heading" in lines
    assert "\\- not a list" in lines and "1\\. no" in lines
    header = lines.index("| x\\|y | n |")
    assert lines[header + 1] == "|---|---:|"
    assert md_cells(lines[header + 2]) == ["\\*bold\\* \\| \\<b>", "2"]
    assert md_cells(lines[header + 3]) == ["multi<br>line", "3"]


@pytest.mark.parametrize(("text", "escaped"), [
    ("plain 1.5 N·m", "plain 1.5 N·m"), ("a*b_c", "a\\*b\\_c"), ("---", "\\---"),
    ("> quote", "\\> quote"), ("x > y", "x > y"), ("[l](u)", "\\[l\\](u)"),
    ("R&D &amp;", "R&D \\&amp;"), ("2) two", "2\\) two"), ("  indented", "indented"),
    ("C# and F #", "C# and F \\#"),
])
def test_escape_markdown(text: str, escaped: str) -> None:
    assert escape_markdown(text) == escaped


@pytest.mark.parametrize(("cell", "number"), [
    ("0.77", True), ("-1.2e-3", True), ("−3", True), ("1,234.5", True), ("12.3 %", True),
    ("5 N", True), ("0.8 N·m", True), ("J1", False), ("ols-cv", False), ("", False),
    ("1.2 ± 0.1", False),
])
def test_is_number_cell(cell: str, number: bool) -> None:
    assert is_number_cell(cell) is number


# ---------------------------------------------------------------- bad input


def _fig_section(fig: Figure) -> Report:
    return Report("T", sections=[Section("S", figures=[fig])])


def test_missing_figure_names_the_field(out_dir: Path) -> None:
    with pytest.raises(DataError, match="figure file not found") as e:
        render_html(_fig_section(Figure(Path("nope.png"), "c")), out_dir)
    assert e.value.field == "sections[0].figures[0].path"
    assert e.value.value == "nope.png"


def test_figure_outside_the_folder_is_refused(out_dir: Path, tmp_path: Path) -> None:
    outside = tmp_path / "outside.png"
    shutil.copy(out_dir / "fig_force.png", outside)
    for path in (outside, Path("../outside.png")):
        with pytest.raises(DataError, match="outside the report folder") as e:
            render_markdown(_fig_section(Figure(path, "c")), out_dir)
        assert e.value.field == "sections[0].figures[0].path"
        assert e.value.expected is not None and str(out_dir.resolve()) in e.value.expected


def test_figure_path_relative_to_working_directory(out_dir: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(out_dir.parent)
    report = _fig_section(Figure(Path("report") / "fig_force.png", "c"))
    assert "](fig_force.png)" in render_markdown(report, Path("report"))


def test_non_png_figure_is_refused(out_dir: Path) -> None:
    (out_dir / "fake.png").write_text("not an image")
    with pytest.raises(DataError, match="not a PNG") as e:
        render_html(_fig_section(Figure(Path("fake.png"), "c")), out_dir)
    assert e.value.field == "sections[0].figures[0].path"


def test_ragged_table_row_names_row_and_expected_cells(out_dir: Path) -> None:
    table = Table("t", ["a", "b", "c"], [["1", "2", "3"], ["1", "2"]])
    with pytest.raises(DataError, match="has 2 cells") as e:
        render_html(Report("T", sections=[Section("S"), Section("S2", tables=[table])]), out_dir)
    assert e.value.field == "sections[1].tables[0].rows[1]"
    assert e.value.value == ["1", "2"]
    assert e.value.expected is not None and e.value.expected.startswith("3 cells")


@pytest.mark.parametrize(("report", "field", "match"), [
    (Report(""), "title", "is empty"),
    (Report("T", sections=[Section(" ")]), "sections[0].title", "is empty"),
    (Report("T", sections=[Section("S", "one string")]),  # type: ignore[arg-type]
     "sections[0].paragraphs", "not a list"),
    (Report("T", sections=[Section("S", tables=[Table("t", ["a"], [[1.5]])])]),  # type: ignore[list-item]
     "sections[0].tables[0].rows[0][0]", "not a string"),
    (Report("T", sections=[Section("S", tables=[Table("t", [], [])])]),
     "sections[0].tables[0].header", "has no columns"),
    (Report("T", seed=1.5), "seed", "not an integer"),  # type: ignore[arg-type]
])
def test_invalid_report_fields(out_dir: Path, report: Report, field: str, match: str) -> None:
    with pytest.raises(DataError, match=match) as e:
        render_html(report, out_dir)
    assert e.value.field == field


def test_missing_report_folder(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="report folder does not exist"):
        write_html(Report("T"), tmp_path / "missing")


@pytest.mark.parametrize("write", [write_html, write_markdown])
def test_no_partial_file_on_error(out_dir: Path, write: Callable[[Report, Path], Path]) -> None:
    bad = Report("T", sections=[Section("ok", figures=[Figure(Path("fig_force.png"), "c")]),
                                Section("bad", figures=[Figure(Path("missing.png"), "c")])])
    before = sorted(p.name for p in out_dir.iterdir())
    with pytest.raises(DataError):
        write(bad, out_dir)
    assert sorted(p.name for p in out_dir.iterdir()) == before  # nothing new, no temp file
    # An existing report is kept as it was.
    good = write(sample_report(out_dir), out_dir)
    old = good.read_bytes()
    with pytest.raises(DataError):
        write(bad, out_dir)
    assert good.read_bytes() == old
    assert sorted(p.name for p in out_dir.iterdir()) == sorted([*before, good.name])


# ---------------------------------------------------------------- headless Chromium

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
# Written into the test's copy of the page only: counts images that loaded and decoded.
PROBE = ("window.addEventListener('load', function () {"
         " var imgs = Array.prototype.slice.call(document.images);"
         " var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; });"
         " document.body.dataset.loaded = ok.length + '/' + imgs.length;"
         " document.body.dataset.sizes = imgs.map(function (i) {"
         " return i.naturalWidth + 'x' + i.naturalHeight; }).join(' '); });")


def _chromium() -> str:
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    message = ("Chromium not installed (looked for " + ", ".join(CHROMIUM_NAMES)
               + "); apt-get install chromium to run")
    if os.environ.get("CI"):
        pytest.fail(message + " (CI is set: the test must run there)")
    pytest.skip(message)


def _run_chromium(binary: str, profile: Path, *args: str) -> str:
    cmd = [binary, "--headless=new", "--disable-gpu", "--no-sandbox", "--disable-dev-shm-usage",
           "--no-first-run", "--hide-scrollbars", f"--user-data-dir={profile}",
           "--virtual-time-budget=5000", *args]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, f"{cmd} failed ({done.returncode}):\n{done.stderr[-2000:]}"
    return done.stdout


def _with_probe(page: str) -> str:
    """The page with PROBE added, and allowed by the page's own CSP through its hash (so the
    page's image and style policy stays in force)."""
    digest = base64.b64encode(hashlib.sha256(PROBE.encode()).digest()).decode()
    csp = "default-src 'none';"
    assert page.count(csp) == 1
    page = page.replace(csp, f"{csp} script-src 'sha256-{digest}';")
    assert page.count("</body>") == 1
    return page.replace("</body>", f"<script>{PROBE}</script>\n</body>")


def _loaded(binary: str, tmp_path: Path, page: str, name: str) -> tuple[str, str]:
    probe = tmp_path / name
    probe.write_text(_with_probe(page), encoding="utf-8")
    dom = _run_chromium(binary, tmp_path / f"profile-{name}", "--dump-dom", probe.as_uri())
    body = re.search(r"<body([^>]*)>", dom)
    assert body is not None, dom[:500]
    loaded = re.search(r'data-loaded="([^"]*)"', body.group(1))
    sizes = re.search(r'data-sizes="([^"]*)"', body.group(1))
    assert loaded is not None and sizes is not None, f"probe did not run: <body{body.group(1)}>"
    return loaded.group(1), sizes.group(1)


def test_chromium_renders_all_figures(out_dir: Path, tmp_path: Path) -> None:
    binary = _chromium()
    t0 = time.perf_counter()
    report_path = write_html(sample_report(out_dir), out_dir)
    page = report_path.read_text(encoding="utf-8")

    # 1. Every <img> loaded and decoded, at the PNG's own size (under the page's CSP).
    loaded, sizes = _loaded(binary, tmp_path, page, "probe.html")
    assert loaded == "3/3"
    assert sizes == "480x240 400x320 320x240"
    # The probe does notice a broken image (the check above is not vacuous).
    broken = page.replace("data:image/png;base64,iVBOR", "data:image/png;base64,AAAAA", 1)
    assert broken != page
    assert _loaded(binary, tmp_path, broken, "broken.html")[0] == "2/3"

    # 2. A screenshot of the unmodified page shows every figure.
    shot = tmp_path / "screenshot.png"
    _run_chromium(binary, tmp_path / "profile-shot", f"--screenshot={shot}",
                  "--window-size=1280,4000", report_path.as_uri())
    assert shot.is_file() and shot.stat().st_size > 20_000
    import matplotlib.image

    pixels = np.asarray(matplotlib.image.imread(shot))[..., :3]
    assert pixels.shape == (4000, 1280, 3)
    assert float(pixels.var()) > 0.0
    rgb = np.rint(pixels * 255).astype(int)
    for name, colour in COLOURS.items():
        hits = int(np.all(np.abs(rgb - np.array(colour)) <= 12, axis=-1).sum())
        assert hits > 2000, f"{name}: only {hits} pixels of its colour {colour} on screen"
    assert time.perf_counter() - t0 < 30.0
