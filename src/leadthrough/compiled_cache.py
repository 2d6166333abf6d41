"""Numba's on-disk cache of compiled functions, kept in step with the whole package's source.

Numba keys a cached function (``@njit(cache=True)``) on its own source file only. A function it
calls from another file is compiled into the caller, and a change to that file does not
invalidate the caller's cache ("Notes on Caching", Cache limitations: "changes in symbols
defined in another file are not recognised"; numba/numba PR #8396 would extend the
invalidation; Numba 0.68.1 does not, as ``tests/test_compiled_cache.py`` shows). So after an
update that changes ``control/safety_rules.py`` but not ``control/guiding_cycle.py``, the
guiding cycle would go on running the old safety rules from its cache: that happened while
this module was written (the collision rule's change did not show until the caches were
deleted).

:func:`refresh_compiled_cache` (run when the package is imported, before any compiled function
is loaded) hashes every ``.py`` file of the package and compares the digest with the one it
wrote last to ``__pycache__/compiled-source.sha256`` at the package root. When they differ,
it deletes the package's cache files (``*.nbi``, ``*.nbc`` under its ``__pycache__``
folders), then writes the new digest: every function compiles again on its next first call,
from the source as it is now. The digest is written only once every cache file is gone, so a
file that could not be deleted is tried again at the next import.

What it does not cover: where the package folder is read-only, or ``NUMBA_CACHE_DIR`` is set,
Numba caches in another folder, beyond this module's reach; and a process that was already
running when the source changed, and compiles a caller only afterwards, writes that caller's
cache from the code it had loaded (the digest then matches the new source, so only the next
change deletes it). After updating, restart the processes that use leadthrough.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["STAMP", "refresh_compiled_cache", "source_digest"]

#: The digest file, under the package root's ``__pycache__``.
STAMP = "compiled-source.sha256"


def source_digest(root: Path) -> str:
    """SHA-256 over the relative path and content of every ``.py`` file under ``root`` (not
    hidden ones, such as an editor's lock files), in sorted order (hex). A file that cannot be
    read counts by its name and a marker, so that reading it later changes the digest; this
    never raises for a file."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if any(part.startswith(".") for part in rel.parts):
            continue
        h.update(rel.as_posix().encode())
        h.update(b"\0")
        try:
            h.update(path.read_bytes())
        except OSError:
            h.update(b"\0unreadable")
        h.update(b"\0")
    return h.hexdigest()


def refresh_compiled_cache(root: Path) -> bool:
    """Delete the compiled-function caches under ``root`` if its source changed since the
    digest was last written.

    Args:
        root: The package folder.

    Returns:
        Whether caches were deleted (or the digest was written for the first time).
    """
    stamp = root / "__pycache__" / STAMP
    digest = source_digest(root)
    try:
        if stamp.read_text().strip() == digest:
            return False
    except OSError:
        pass    # no digest yet, or unreadable: refresh
    complete = True
    try:
        caches = [f for d in root.rglob("__pycache__") for f in d.iterdir()
                  if f.suffix in (".nbi", ".nbc")]
    except OSError:
        return False    # a read-only or vanishing tree: numba caches elsewhere
    for f in caches:
        try:
            f.unlink(missing_ok=True)
        except OSError:
            complete = False    # e.g. open in another process on Windows: next import
    if not complete:
        return True     # no digest: the next import deletes what is left
    try:
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{STAMP}.{os.getpid()}.tmp")
        tmp.write_text(digest + "\n")
        tmp.replace(stamp)
    except OSError:
        return False    # a read-only install: numba caches elsewhere
    return True
