"""The session file's format: a guiding session's rows and events, and its Parquet file.

A top-level module, outside the real-time package: the loop (:mod:`leadthrough.session`) and
its writer process write sessions in this format; teach-in (:mod:`leadthrough.teach`), the
session's figures and reports, and the pendant's export read them, without importing the loop.

One row per servo period (1 ms): measured joint positions and currents, the estimator's joint
torque and wrench, the 1 ms joint command, and the controller's latest commanded TCP pose and
twist with the safety state. Events (state transitions with their cause, and the operator's
"mark point" presses) are stored in the file's metadata, as are the robot name and settings.

Columns (n joints): ``t``; ``q_1..n`` [rad]; ``current_1..n`` [A]; ``tau_ext_1..n`` [N·m];
``wrench_base_fx, fy, fz, tx, ty, tz`` [N, N·m]; ``q_cmd_1..n`` [rad]; ``qd_cmd_1..n`` [rad/s];
``tcp_cmd_x, y, z`` [m] and ``tcp_cmd_qx, qy, qz, qw`` (commanded TCP pose in the base frame);
``twist_cmd_vx, vy, vz, wx, wy, wz`` [m/s, rad/s] (base axes at the TCP); ``state`` and
``fault`` (codes of :class:`~leadthrough.control.safety.State` / ``Fault``); and, from a
simulator only, ``wrench_applied_fx..tz`` (the true operator wrench, base frame).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from leadthrough.errors import DataError
from leadthrough.fileio import atomic_write, require_file

__all__ = ["Mark", "SessionEvent", "SessionLog", "load_session", "save_session",
           "session_columns", "session_metadata"]

Array = NDArray[np.float64]
_WRENCH = ("fx", "fy", "fz", "tx", "ty", "tz")
_TWIST = ("vx", "vy", "vz", "wx", "wy", "wz")
_META_KEY = b"leadthrough.session"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class Mark:
    """The operator presses the "mark point" button.

    Attributes:
        t: Time of the press [s] (the session's clock).
        label: Name of the marked point, e.g. ``"P1"``.
    """

    t: float
    label: str


@dataclass(frozen=True)
class SessionEvent:
    """Something that happened at one instant of a session.

    Attributes:
        t: Time [s].
        kind: ``"transition"`` (safety state change) or ``"mark"`` (operator marked a point).
        label: Transition ``"GUIDING->STOPPING"`` style, or the mark's name (``"P1"``).
        cause: Why (transitions: the cause/fault name; marks: empty).
    """

    t: float
    kind: str
    label: str
    cause: str = ""


@dataclass
class SessionLog:
    """A recorded guiding session (arrays have one row per servo period).

    Attributes:
        robot: Robot name.
        time: Time [s], shape (N,).
        q: Measured joint positions [rad], shape (N, n).
        current: Measured motor currents [A], shape (N, n).
        tau_ext: Estimated external joint torque [N·m], shape (N, n).
        wrench_base: Estimated wrench at the TCP, base axes [N, N·m], shape (N, 6).
        q_cmd: Joint position command the loop computed in this period [rad], shape (N, n):
            sent at the start of the next one (row i is sent after sample i, unlike a
            :class:`~leadthrough.data.recording.Recording`'s ``q_cmd``, which is the command
            sent before its sample).
        qd_cmd: Its joint velocity feed-forward [rad/s], shape (N, n).
        tcp_cmd_base: Commanded TCP position in the base frame [m], shape (N, 3).
        tcp_cmd_quat: Commanded TCP orientation, quaternion (x, y, z, w), shape (N, 4).
        twist_cmd_base: Commanded TCP twist, base axes at the TCP [m/s, rad/s], shape (N, 6).
        state: Safety state code, shape (N,).
        fault: Fault code, shape (N,).
        wrench_applied_base: True operator wrench (simulator only) [N, N·m], shape (N, 6), or
            None.
        events: Transitions and marks, in time order.
        settings: Free-form settings (controller, operator, seed, dt, ...), JSON-serialisable.
    """

    robot: str
    time: Array
    q: Array
    current: Array
    tau_ext: Array
    wrench_base: Array
    q_cmd: Array
    qd_cmd: Array
    tcp_cmd_base: Array
    tcp_cmd_quat: Array
    twist_cmd_base: Array
    state: NDArray[np.int64]
    fault: NDArray[np.int64]
    wrench_applied_base: Array | None = None
    events: list[SessionEvent] = field(default_factory=list)
    settings: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.q.shape[1])

    @property
    def marks(self) -> list[SessionEvent]:
        """The operator's marks, in time order."""
        return [e for e in self.events if e.kind == "mark"]


def _blocks(log: SessionLog) -> dict[str, tuple[Array, tuple[str, ...]]]:
    n = log.n
    joints = tuple(str(j) for j in range(1, n + 1))
    blocks: dict[str, tuple[Array, tuple[str, ...]]] = {
        "q": (log.q, joints), "current": (log.current, joints),
        "tau_ext": (log.tau_ext, joints), "wrench_base": (log.wrench_base, _WRENCH),
        "q_cmd": (log.q_cmd, joints), "qd_cmd": (log.qd_cmd, joints),
        "tcp_cmd": (np.hstack([log.tcp_cmd_base, log.tcp_cmd_quat]),
                    ("x", "y", "z", "qx", "qy", "qz", "qw")),
        "twist_cmd": (log.twist_cmd_base, _TWIST),
    }
    if log.wrench_applied_base is not None:
        blocks["wrench_applied"] = (log.wrench_applied_base, _WRENCH)
    return blocks


def save_session(log: SessionLog, path: str | Path) -> Path:
    """Write a session to Parquet atomically.

    Args:
        log: The session.
        path: Target ``.parquet`` file.

    Returns:
        The path written.

    Raises:
        DataError: Wrong suffix or missing folder.
    """
    path = Path(path)
    if path.suffix.lower() not in (".parquet", ".pq"):
        raise DataError("unsupported session file type", source=path, field="suffix",
                        value=path.suffix, expected=".parquet")
    table = pa.table(session_columns(log)).replace_schema_metadata(
        session_metadata(log.robot, log.n, log.events, log.settings))

    def write(tmp: Path) -> None:
        pq.write_table(table, tmp)

    return atomic_write(path, write)


def session_columns(log: SessionLog) -> dict[str, Array]:
    """The session file's columns of ``log``'s rows (``t``, ``q_1``..., ``state``, ...), each
    contiguous (a strided column is copied here, one short call per column, not inside
    ``pyarrow.table`` in one call holding the interpreter lock for all of them)."""
    columns: dict[str, Array] = {"t": log.time}
    for prefix, (arr, names) in _blocks(log).items():
        for k, name in enumerate(names):
            columns[f"{prefix}_{name}"] = np.ascontiguousarray(arr[:, k])
    columns["state"] = log.state.astype(np.int8)
    columns["fault"] = log.fault.astype(np.int8)
    return columns


def session_metadata(robot: str, n: int, events: list[SessionEvent],
                     settings: dict[str, object]) -> dict[bytes, bytes]:
    """The session file's key-value metadata (robot, joints, events, settings)."""
    meta = {"format": FORMAT_VERSION, "robot": robot, "n": n,
            "events": [asdict(e) for e in events], "settings": settings}
    return {_META_KEY: json.dumps(meta).encode()}


def load_session(path: str | Path) -> SessionLog:
    """Read a session written by :func:`save_session`.

    Args:
        path: The ``.parquet`` file.

    Returns:
        The session.

    Raises:
        DataError: Missing or unreadable file, not a leadthrough session, or missing columns.
    """
    path = Path(path)
    require_file(path, "session file", "an existing session .parquet")
    try:
        table = pq.read_table(path)
        # save_session puts it in the schema; a file streamed chunk by chunk in the footer
        raw = ((table.schema.metadata or {}).get(_META_KEY)
               or (pq.read_metadata(path).metadata or {}).get(_META_KEY))
    except (OSError, pa.ArrowException) as e:
        raise DataError(f"not a readable Parquet file ({e})", source=path,
                        expected="a session written by 'leadthrough guide'") from e
    if raw is None:
        raise DataError("not a leadthrough session (no session metadata)", source=path,
                        expected="a session written by 'leadthrough guide'")
    try:
        meta = json.loads(raw)
        n = int(meta["n"])
        events = [SessionEvent(**e) for e in meta["events"]]
    except (ValueError, KeyError, TypeError) as e:
        raise DataError(f"corrupt session metadata ({e})", source=path,
                        expected="a session written by 'leadthrough guide'") from e
    if meta.get("format") != FORMAT_VERSION:
        raise DataError("a session format this version does not read", source=path,
                        field="format", value=meta.get("format"),
                        expected=f"{FORMAT_VERSION} (written by this leadthrough's guide)")
    names = set(table.column_names)

    def block(prefix: str, suffixes: tuple[str, ...]) -> Array:
        cols = [f"{prefix}_{s}" for s in suffixes]
        missing = [c for c in cols if c not in names]
        if missing:
            raise DataError("missing column", source=path, field=missing[0],
                            expected=f"columns {cols[0]}..{cols[-1]}")
        return np.column_stack([table.column(c).to_numpy().astype(float) for c in cols])

    joints = tuple(str(j) for j in range(1, n + 1))
    if "t" not in names or "state" not in names or "fault" not in names:
        raise DataError("missing column", source=path, field="t/state/fault",
                        expected="a session written by 'leadthrough guide'")
    tcp = block("tcp_cmd", ("x", "y", "z", "qx", "qy", "qz", "qw"))
    applied = (block("wrench_applied", _WRENCH) if "wrench_applied_fx" in names else None)
    return SessionLog(
        robot=str(meta["robot"]), time=table.column("t").to_numpy().astype(float),
        q=block("q", joints), current=block("current", joints),
        tau_ext=block("tau_ext", joints), wrench_base=block("wrench_base", _WRENCH),
        q_cmd=block("q_cmd", joints), qd_cmd=block("qd_cmd", joints),
        tcp_cmd_base=tcp[:, :3], tcp_cmd_quat=tcp[:, 3:],
        twist_cmd_base=block("twist_cmd", _TWIST),
        state=table.column("state").to_numpy().astype(np.int64),
        fault=table.column("fault").to_numpy().astype(np.int64),
        wrench_applied_base=applied, events=events, settings=dict(meta.get("settings", {})))
