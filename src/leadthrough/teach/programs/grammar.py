"""The line grammar of the statements the program writers emit, and the checks every written
program passes before it is written.

A program file is read back line by line: each line must be one statement of the subset its
writer emits (a rule of the language's grammar: a regular expression over the whole line), and
the statements must come in the order the writer emits them (a sequence of segments over the
statements' codes). A line that is no statement of ours — a digital output, a wait, a move with
an inline target, a comment ended early by a newline in an embedded name — is an error naming
the file, the line and its text. The files hold printable ASCII, tabs and ``\\n`` line ends only.

What the writers embed is checked here too: labels (:func:`check_target_label`, the charset of
:mod:`leadthrough.labels`), comment text (:func:`comment_text`, anything outside
:data:`COMMENT_CHARSET` replaced by ``?``), program names (:func:`check_program_name`) and
numbers (:func:`finite`).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from dataclasses import dataclass

from leadthrough.errors import TeachError
from leadthrough.labels import LabelError, check_label

__all__ = ["COMMENT_CHARSET", "NAME_RULES", "Rule", "Statement", "check_program_name",
           "check_target_label", "comment_text", "finite", "read_statements"]

#: Characters of a comment we write (in a regular-expression class): letters, digits, space and
#: ``_ . , : ; = + - / ( ) > ' ?``. None ends a comment in any of the four languages except
#: ``;`` in a FANUC remark (:mod:`~leadthrough.teach.programs.fanuc_tp` leaves it out).
COMMENT_CHARSET = r"A-Za-z0-9 _.,:;=+\-/()>'?"
_NOT_COMMENT = re.compile(f"[^{COMMENT_CHARSET}]")
_FILE_TEXT = re.compile(r"[\t\n\x20-\x7e]*")

#: Program names per language: (pattern, rule in words).
NAME_RULES = {
    "krl": (r"[A-Za-z_][A-Za-z0-9_]{0,23}", "a letter or _, then letters, digits, _ (≤ 24)"),
    "tp": (r"[A-Za-z][A-Za-z0-9_]{0,35}", "a letter, then letters, digits, _ (≤ 36)"),
    "rapid": (r"[A-Za-z][A-Za-z0-9_]{0,31}", "a letter, then letters, digits, _ (≤ 32)"),
    "urscript": (r"[A-Za-z_][A-Za-z0-9_]{0,62}", "a letter or _, then letters, digits, _"),
}


def comment_text(text: str, *, exclude: str = "") -> str:
    """``text`` with every character outside :data:`COMMENT_CHARSET` (and those in ``exclude``)
    replaced by ``?``: safe inside a comment of each language."""
    out = _NOT_COMMENT.sub("?", text)
    for c in exclude:
        out = out.replace(c, "?")
    return out


def finite(value: float, field: str) -> float:
    """``value`` if it is a finite number, else TeachError (a NaN or infinity written into a
    program would be read by the controller as a name or a syntax error)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(value):
        raise TeachError("not a finite number", field=field, value=value,
                         expected="a finite number")
    return float(value)


def check_program_name(name: str, language: str) -> str:
    """``name`` if it is a valid program name in ``language``, else TeachError."""
    pattern, rule = NAME_RULES[language]
    if not isinstance(name, str) or not re.fullmatch(pattern, name):
        raise TeachError("not a valid program name", field="name", value=name,
                         expected=f"{language} program name: {rule}")
    return name


def check_target_label(label: str, index: int) -> str:
    """A target's label: ``""`` or mark labels joined with ``/`` (marks pressed on the same
    recorded row), each one passing :func:`leadthrough.labels.check_label`.

    Raises:
        TeachError: Naming the target and the label.
    """
    if label == "":
        return label
    if not isinstance(label, str):
        raise TeachError(f"target {index}: a label must be a string", field="label",
                         value=label, expected="mark labels")
    for part in label.split("/"):
        try:
            check_label(part, field=f"targets[{index}].label")
        except LabelError as e:
            raise TeachError(f"target {index}: {e.message}; a program writer embeds only "
                             "mark labels", field=e.field, value=e.value,
                             expected=e.expected) from e
    return label


@dataclass(frozen=True)
class Rule:
    """One statement of a language's subset.

    Attributes:
        code: One character naming it in the statement sequence.
        pattern: The whole line (``re.fullmatch``), with named groups for its values.
        what: The statement in words (for messages).
    """

    code: str
    pattern: re.Pattern[str]
    what: str

    @classmethod
    def of(cls, code: str, pattern: str, what: str) -> Rule:
        """A rule from a pattern string."""
        return cls(code, re.compile(pattern), what)


@dataclass(frozen=True)
class Statement:
    """A line read back: its rule's code, the match (values) and its 1-based line number."""

    code: str
    match: re.Match[str]
    line: int


def _tokens(text: str, rules: Sequence[Rule], file: str) -> list[Statement]:
    if not isinstance(text, str) or not _FILE_TEXT.fullmatch(text):
        bad = next((c for c in str(text) if not _FILE_TEXT.fullmatch(c)), None)
        at = str(text)[:str(text).find(bad)].count("\n") + 1 if bad else 0
        raise TeachError("a character the program writer does not emit", source=file,
                         field=f"line {at}", value=bad,
                         expected="printable ASCII, tabs and \\n line ends")
    if not text.endswith("\n"):
        raise TeachError("the program does not end with a line end", source=file,
                         expected="a text ending in \\n")
    out: list[Statement] = []
    for k, line in enumerate(text[:-1].split("\n"), start=1):
        for rule in rules:
            m = rule.pattern.fullmatch(line)
            if m is not None:
                out.append(Statement(rule.code, m, k))
                break
        else:
            raise TeachError("a statement the program writer does not emit", source=file,
                             field=f"line {k}", value=line[:80],
                             expected="only the statements leadthrough writes")
    return out


def read_statements(text: str, rules: Sequence[Rule], order: Sequence[tuple[str, bool]],
                    file: str) -> list[Statement]:
    """The statements of a program file, checked against the grammar and the order.

    Args:
        text: The file's text.
        rules: The statements of the subset (a line matching none is an error).
        order: Segments of the statement sequence, in order: (regular expression over the
            codes, repeated); a repeated segment matches zero or more times.
        file: The file (its suffix, or its path), for messages.

    Returns:
        The statements, one per line.

    Raises:
        TeachError: A character, line or statement order the writer does not emit, naming
            the file and the line.
    """
    statements = _tokens(text, rules, file)
    codes = "".join(s.code for s in statements)
    what = {r.code: r.what for r in rules}
    pos, complete = 0, True
    for pattern, repeated in order:
        segment = re.compile(pattern)
        if repeated:
            while (m := segment.match(codes, pos)) is not None and m.end() > pos:
                pos = m.end()
        elif (m := segment.match(codes, pos)) is not None:
            pos = m.end()
        else:
            complete = False
            break
    if not complete or pos != len(codes):
        if pos < len(statements):
            s = statements[pos]
            raise TeachError(f"a {what[s.code]} where the program writer does not put one",
                             source=file, field=f"line {s.line}", value=s.match.group(0)[:80],
                             expected="the statements in the order leadthrough writes them")
        raise TeachError("the program ends early", source=file, field="end",
                         expected="the statements in the order leadthrough writes them")
    return statements
