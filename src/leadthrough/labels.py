"""Names of taught points (mark labels).

A label is a name, not text: it ends up in the comments and target names of robot programs in
four languages (FANUC TP, ABB RAPID, KUKA KRL, URScript), in file names of exports and on the
pendant's page. So every label is checked against one small charset that each of those accepts
inside an identifier or a comment, at every place a label enters: the pendant's mark request,
the session file that ``teach`` reads, and the program writers themselves.

The charset: ASCII letters, digits, ``_``, ``-``, ``.`` and the plain space, 1 to
:data:`MAX_LABEL_CHARS` characters, not starting or ending with a space. No newline, quote,
semicolon, bracket, ``<``, ``>``, ``&``, ``!`` or any other character that could end a comment
or a string in one of the target languages, or be read as markup on the page.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from leadthrough.errors import LeadthroughError

__all__ = ["LABEL_CHARSET", "MAX_LABEL_CHARS", "LabelError", "check_label", "is_label"]

#: The longest label accepted [characters].
MAX_LABEL_CHARS = 32
#: The accepted characters, in words (for error messages and help texts).
LABEL_CHARSET = "letters A-Z a-z, digits 0-9, '_', '-', '.' and spaces (not at either end)"

_LABEL = re.compile(r"[A-Za-z0-9_.\-](?:[A-Za-z0-9_.\- ]{0,"
                    + str(MAX_LABEL_CHARS - 2) + r"}[A-Za-z0-9_.\-])?")


class LabelError(LeadthroughError):
    """A mark label is not a name: wrong type, empty, too long, or a character outside
    :data:`LABEL_CHARSET`."""


def is_label(value: Any) -> bool:
    """Whether ``value`` is an acceptable label (a ``str`` of the charset and length)."""
    return isinstance(value, str) and _LABEL.fullmatch(value) is not None


def check_label(value: Any, *, source: str | Path | None = None,
                field: str = "label") -> str:
    """Return ``value`` if it is an acceptable label, else raise :class:`LabelError`.

    Args:
        value: The label as received.
        source: Where it came from (a file, ``pendant``), named in the error.
        field: The field it came in, named in the error.

    Returns:
        The label, unchanged.

    Raises:
        LabelError: naming the source, field and (a shortened form of) the value.
    """
    if is_label(value):
        return str(value)
    shown = value if not isinstance(value, str) or len(value) <= 40 else value[:40] + "..."
    if not isinstance(value, str):
        why = f"a label must be a string, not {type(value).__name__}"
    elif not value:
        why = "a label must not be empty"
    elif len(value) > MAX_LABEL_CHARS:
        why = f"a label has at most {MAX_LABEL_CHARS} characters, this one {len(value)}"
    else:
        bad = sorted({c for c in value if not re.fullmatch(r"[A-Za-z0-9_.\- ]", c)})
        why = (f"a label may not contain {', '.join(repr(c) for c in bad)}" if bad
               else "a label may not start or end with a space")
    raise LabelError(why, source=source, field=field, value=shown,
                     expected=f"1-{MAX_LABEL_CHARS} characters of {LABEL_CHARSET}")
