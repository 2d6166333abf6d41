"""Atomic file output: write to a temporary file beside the target, then rename. And the checks
of an input file before it is parsed.

A crash or a bad input never leaves a half-written file behind. An output is never written
through or over a symbolic link (refused: a link planted where an output goes would otherwise
redirect it, or be replaced by it), and it gets a normal file's mode (``0o666`` less the
process's umask, e.g. ``0644``), like any file the user's programs create.
"""

from __future__ import annotations

import codecs
import math
import os
import tempfile
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from leadthrough.errors import DataError, LeadthroughError

__all__ = ["atomic_write", "atomic_write_text", "file_mode", "read_comment_header", "read_toml",
           "refuse_symlink", "require_file", "require_folder", "require_text", "toml_number",
           "toml_table"]

#: The first bytes of a Parquet file (its magic number).
PARQUET_MAGIC = b"PAR1"


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Create ``path`` atomically.

    Args:
        path: Target file.
        write: Called with a temporary path (same folder, same suffix) to write the content to.

    Returns:
        The target path.

    Raises:
        DataError: The folder does not exist or is not writable, or ``path`` is a symbolic
            link.
    """
    path = Path(path)
    folder = require_folder(path)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix,
                                        dir=folder)
    except OSError as e:
        raise DataError(f"cannot write into the folder ({e.strerror})", source=path,
                        expected="an existing, writable folder") from e
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.chmod(tmp, file_mode())      # mkstemp's 0600, as a normal file instead
        refuse_symlink(path)            # (again: one may have appeared while writing)
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise DataError(f"cannot write the file ({e.strerror})", source=path,
                        expected="a writable file path") from e
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def file_mode() -> int:
    """The mode a new file gets from ``open(2)``: ``0o666`` less this process's umask (read
    from ``/proc/self/status`` on Linux, which leaves it unchanged; else set and restored)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def refuse_symlink(path: str | Path) -> None:
    """Refuse an output path that is a symbolic link (dangling or not).

    Raises:
        DataError: It is one, naming its target.
    """
    path = Path(path)
    if path.is_symlink():
        raise DataError("is a symbolic link: an output is not written through or over a link",
                        source=path, field="link target", value=os.readlink(path),
                        expected="a path that is not a symbolic link (give the target's path, "
                                 "or remove the link)")


def require_folder(path: str | Path) -> Path:
    """The folder an output file goes into; check it exists before any work is done.

    Returns:
        The folder.

    Raises:
        DataError: The folder does not exist or is not writable, or the path is a folder or
            a symbolic link.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise DataError("output folder does not exist", source=path,
                        expected="an existing, writable folder")
    refuse_symlink(path)
    if path.is_dir():
        raise DataError("is a folder, not a file", source=path, expected="an output file path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise DataError("output folder is not writable", source=path,
                        expected="an existing, writable folder")
    return folder


def require_file(path: str | Path, what: str, expected: str,
                 error: type[LeadthroughError] = DataError, *, source: str | Path | None = None,
                 field: str | None = None, value: object = None) -> Path:
    """An input file; check it exists and is a file.

    Args:
        path: The file.
        what: What it is, for the message (``"params file"``).
        expected: The expected input, for the message (``"an existing TOML file"``).
        error: Exception class to raise.
        source: The file that named ``path`` (default: ``path`` itself).
        field: Field of ``source`` that named it.
        value: Its value there.

    Raises:
        LeadthroughError: ``error``: not found, or a folder.
    """
    path = Path(path)
    problem = ("is a folder, not a file" if path.is_dir()
               else "not found" if not path.is_file() else "")
    if problem:
        raise error(f"{what} {problem}", source=source if source is not None else path,
                    field=field, value=value, expected=expected)
    return path


def require_text(path: Path, what: str) -> None:
    """A delimited text file: UTF-8 throughout, checked before it is parsed (a parser meeting
    a binary file, or one bad byte in a log, fails with an unreadable message).

    Args:
        path: The file (it exists).
        what: What it is, for the message (``"log"``).

    Raises:
        DataError: A Parquet file, or the first bytes that are not UTF-8, with their line.
    """
    decoder = codecs.getincrementaldecoder("utf-8")()
    line = 1
    try:
        with Path(path).open("rb") as f:
            chunk = f.read(1 << 20)
            if chunk.startswith(PARQUET_MAGIC):
                raise DataError(f"a Parquet file given as a delimited {what}", source=path,
                                field="format", value="Parquet",
                                expected="delimited text (a Parquet recording loads without a "
                                         "column map)")
            while chunk:
                try:
                    decoder.decode(chunk)
                except UnicodeDecodeError as e:
                    line += chunk.count(b"\n", 0, e.start)
                    raise DataError(f"not text: the {what} has bytes that are not UTF-8",
                                    source=path, field=f"line {line}",
                                    value=chunk[e.start:e.start + 8].split(b"\n")[0].hex(" "),
                                    expected="UTF-8 text (a binary file given as a delimited "
                                             f"{what}?)") from e
                line += chunk.count(b"\n")
                chunk = f.read(1 << 20)
    except OSError as e:
        raise DataError(f"cannot read: {e}", source=path) from e


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write a text file atomically (UTF-8)."""

    def write(tmp: Path) -> None:
        tmp.write_text(text, encoding="utf-8")

    return atomic_write(path, write)


def read_comment_header(path: Path) -> tuple[int, dict[str, str]]:
    """Leading ``# key: value`` lines of a text file.

    Returns:
        The number of comment lines and the key/value pairs found in them.
    """
    meta: dict[str, str] = {}
    count = 0
    with Path(path).open("r", encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line.startswith("#"):
                break
            count += 1
            key, sep, value = line[1:].partition(":")
            if sep:
                meta[key.strip()] = value.strip()
    return count, meta


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """A TOML file's document.

    Args:
        path: The file.
        what: What it is, for the message (``"params file"``).

    Raises:
        DataError: Missing, a folder, not UTF-8 or not valid TOML.
    """
    path = Path(path)
    require_file(path, what, "an existing TOML file")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise DataError(f"not valid TOML: {e}", source=path) from e


def toml_number(path: Path, field: str, value: Any) -> float:
    """A TOML value that must be a finite number (not a boolean).

    Raises:
        DataError: Anything else, naming ``path`` and ``field``.
    """
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise DataError("not a finite number", source=path, field=field, value=value,
                        expected="a finite number")
    return float(value)


def toml_table(path: Path, doc: dict[str, Any], key: str, name: str | None = None
               ) -> dict[str, Any]:
    """The table ``doc[key]`` (named ``name`` in messages, default ``key``).

    Raises:
        DataError: Missing or not a table.
    """
    t = doc.get(key)
    if not isinstance(t, dict):
        raise DataError("missing", source=path, field=name or key,
                        expected=f"a [{name or key}] table")
    return t
