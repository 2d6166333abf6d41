"""The package's shape: the layers as the folders draw them, short functions, named state.

* the driver protocol and the real-time loop load nothing of the simulator (MuJoCo);
* no package of the pipeline imports the simulator, the CLI, the demo or the report, and no
  layer imports a later one (the real-time control does not import the estimator, the estimator
  not the controller, identification not estimation);
* no function in ``src/`` is longer than 80 lines;
* no module defines slot indices (``A, B, C = range(3)``): state is named fields;
* no import circle among the package's modules (module-level imports, those under
  ``if TYPE_CHECKING:`` included: a circle of types is still two modules that need each other);
* no two classes in ``src/`` share a name (one name, one thing).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src" / "leadthrough"

#: Package → packages of leadthrough it may not import (besides the simulator and the apps).
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "robot": ("dynamics", "excitation", "data", "identification", "estimation", "control",
              "session", "drivers", "teach"),
    "dynamics": ("excitation", "data", "identification", "estimation", "control", "session",
                 "drivers", "teach"),
    "identification": ("estimation", "control", "session", "drivers", "teach"),
    "estimation": ("control", "session", "drivers", "teach"),
    "control": ("estimation", "identification", "session", "drivers", "teach"),
    "drivers": ("dynamics", "excitation", "identification", "estimation", "control", "session",
                "teach"),
    "session": ("teach",),
    "teach": ("control", "estimation", "identification", "drivers"),
}
#: The simulator and the apps (the apps wire everything together).
APPS = ("sim", "cli", "demo", "report", "pendant")
#: Only these import them.
MAY_IMPORT_APPS = (*APPS, "__main__")


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return {n for n in names if n == "leadthrough" or n.startswith("leadthrough.")}


def _package(path: Path) -> str:
    rel = path.relative_to(SRC).parts
    return rel[0] if len(rel) > 1 else rel[0].removesuffix(".py")


@pytest.mark.parametrize("module", ["leadthrough.drivers.protocol", "leadthrough.session.loop",
                                    "leadthrough.session.loop_config"])
def test_the_real_time_side_loads_nothing_of_the_simulator(module: str) -> None:
    code = (f"import sys, {module}; bad = [m for m in sys.modules if m == 'mujoco' or "
            "m.startswith('leadthrough.sim')]; print(bad); sys.exit(1 if bad else 0)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stdout + done.stderr


def test_layers_import_only_what_the_pipeline_allows() -> None:
    wrong = []
    for path in _modules():
        pkg = _package(path)
        for name in _imports(path):
            target = name.split(".")[1] if "." in name else ""
            if target in APPS and pkg not in MAY_IMPORT_APPS:
                wrong.append(f"{path.relative_to(SRC)} imports {name}")
            if target in FORBIDDEN.get(pkg, ()):
                wrong.append(f"{path.relative_to(SRC)} imports {name}")
    assert not wrong, "\n".join(wrong)


#: Packages that read a session file but import nothing of the real-time loop or the pendant.
READ_SESSIONS_ONLY = ("teach", "report")
#: What they may not import (the session's format is the top-level ``session_format``).
REAL_TIME = ("leadthrough.session", "leadthrough.pendant")


def _all_imports(source: str, package: str) -> set[str]:
    """Every module ``source`` (a module of ``package``) imports, anywhere in it (inside
    functions too), relative imports resolved; ``from P import x`` counts ``P`` and ``P.x``."""
    parts = package.split(".")
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = parts[:len(parts) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def _reaches(name: str, packages: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def test_the_import_finder_sees_lazy_relative_and_from_package_imports() -> None:
    source = ("import numpy\n"
              "def f():\n    from leadthrough.session.loop import run_session\n"
              "def g():\n    from ..pendant import backend\n"
              "from leadthrough import session\n")
    found = _all_imports(source, "leadthrough.teach")
    assert {"leadthrough.session.loop", "leadthrough.pendant.backend",
            "leadthrough.session"} <= found
    assert not _reaches("leadthrough.session_format", REAL_TIME)
    assert _reaches("leadthrough.session", REAL_TIME)


def test_teach_and_report_import_nothing_of_the_loop_or_the_pendant() -> None:
    wrong = []
    for path in _modules():
        if _package(path) not in READ_SESSIONS_ONLY:
            continue
        module = _module_name(path)
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for name in _all_imports(path.read_text(encoding="utf-8"), package):
            if _reaches(name, REAL_TIME):
                wrong.append(f"{path.relative_to(SRC)} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_no_function_is_longer_than_80_lines() -> None:
    long = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > 80:
                    long.append(f"{path.relative_to(SRC)}:{node.lineno} {node.name} ({lines})")
    assert not long, "\n".join(long)


def test_state_is_named_not_indexed_by_slot_constants() -> None:
    """No ``NAME_A, NAME_B, ... = range(k)`` slot tables (the records name their fields)."""
    slots = []
    for path in _modules():
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) \
                    and isinstance(node.value.func, ast.Name) and node.value.func.id == "range" \
                    and isinstance(node.targets[0], ast.Tuple):
                slots.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert not slots, "\n".join(slots)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _top_level(body: list[ast.stmt]) -> list[ast.stmt]:
    """The module's statements, those under a module-level ``if`` (``TYPE_CHECKING``) or
    ``try`` included, not those of functions and classes."""
    out: list[ast.stmt] = []
    for node in body:
        out.append(node)
        if isinstance(node, ast.If):
            out += _top_level(node.body) + _top_level(node.orelse)
        elif isinstance(node, ast.Try):
            out += _top_level(node.body + node.orelse + node.finalbody)
            for handler in node.handlers:
                out += _top_level(handler.body)
    return out


def _import_graph() -> dict[str, set[str]]:
    """Module → the package's modules it imports at module level. ``from P import x`` is an
    import of the module ``P.x`` where that is a module, else of ``P``."""
    paths = {_module_name(p): p for p in _modules()}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        deps: set[str] = set()
        for node in _top_level(ast.parse(path.read_text(encoding="utf-8")).body):
            if isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                subs = {f"{base}.{a.name}" for a in node.names} & paths.keys()
                deps |= subs
                if len(subs) < len(node.names):
                    deps.add(base)
        graph[name] = {d for d in deps if d in paths and d != name}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One circle (a path back to its start) per strongly connected group of ``graph``."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while (w := stack.pop()) != v:
                group.append(w)
            group.append(v)
            if len(group) > 1:
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    circles = []
    for group in groups:
        members, start = set(group), min(group)
        path, seen = [start], {start}
        while True:       # walk inside the group until a module repeats: a circle
            nxt = min(graph[path[-1]] & members)
            if nxt in seen:
                circles.append([*path[path.index(nxt):], nxt])
                break
            path.append(nxt)
            seen.add(nxt)
    return circles


def test_no_import_circle_among_the_packages_modules() -> None:
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    graph = _import_graph()
    assert "leadthrough.session.servo_loop" in graph["leadthrough.session.loop"]
    circles = _circles(graph)
    assert not circles, "\n".join(" -> ".join(c) for c in circles)


def test_no_two_classes_share_a_name() -> None:
    where: dict[str, list[str]] = defaultdict(list)
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                where[node.name].append(f"{path.relative_to(SRC)}:{node.lineno}")
    shared = {name: places for name, places in where.items() if len(places) > 1}
    assert not shared, "\n".join(f"{n}: {', '.join(p)}" for n, p in sorted(shared.items()))
