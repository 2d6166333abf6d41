"""Column maps: load real controller logs as they are, without reformatting.

A small TOML file says which columns of a delimited text log are time, joint positions, motor
current or joint torque, with units and scale factors. Example for the UR10e logs of Mamedov et
al. (headerless, 31 columns, current × drive gain = joint torque)::

    delimiter = ","
    skip_rows = 0                   # header lines to skip
    drop_abs_above = 1e4            # optional: rows with any |value| above are corrupt → dropped
    drop_non_increasing_time = true # optional: drop rows whose time does not increase

    [time]
    column = 0                      # 0-based
    unit = "s"                      # s | ms | us | ns

    [q]
    columns = [1, 2, 3, 4, 5, 6]
    unit = "rad"                    # rad | deg
    scale = 1.0                     # optional: scalar or one per joint (e.g. −1 flips a joint)
    offset = 0.0                    # optional: added after scaling [rad]

    [torque]                        # or [current] with unit "A" | "mA"
    columns = [13, 14, 15, 16, 17, 18]
    unit = "N·m"                    # N·m | Nm
    scale = [11.976, 11.976, 9.839, 10.763, 10.763, 10.763]

    [q_cmd]                         # optional, like [q]

Logs split over several files, one per signal, as some controllers write them (each file with
its own time column, rows not aligned across files): give each signal table a ``file`` (relative
to the recording folder, which is what you then load) and the rows are joined on equal time::

    delimiter = ","
    drop_unterminated_last_row = true   # optional: a last line without newline was cut off
    join_tolerance_s = 1e-6             # optional: times closer than this are equal [s]

    [time]
    column = 0                          # the time column of every file
    unit = "s"

    [q]
    file = "log_q_actual.csv"
    columns = [1, 2, 3, 4, 5, 6]

    [current]
    file = "log_i_actual.csv"
    columns = [1, 2, 3, 4, 5, 6]

MATLAB files (``format = "mat"``) name a struct and, per signal, a field holding a
(joints, samples) or (samples, joints) array instead of columns::

    format = "mat"
    struct = "rec"
    [time]
    field = "time_cont"
    [q]
    field = "act_pos_mot_deg"
    unit = "deg"
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.fileio import read_toml

__all__ = ["ColumnMap", "Signal", "parse_column_map"]

_UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9},
    "q": {"rad": 1.0, "deg": math.pi / 180.0},
    "q_cmd": {"rad": 1.0, "deg": math.pi / 180.0},
    "current": {"A": 1.0, "mA": 1e-3},
    "torque": {"N·m": 1.0, "Nm": 1.0, "N*m": 1.0, "mN·m": 1e-3},
}


@dataclass(frozen=True)
class Signal:
    """One mapped signal.

    Attributes:
        columns: 0-based column indices, one per joint (one for time); empty for MAT fields.
        factor: Multiplier to SI (unit × scale), shape (joints,) or (1,).
        offset: Added after scaling, same shape.
        field: Struct field name (MAT files), else None.
        file: File holding the signal, relative to the recording folder (logs split over
            several files), else None.
    """

    columns: tuple[int, ...]
    factor: NDArray[np.float64]
    offset: NDArray[np.float64]
    field: str | None = None
    file: str | None = None

    def extract(self, table: NDArray[np.float64]) -> NDArray[np.float64]:
        """Scaled columns of a (rows, cols) table, shape (rows, len(columns))."""
        return table[:, list(self.columns)] * self.factor + self.offset


@dataclass(frozen=True)
class ColumnMap:
    """A parsed column map (see the module docstring for the format).

    Attributes:
        path: The TOML file.
        format: ``"csv"`` (delimited text) or ``"mat"`` (MATLAB file).
        struct: Struct holding the fields (MAT files).
        delimiter: Field separator.
        skip_rows: Leading lines to skip.
        drop_abs_above: Rows with any |value| above this are dropped (None: keep all).
        drop_non_increasing_time: Drop rows whose time does not increase.
        signals: Mapped signals by name: time, q, and current or torque, optionally q_cmd.
        drop_unterminated_last_row: Drop a last line that does not end with a newline (a log
            cut off while being written: its last value may be truncated yet still parse).
        join_tolerance_s: Logs split over several files: rows whose times differ by at most
            this are joined [s].
    """

    path: Path
    format: str
    struct: str | None
    delimiter: str
    skip_rows: int
    drop_abs_above: float | None
    drop_non_increasing_time: bool
    signals: dict[str, Signal]
    drop_unterminated_last_row: bool = False
    join_tolerance_s: float = 1e-6

    @property
    def max_column(self) -> int:
        """Largest column index used (−1 for MAT files)."""
        return max((max(s.columns) for s in self.signals.values() if s.columns), default=-1)

    @property
    def files(self) -> tuple[str, ...]:
        """Files of a log split over several files, that of [q] first; empty for one file."""
        names = [self.signals["q"].file] + [s.file for s in self.signals.values()]
        return tuple(dict.fromkeys(f for f in names if f is not None))

    def max_column_in(self, file: str) -> int:
        """Largest column index used in ``file`` of a split log (its time column included)."""
        cols = [max(s.columns) for s in self.signals.values() if s.file == file]
        return max([*cols, max(self.signals["time"].columns)])


def _vector(path: Path, field: str, value: Any, size: int, default: float,
            nonzero: bool = False) -> NDArray[np.float64]:
    """A per-joint number (one for all, or a list of ``size``); ``nonzero``: a scale (0
    would turn the signal into zeros)."""
    if value is None:
        return np.full(size, default)
    vals = value if isinstance(value, list) else [value] * size
    if len(vals) != size or not all(isinstance(v, int | float) and not isinstance(v, bool)
                                    and math.isfinite(v) and (v != 0 or not nonzero)
                                    for v in vals):
        raise DataError("malformed", source=path, field=field, value=value,
                        expected=f"a finite{' non-zero' if nonzero else ''} number or a list "
                                 f"of {size}")
    return np.asarray(vals, dtype=float)


def _signal(path: Path, name: str, table: Any, mat: bool = False, joints: int = 0) -> Signal:
    if not isinstance(table, dict):
        raise DataError("not a table", source=path, field=name, value=table,
                        expected=f"a [{name}] table")
    unit = table.get("unit", next(iter(_UNITS[name])))
    if unit not in _UNITS[name]:
        raise DataError("unknown unit", source=path, field=f"{name}.unit", value=unit,
                        expected=f"one of {sorted(_UNITS[name])}")
    if mat:
        fld = table.get("field")
        if not isinstance(fld, str) or not fld:
            raise DataError("missing", source=path, field=f"{name}.field",
                            expected="the name of the struct field")
        size = 1 if name == "time" else joints
        scale = _vector(path, f"{name}.scale", table.get("scale"), size, 1.0, nonzero=True)
        offset = _vector(path, f"{name}.offset", table.get("offset"), size, 0.0)
        return Signal(columns=(), factor=scale * _UNITS[name][unit], offset=offset, field=fld)
    key = "column" if name == "time" else "columns"
    cols = table.get(key)
    if name == "time" and isinstance(cols, int) and not isinstance(cols, bool):
        cols = [cols]
    if (not isinstance(cols, list) or not cols
            or not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0 for c in cols)):
        raise DataError("malformed", source=path, field=f"{name}.{key}", value=cols,
                        expected="a 0-based column index" if name == "time"
                        else "a list of 0-based column indices, one per joint")
    scale = _vector(path, f"{name}.scale", table.get("scale"), len(cols), 1.0, nonzero=True)
    offset = _vector(path, f"{name}.offset", table.get("offset"), len(cols), 0.0)
    file = table.get("file")
    if file is not None and (name == "time" or not isinstance(file, str) or not file
                             or Path(file).is_absolute() or ".." in Path(file).parts):
        raise DataError("malformed", source=path, field=f"{name}.file", value=file,
                        expected="no file for [time] (it is the time column of every file)"
                        if name == "time" else "a file name inside the recording folder")
    return Signal(columns=tuple(cols), factor=scale * _UNITS[name][unit], offset=offset,
                  file=file)


def parse_column_map(path: str | Path) -> ColumnMap:
    """Read and validate a column-map TOML file.

    Raises:
        DataError: The file is missing or malformed; the message names the field.
    """
    path = Path(path)
    doc = read_toml(path, "column map")
    for required in ("time", "q"):
        if required not in doc:
            raise DataError("missing", source=path, field=required,
                            expected=f"a [{required}] table")
    if ("current" in doc) == ("torque" in doc):
        raise DataError("needs exactly one of [current] and [torque]", source=path,
                        field="current/torque", expected="one signal table")
    fmt = doc.get("format", "csv")
    if fmt not in ("csv", "mat"):
        raise DataError("unknown format", source=path, field="format", value=fmt,
                        expected="'csv' or 'mat'")
    struct = doc.get("struct")
    joints = 0
    if fmt == "mat":
        joints = doc.get("joints", 0)
        if isinstance(joints, bool) or not isinstance(joints, int) or joints < 1:
            raise DataError("malformed", source=path, field="joints", value=joints,
                            expected="the number of joints (an integer >= 1) for MAT files")
        if struct is not None and not isinstance(struct, str):
            raise DataError("malformed", source=path, field="struct", value=struct,
                            expected="a struct name")
    signals: dict[str, Signal] = {
        name: _signal(path, name, doc[name], fmt == "mat", joints)
        for name in ("time", "q", "current", "torque", "q_cmd") if name in doc}
    n = len(signals["q"].columns)
    for name, sig in signals.items():
        if fmt != "mat" and name != "time" and len(sig.columns) != n:
            raise DataError("joint count differs from [q]", source=path,
                            field=f"{name}.columns", value=list(sig.columns),
                            expected=f"{n} columns")
    with_file = [name for name, sig in signals.items() if sig.file is not None]
    if with_file and len(with_file) != len(signals) - 1:
        missing = sorted(set(signals) - set(with_file) - {"time"})
        raise DataError("some signals name a file and others do not", source=path,
                        field=f"{missing[0]}.file", expected="a file for every signal table "
                        "(a log split over several files) or for none")
    join_tol = doc.get("join_tolerance_s", 1e-6)
    if isinstance(join_tol, bool) or not isinstance(join_tol, int | float) or not join_tol >= 0:
        raise DataError("malformed", source=path, field="join_tolerance_s", value=join_tol,
                        expected="a number >= 0 [s]")
    unterminated = doc.get("drop_unterminated_last_row", False)
    if not isinstance(unterminated, bool):
        raise DataError("malformed", source=path, field="drop_unterminated_last_row",
                        value=unterminated, expected="true or false")
    delimiter = doc.get("delimiter", ",")
    skip = doc.get("skip_rows", 0)
    drop_abs = doc.get("drop_abs_above")
    if not isinstance(delimiter, str) or len(delimiter) != 1:
        raise DataError("malformed", source=path, field="delimiter", value=delimiter,
                        expected="one character")
    if isinstance(skip, bool) or not isinstance(skip, int) or skip < 0:
        raise DataError("malformed", source=path, field="skip_rows", value=skip,
                        expected="an integer >= 0")
    if drop_abs is not None and (isinstance(drop_abs, bool) or not isinstance(
            drop_abs, int | float) or not drop_abs > 0):
        raise DataError("malformed", source=path, field="drop_abs_above", value=drop_abs,
                        expected="a number > 0")
    return ColumnMap(
        path=path, format=fmt, struct=struct if isinstance(struct, str) else None,
        delimiter=delimiter, skip_rows=skip,
        drop_abs_above=None if drop_abs is None else float(drop_abs),
        drop_non_increasing_time=bool(doc.get("drop_non_increasing_time", False)),
        signals=signals, drop_unterminated_last_row=unterminated,
        join_tolerance_s=float(join_tol),
    )
