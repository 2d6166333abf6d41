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
from the source as it is now. Where the package folder is read-only (numba then caches in the
user's cache folder, beyond this module's reach) it does nothing; a running process keeps what
it has loaded (Numba tolerates cache files that vanish).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["STAMP", "refresh_compiled_cache", "source_digest"]

#: The digest file, under the package root's ``__pycache__``.
STAMP = "compiled-source.sha256"


def source_digest(root: Path) -> str:
    """SHA-256 over the relative path and content of every ``.py`` file under ``root``, in
    sorted order (hex)."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
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
    try:
        for cache in root.rglob("__pycache__"):
            for f in cache.iterdir():
                if f.suffix in (".nbi", ".nbc"):
                    f.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{STAMP}.{os.getpid()}.tmp")
        tmp.write_text(digest + "\n")
        tmp.replace(stamp)
    except OSError:
        return False    # a read-only install: numba caches elsewhere
    return True
