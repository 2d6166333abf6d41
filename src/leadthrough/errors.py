"""Exception hierarchy.

Every error the package raises on purpose derives from :class:`LeadthroughError`. Subclasses carry
the offending source (file), field, value and what was expected, so that a message always tells the
user what to fix. Backend errors (Pinocchio, MuJoCo, TOML parsing) are wrapped with ``from e``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

__all__ = [
    "ControlError",
    "DataError",
    "DataWarning",
    "DriverError",
    "LeadthroughError",
    "MissingPackageError",
    "RobotFileError",
    "SimulationError",
    "TeachError",
    "UnknownRobotError",
    "check_fields",
    "check_period",
]


class LeadthroughError(Exception):
    """Root of all leadthrough errors.

    Attributes:
        source: File (or other input) the problem was found in, if any.
        field: Name of the offending field or column, if any.
        value: The offending value, if any.
        expected: What would have been accepted, in words.
    """

    def __init__(
        self,
        message: str,
        *,
        source: str | Path | None = None,
        field: str | None = None,
        value: Any = None,
        expected: str | None = None,
    ) -> None:
        self.source = str(source) if source is not None else None
        self.field = field
        self.value = value
        self.expected = expected
        self.message = message
        super().__init__(self._format())

    def _format(self) -> str:
        parts: list[str] = []
        if self.source is not None:
            parts.append(f"{self.source}:")
        if self.field is not None:
            parts.append(f"field '{self.field}'")
            if self.value is not None:
                parts.append(f"= {self.value!r}")
            parts[-1] += ":"
        parts.append(self.message)
        if self.expected is not None:
            parts.append(f"(expected {self.expected})")
        return " ".join(parts)


class RobotFileError(LeadthroughError):
    """A robot description (URDF or drive TOML) is missing, unreadable or inconsistent."""


class UnknownRobotError(RobotFileError):
    """A robot name is neither a built-in robot nor a path to a robot TOML file."""


class DataError(LeadthroughError):
    """A recording, trajectory or parameter file is malformed or does not fit the robot."""


class SimulationError(LeadthroughError):
    """The simulated robot was configured with invalid settings."""


class TeachError(LeadthroughError):
    """A taught path cannot be made or exported: missing or ambiguous marks, a degenerate welding
    line, or a waypoint outside the joint position or speed limits at the programmed speed."""


class ControlError(LeadthroughError):
    """The guiding controller was configured with invalid settings or started from an invalid
    state (pose outside the joint limits or the workspace box, missing optional package)."""


class MissingPackageError(LeadthroughError):
    """An optional package that a command needs (an extra, e.g. the pendant's web stack) is
    not installed; ``expected`` says how to install it."""


class DriverError(LeadthroughError):
    """The link to a robot controller failed or does not fit: it cannot be reached, it refused
    the stream or a request, it does not match the robot file (joint count, units, limits), it
    broke mid-session or a call timed out."""


def check_fields(prefix: str, obj: Any, checks: list[tuple[str, bool, str]],
                 error: type[LeadthroughError] | None = None) -> None:
    """Raise for the first failed check of a settings object.

    Args:
        prefix: Prefix of the field names in messages (e.g. ``"excitation"``).
        obj: The settings object (its attributes give the offending values).
        checks: (attribute name, passed, expected range in words) triples.
        error: Exception class to raise (default :class:`DataError`).

    Raises:
        LeadthroughError: Naming ``prefix.name``, the value and the expected range.
    """
    cls = error if error is not None else DataError
    for name, ok, expected in checks:
        if not ok:
            raise cls("out of range", field=f"{prefix}.{name}", value=getattr(obj, name),
                      expected=expected)


def check_period(name: str, value: float, error: type[LeadthroughError] | None = None) -> None:
    """Raise unless a time step is finite and positive.

    Args:
        name: Field name in the message (e.g. ``"dt"``).
        value: The time step [s].
        error: Exception class to raise (default :class:`DataError`).

    Raises:
        LeadthroughError: Naming the field, the value and "finite and > 0 s".
    """
    if not (math.isfinite(value) and value > 0):
        cls = error if error is not None else DataError
        raise cls("out of range", field=name, value=value, expected="finite and > 0 s")


class DataWarning(UserWarning):
    """Data were usable but something was dropped or adjusted (e.g. rows with NaN)."""
