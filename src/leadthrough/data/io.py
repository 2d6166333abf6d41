"""Read and write recordings: our CSV (header with units), Parquet, and any log with a column map.

A column map may also describe a log split over several files (one per signal, each with its
own time column, as the UR5 logs of Kufieta 2014): load its folder, the rows are joined on time.

Our CSV::

    # leadthrough recording
    # robot: er20
    time [s],q1 [rad],...,q6 [rad],current1 [A],...,current6 [A],q_cmd1 [rad],...

Parquet files use the same column names and keep the robot name in the schema metadata (and
the simulated robot instance, ``sim_seed``, of a simulated recording; CSV: a comment line).
Writing is atomic (temporary file, then rename). Rows with non-finite values are dropped on
load and counted in a :class:`~leadthrough.errors.DataWarning`; anything else malformed raises a
:class:`~leadthrough.errors.DataError` naming the file and column.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
from numpy.typing import NDArray

from leadthrough.data.column_map import ColumnMap, parse_column_map
from leadthrough.data.recording import Recording, is_sim_seed
from leadthrough.errors import DataError, DataWarning
from leadthrough.fileio import atomic_write, read_comment_header, require_file, require_text

__all__ = ["load_recording", "save_recording"]

Array = NDArray[np.float64]
_UNIT = {"time": "s", "q": "rad", "current": "A", "torque": "N·m", "q_cmd": "rad"}
_HEADER = re.compile(r"^(time|q_cmd|q|current|torque)(\d*) \[(.+)\]$")


def _columns(rec: Recording) -> dict[str, Array]:
    cols: dict[str, Array] = {"time [s]": rec.time}
    for name in ("q", "current", "torque", "q_cmd"):
        v = getattr(rec, name)
        if v is None:
            continue
        for j in range(rec.n):
            cols[f"{name}{j + 1} [{_UNIT[name]}]"] = v[:, j]
    return cols


def save_recording(rec: Recording, path: str | Path) -> Path:
    """Write a recording as CSV or Parquet (by suffix), atomically.

    Raises:
        DataError: Unknown suffix or unwritable folder.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    cols = _columns(rec)
    if suffix == ".csv":
        def write_csv(tmp: Path) -> None:
            header = ",".join(cols)
            data = np.column_stack(list(cols.values()))
            with tmp.open("w", encoding="utf-8") as f:
                f.write("# leadthrough recording\n")
                f.write(f"# robot: {rec.robot or ''}\n")
                if rec.sim_seed is not None:
                    f.write(f"# sim_seed: {rec.sim_seed}\n")
                np.savetxt(f, data, delimiter=",", header=header, comments="", fmt="%.17g")
        return atomic_write(path, write_csv)
    if suffix in (".parquet", ".pq"):
        meta = {"leadthrough.robot": rec.robot or "", "leadthrough.kind": "recording"}
        if rec.sim_seed is not None:
            meta["leadthrough.sim_seed"] = str(rec.sim_seed)
        table = pa.table(cols).replace_schema_metadata(meta)
        return atomic_write(path, lambda tmp: pq.write_table(table, tmp))
    raise DataError("unknown recording format", source=path, field="suffix", value=suffix,
                    expected=".csv or .parquet")


def _sim_seed(value: str | None, source: str) -> int | None:
    """The ``sim_seed`` entry of a file's metadata (None if absent)."""
    if value is None or value == "":
        return None
    try:
        seed = int(value)
    except ValueError:
        seed = -1
    if not is_sim_seed(seed):
        raise DataError("malformed", source=source, field="sim_seed", value=value,
                        expected="an integer >= 0 (the simulated robot instance)")
    return seed


def _assemble(columns: dict[str, Array], source: str, robot: str | None,
              sim_seed: int | None = None) -> Recording:
    """Build a Recording from named columns, dropping rows with non-finite values."""
    groups: dict[str, dict[int, Array]] = {}
    for name, values in columns.items():
        m = _HEADER.match(name.strip())
        if m is None:
            raise DataError("unknown column", source=source, field=name,
                            expected="time [s], qJ [rad], currentJ [A], torqueJ [N·m], "
                                     "q_cmdJ [rad]")
        sig, idx, unit = m.group(1), m.group(2), m.group(3)
        if unit != _UNIT[sig]:
            raise DataError("unexpected unit", source=source, field=name, value=unit,
                            expected=f"[{_UNIT[sig]}] (use a column map to convert units)")
        groups.setdefault(sig, {})[int(idx) if idx else 0] = np.asarray(values, dtype=float)
    if "time" not in groups or "q" not in groups:
        raise DataError("missing columns", source=source, field="time/q",
                        expected="'time [s]' and 'q1 [rad]'...")
    arrays: dict[str, Array] = {"time": groups["time"][0]}
    for sig in ("q", "current", "torque", "q_cmd"):
        if sig in groups:
            idx = sorted(groups[sig])
            if idx != list(range(1, len(idx) + 1)):
                raise DataError("joint columns are not numbered 1..n", source=source,
                                field=sig, value=idx, expected="1, 2, ..., n")
            arrays[sig] = np.column_stack([groups[sig][j] for j in idx])
    return _finite_recording(arrays, source, robot, sim_seed=sim_seed)


def _finite_recording(arrays: dict[str, Array], source: str, robot: str | None,
                      extra_bad: NDArray[np.bool_] | None = None, why: str = "",
                      sim_seed: int | None = None) -> Recording:
    cut = _clean_rows(arrays, source, extra_bad, why)
    return Recording(time=cut["time"], q=cut["q"], current=cut.get("current"),
                     torque=cut.get("torque"), q_cmd=cut.get("q_cmd"), robot=robot,
                     source=source, sim_seed=sim_seed)


def _clean_rows(arrays: dict[str, Array], source: str,
                extra_bad: NDArray[np.bool_] | None = None, why: str = "") -> dict[str, Array]:
    """Drop rows with non-finite values or marked bad, with a DataWarning counting them."""
    rows = arrays["time"].shape[0]
    if rows == 0:
        raise DataError("the recording has no rows", source=source, field="time", value=0,
                        expected="at least one sample")
    good = np.ones(rows, dtype=bool)
    for v in arrays.values():
        good &= np.isfinite(v.reshape(rows, -1)).all(axis=1)
    dropped = int(rows - good.sum())
    if extra_bad is not None:
        good &= ~extra_bad
    total = int(rows - good.sum())
    if total:
        detail = f"{dropped} with non-finite values" + (f", {total - dropped} {why}" if why
                                                         and total > dropped else "")
        warnings.warn(f"{source}: dropped {total} of {rows} rows ({detail})", DataWarning,
                      stacklevel=4)
    return {k: v[good] for k, v in arrays.items()}


def _read_csv_table(path: Path, delimiter: str, skip_rows: int, header: bool,
                    drop_unterminated: bool = False) -> pa.Table:
    invalid = [0]

    def skip_invalid(row: object) -> str:
        invalid[0] += 1
        return "skip"

    require_text(path, "log")
    source: Path | pa.BufferReader = path
    if drop_unterminated:
        try:
            data = path.read_bytes()
        except OSError as e:
            raise DataError(f"cannot read: {e}", source=path) from e
        if data and not data.endswith(b"\n"):
            warnings.warn(f"{path}: dropped the unterminated last line (log cut off while "
                          "being written)", DataWarning, stacklevel=5)
            source = pa.BufferReader(data[:data.rfind(b"\n") + 1])
    try:
        table = pacsv.read_csv(
            source,
            read_options=pacsv.ReadOptions(skip_rows=skip_rows,
                                           autogenerate_column_names=not header),
            parse_options=pacsv.ParseOptions(delimiter=delimiter,
                                             invalid_row_handler=skip_invalid),
            convert_options=pacsv.ConvertOptions(strings_can_be_null=True),
        )
    except (pa.ArrowInvalid, OSError, UnicodeDecodeError) as e:
        raise DataError(f"cannot parse CSV: {e}", source=path) from e
    if invalid[0]:
        warnings.warn(f"{path}: dropped {invalid[0]} malformed rows (wrong field count)",
                      DataWarning, stacklevel=3)
    return table


def _to_float(table: pa.Table, source: Path) -> dict[str, Array]:
    out: dict[str, Array] = {}
    for name in table.column_names:
        col = table.column(name)
        try:
            out[name] = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as e:
            raise DataError("column is not numeric", source=source, field=name,
                            expected="numbers") from e
    return out


def _load_native_csv(path: Path) -> Recording:
    skip, meta = read_comment_header(path)
    table = _read_csv_table(path, ",", skip, header=True)
    return _assemble(_to_float(table, path), str(path), meta.get("robot") or None,
                     _sim_seed(meta.get("sim_seed"), str(path)))


def _load_parquet(path: Path) -> Recording:
    try:
        table = pq.read_table(path)
    except (pa.ArrowInvalid, OSError) as e:
        raise DataError(f"not a readable Parquet file: {e}", source=path) from e
    meta = table.schema.metadata or {}
    robot = meta.get(b"leadthrough.robot", b"").decode() or None
    seed = meta.get(b"leadthrough.sim_seed")
    return _assemble(_to_float(table, path), str(path), robot,
                     _sim_seed(None if seed is None else seed.decode(), str(path)))


def _load_mat(path: Path, cmap: ColumnMap) -> Recording:
    import scipy.io

    try:
        doc = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, OSError, NotImplementedError) as e:
        raise DataError(f"not a readable MATLAB file: {e}", source=path) from e
    container: object = doc
    if cmap.struct is not None:
        if cmap.struct not in doc:
            names = sorted(k for k in doc if not k.startswith("__"))
            raise DataError("struct not in file", source=path, field="struct",
                            value=cmap.struct, expected=f"one of {names}")
        container = doc[cmap.struct]
    arrays: dict[str, Array] = {}
    for name, sig in cmap.signals.items():
        assert sig.field is not None
        try:
            raw = np.asarray(container[sig.field] if isinstance(container, dict)
                             else getattr(container, sig.field), dtype=float)
        except (KeyError, AttributeError) as e:
            raise DataError("field not in file", source=path, field=f"{name}.field",
                            value=sig.field, expected="a field of the struct") from e
        if name == "time":
            arrays[name] = raw.ravel() * sig.factor[0] + sig.offset[0]
            continue
        joints = sig.factor.size
        if raw.ndim != 2 or joints not in raw.shape:
            raise DataError("wrong shape", source=path, field=f"{name}.field",
                            value=raw.shape, expected=f"(samples, {joints}) or ({joints}, samples)")
        if raw.shape[1] != joints:
            raw = raw.T
        arrays[name] = raw * sig.factor + sig.offset
    return _finite_recording(arrays, str(path), None)


def _read_mapped(path: Path, cmap: ColumnMap, names: list[str], max_column: int
                 ) -> tuple[dict[str, Array], NDArray[np.bool_], str]:
    """Time and the named signals of one delimited file, the rows to drop and why."""
    table = _read_csv_table(path, cmap.delimiter, cmap.skip_rows, header=False,
                            drop_unterminated=cmap.drop_unterminated_last_row)
    if table.num_columns <= max_column:
        raise DataError("log has fewer columns than the column map uses", source=path,
                        field="columns", value=table.num_columns,
                        expected=f"more than {max_column} (see {cmap.path})")
    cols = _to_float(table, path)
    raw = np.column_stack([cols[name] for name in table.column_names])
    arrays = {name: cmap.signals[name].extract(raw) for name in ("time", *names)}
    arrays["time"] = arrays["time"][:, 0]
    bad = np.zeros(raw.shape[0], dtype=bool)
    reasons = []
    if cmap.drop_abs_above is not None:
        with np.errstate(invalid="ignore"):
            bad |= np.nanmax(np.abs(raw), axis=1) > cmap.drop_abs_above
        reasons.append(f"|value| > {cmap.drop_abs_above:g}")
    if cmap.drop_non_increasing_time:
        t = arrays["time"]
        finite = np.isfinite(t) & ~bad
        running = np.maximum.accumulate(np.where(finite, t, -np.inf))
        prev = np.concatenate([[-np.inf], running[:-1]])
        bad |= finite & (t <= prev)
        reasons.append("non-increasing time")
    return arrays, bad, " or ".join(reasons)


def _load_mapped(path: Path, cmap: ColumnMap) -> Recording:
    if cmap.format == "mat":
        return _load_mat(path, cmap)
    names = [n for n in cmap.signals if n != "time"]
    arrays, bad, why = _read_mapped(path, cmap, names, cmap.max_column)
    return _finite_recording(arrays, str(path), None, bad, why)


def _load_split(folder: Path, cmap: ColumnMap) -> Recording:
    """A log split over several files (one per signal): read each, join the rows on time."""
    parts: list[dict[str, Array]] = []
    for file in cmap.files:
        path = folder / file
        names = [n for n, s in cmap.signals.items() if s.file == file]
        require_file(path, "file of the column map",
                     f"an existing file in the folder (see {cmap.path})", source=folder,
                     field=f"{names[0]}.file", value=file)
        arrays, bad, why = _read_mapped(path, cmap, names, cmap.max_column_in(file))
        part = _clean_rows(arrays, str(path), bad, why)
        t = part["time"]
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise DataError("time is not strictly increasing" if t.size >= 2 else
                            "fewer than 2 usable rows", source=path, field="time",
                            expected="increasing times (set drop_non_increasing_time = true "
                                     f"in {cmap.path} to drop the others)")
        parts.append(part)
    return _finite_recording(_join_on_time(parts, cmap.join_tolerance_s, str(folder)),
                             str(folder), None)


def _join_on_time(parts: list[dict[str, Array]], tolerance: float, source: str
                  ) -> dict[str, Array]:
    """Inner join of per-file signals on their (strictly increasing) time columns.

    Rows of the first part are kept where every other part has a row within ``tolerance``
    seconds; the count of rows without a partner goes into a DataWarning.
    """
    t = parts[0]["time"]
    keep = np.ones(t.size, dtype=bool)
    matches: list[NDArray[np.intp]] = []
    for part in parts[1:]:
        other = part["time"]
        k = np.clip(np.searchsorted(other, t), 1, other.size - 1)
        k = k - ((t - other[k - 1]) < (other[k] - t))
        keep &= np.abs(other[k] - t) <= tolerance
        matches.append(k)
    if keep.sum() < 2:
        raise DataError("the files share fewer than 2 sample times", source=source,
                        field="time", expected="files logged over the same times (or a larger "
                                               "join_tolerance_s)")
    if not keep.all():
        warnings.warn(f"{source}: dropped {int((~keep).sum())} of {t.size} rows of "
                      f"{len(parts)} files that have no partner at the same time", DataWarning,
                      stacklevel=4)
    joined = {name: v[keep] for name, v in parts[0].items()}
    for part, k in zip(parts[1:], matches, strict=True):
        joined.update({name: v[k[keep]] for name, v in part.items() if name != "time"})
    return joined


def load_recording(path: str | Path, columns: str | Path | None = None) -> Recording:
    """Load a recording.

    Args:
        path: Our CSV, a Parquet file, or any delimited log when ``columns`` is given (the
            log's folder when the column map names a file per signal).
        columns: Column-map TOML for logs in a controller's own format.

    Returns:
        The validated recording.

    Raises:
        DataError: Missing or malformed file, or columns that do not fit.
    """
    path = Path(path)
    if columns is not None:
        cmap = parse_column_map(columns)
        if cmap.files:
            if not path.is_dir():
                raise DataError("a log split over several files is loaded from its folder",
                                source=path, expected=f"the folder holding "
                                                      f"{', '.join(cmap.files)}")
            return _load_split(path, cmap)
        require_file(path, "recording", "an existing file")
        return _load_mapped(path, cmap)
    require_file(path, "recording", "an existing file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _load_native_csv(path)
    if suffix in (".parquet", ".pq"):
        return _load_parquet(path)
    raise DataError("unknown recording format", source=path, field="suffix", value=suffix,
                    expected=".csv or .parquet, or pass a column map (--columns map.toml)")
