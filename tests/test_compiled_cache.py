"""The compiled-function cache follows the whole package's source (leadthrough.compiled_cache):
numba's own cache does not see a change in another file's function that a cached one calls."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from leadthrough.compiled_cache import STAMP, refresh_compiled_cache, source_digest

CALLER = """from numba import njit
from {pkg}.callee import value


@njit(cache=True)
def call():
    return value()
"""
CALLEE = """from numba import njit


@njit(cache=True)
def value():
    return {value}
"""
REFRESH = """from pathlib import Path
from leadthrough.compiled_cache import refresh_compiled_cache
refresh_compiled_cache(Path(__file__).parent)
"""


def _package(root: Path, name: str, refresh: bool) -> Path:
    pkg = root / name
    pkg.mkdir()
    (pkg / "__init__.py").write_text(REFRESH if refresh else "")
    (pkg / "caller.py").write_text(CALLER.format(pkg=name))
    (pkg / "callee.py").write_text(CALLEE.format(value=1))
    return pkg


def _call(root: Path, name: str) -> int:
    out = subprocess.run([sys.executable, "-c", f"import {name}.caller as c; print(c.call())"],
                         cwd=root, capture_output=True, text=True, check=True)
    return int(out.stdout)


def test_a_change_in_a_called_file_recompiles_the_caller(tmp_path: Path) -> None:
    """A cached caller of a function in another file: after that file changes, plain numba
    still runs the old callee (its limitation); with the refresh at import, the new one."""
    for name, refresh, after in (("plain", False, 1), ("refreshed", True, 22)):
        pkg = _package(tmp_path, name, refresh)
        assert _call(tmp_path, name) == 1
        assert any(pkg.glob("__pycache__/caller.call-*.nbc"))      # cached on disk
        (pkg / "callee.py").write_text(CALLEE.format(value=22))
        assert _call(tmp_path, name) == after


def test_refresh_deletes_caches_only_when_the_source_changed(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cache = pkg / "sub" / "__pycache__" / "b.f-3.py311.nbi"
    other = pkg / "sub" / "__pycache__" / "b.cpython-311.pyc"
    cache.write_bytes(b"index")
    other.write_bytes(b"bytecode")
    assert refresh_compiled_cache(pkg)                       # no digest yet: refreshed
    assert not cache.exists() and other.exists()
    assert (pkg / "__pycache__" / STAMP).read_text().strip() == source_digest(pkg)
    cache.write_bytes(b"index")
    assert not refresh_compiled_cache(pkg) and cache.exists()   # unchanged: kept
    (pkg / "a.py").write_text("x = 3\n")
    assert refresh_compiled_cache(pkg) and not cache.exists()   # changed: deleted
    digest = source_digest(pkg)
    (pkg / "a.py").rename(pkg / "c.py")                      # a rename is a change
    assert source_digest(pkg) != digest


def test_the_digest_skips_hidden_files_and_survives_unreadable_ones(tmp_path: Path) -> None:
    """An editor's lock file (a dangling symlink named .#x.py) and an unreadable file must not
    stop the package from importing: the digest never raises for a file."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    digest = source_digest(pkg)
    (pkg / ".#a.py").symlink_to(pkg / "missing.py")
    assert source_digest(pkg) == digest                      # hidden: not hashed
    (pkg / "b.py").symlink_to(pkg / "missing.py")            # unreadable, not hidden
    assert source_digest(pkg) != digest
    assert refresh_compiled_cache(pkg)
