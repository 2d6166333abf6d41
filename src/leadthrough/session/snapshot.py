"""What a running guiding loop publishes for a pendant or a UI: :class:`LoopSnapshot`.

The loop writes its state once per controller cycle into one preallocated record
(:func:`snapshot_dtype`) on a :class:`SnapshotBoard`; a reader in any thread copies it. The two
never wait on each other: the board is a *sequence lock* (Lameter, "Effective synchronization
on Linux/NUMA systems", 2005; the Linux kernel's ``seqlock_t``). The writer makes the record's
counter odd, writes, and makes it even again; a reader copies the record and keeps the copy only
if the counter was even and unchanged around the copy, else copies again. The loop allocates
nothing to publish (field writes into the record); the reader builds the
:class:`LoopSnapshot` from its copy, in its own thread.

The few texts (the fault's cause, the last notice, the end's cause) and the marks are immutable
Python objects the loop replaces, rarely, by assignment (atomic); the record counts the marks so
that a snapshot shows exactly those of its cycle.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.protocol import ControllerState
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.session.record import Mark
from leadthrough.state_records import Fields, new_record, view

__all__ = ["LoopSnapshot", "SnapshotBoard", "snapshot_dtype"]

Array = NDArray[np.float64]
#: Copies a reader tries before it gives up on a board the loop keeps rewriting.
_READ_ATTEMPTS = 1000


@cache
def snapshot_dtype(n: int) -> np.dtype[Any]:
    """The published record for ``n`` joints (see :class:`LoopSnapshot` for the fields)."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    return np.dtype([
        ("sequence", i8),          # the sequence lock: odd while the loop writes
        ("t", f8), ("wall_time", f8), ("period", i8),
        ("q", f8, (n,)), ("q_cmd", f8, (n,)),
        ("tcp_rotation", f8, (3, 3)), ("tcp_position", f8, (3,)),
        ("wrench", f8, (6,)), ("twist", f8, (6,)),
        ("state", i8), ("fault", i8), ("controller_state", i8), ("estimator_status", i8),
        ("enable_held", b1), ("enabled", b1), ("ready", b1),
        ("axes_enabled", b1, (6,)), ("tool_frame", b1),
        ("mass", f8, (6,)), ("friction", f8, (6,)), ("stopping_friction", f8, (6,)),
        ("mark_count", i8), ("late_periods", i8), ("running", b1),
    ])


@dataclass(frozen=True)
class LoopSnapshot:
    """The loop's state at one controller cycle, for a pendant or a UI.

    Attributes:
        t: The loop's time [s].
        age_s: Wall-clock time since the loop published it [s] (a stalled loop shows as a
            growing age).
        period: Servo periods run.
        q: Measured joint positions [rad], shape (n,).
        q_cmd: Commanded joint positions [rad], shape (n,).
        tcp_position: Commanded TCP position, base frame [m], shape (3,).
        tcp_quaternion: Commanded TCP orientation, (x, y, z, w), shape (4,).
        wrench: Estimated operator wrench at the TCP, base axes [N, N·m], shape (6,).
        linear_speed: Commanded TCP speed [m/s].
        angular_speed: Commanded TCP angular speed [rad/s].
        state: The safety state.
        fault: The latched fault (``Fault.NONE`` unless ``state`` is FAULT).
        fault_cause: The fault's cause in words ("" without a fault).
        controller_state: The robot controller's own state.
        estimator_status: The force estimator's status (WARMING_UP and TARING: hands off).
        enable_held: The enabling device is pressed.
        enabled: Guiding is enabled (a fresh press seen while ready, held since).
        ready: A fresh press would start guiding (estimator OK, no fault, no stop requested).
        needs_release: The device is held but does not count: release it and press again.
        axes_enabled: The axes the operator can move (x, y, z, ωx, ωy, ωz of ``frame``).
        frame: ``"base"`` or ``"tool"``.
        mass: Virtual mass per axis [kg, kg·m²].
        friction: Virtual friction δ per axis [N, N·m].
        stopping_friction: Stopping friction δ_s per axis [N, N·m].
        marks: The marks so far, in time order.
        late_periods: Servo periods that missed their deadline so far.
        running: The loop runs (False in the last snapshot, after the end).
        end_cause: Why the loop ended ("" while it runs).
        notice: The loop's last message to the operator (a refused request, a reset, ...).
    """

    t: float
    age_s: float
    period: int
    q: Array
    q_cmd: Array
    tcp_position: Array
    tcp_quaternion: Array
    wrench: Array
    linear_speed: float
    angular_speed: float
    state: State
    fault: Fault
    fault_cause: str
    controller_state: ControllerState
    estimator_status: EstimatorStatus
    enable_held: bool
    enabled: bool
    ready: bool
    needs_release: bool
    axes_enabled: tuple[bool, ...]
    frame: str
    mass: tuple[float, ...]
    friction: tuple[float, ...]
    stopping_friction: tuple[float, ...]
    marks: tuple[Mark, ...]
    late_periods: int
    running: bool
    end_cause: str
    notice: str


class SnapshotBoard:
    """The loop's published state (see the module doc). The loop calls :meth:`attach` once,
    then :meth:`begin`, writes :attr:`fields`, :meth:`end`; readers call :meth:`read`."""

    def __init__(self) -> None:
        self._record: NDArray[np.void] | None = None
        self.fields: Fields | None = None
        #: Immutable texts and marks, replaced by the loop (atomic assignments).
        self.marks: tuple[Mark, ...] = ()
        self.fault_cause = ""
        self.notice = ""
        self.end_cause = ""

    def attach(self, n: int) -> Fields:
        """Allocate the record for ``n`` joints (before the loop's first period); returns the
        fields the loop writes."""
        record = new_record(snapshot_dtype(n))
        record["tcp_rotation"][0] = np.eye(3)     # a rotation before the first cycle writes one
        self.fields = fields = view(record)
        self._record = record
        return fields

    def begin(self) -> None:
        """The loop starts writing (the counter turns odd)."""
        f = self.fields
        if f is not None:
            f.sequence = f.sequence + 1

    def end(self) -> None:
        """The loop has written a consistent state (the counter turns even)."""
        f = self.fields
        if f is not None:
            f.wall_time = time.monotonic()
            f.sequence = f.sequence + 1

    def read(self) -> LoopSnapshot | None:
        """The latest consistent state (None before :meth:`attach`, or if the loop rewrote the
        record during every one of many attempts)."""
        record = self._record
        if record is None:
            return None
        for _ in range(_READ_ATTEMPTS):
            before = int(record["sequence"][0])
            copy = record.copy()
            if before % 2 == 0 and int(record["sequence"][0]) == before:
                return self._build(copy[0])
            time.sleep(0)
        return None

    def _build(self, r: Any) -> LoopSnapshot:
        twist = r["twist"]
        return LoopSnapshot(
            t=float(r["t"]), age_s=time.monotonic() - float(r["wall_time"]),
            period=int(r["period"]), q=r["q"].copy(), q_cmd=r["q_cmd"].copy(),
            tcp_position=r["tcp_position"].copy(),
            tcp_quaternion=Rotation.from_matrix(r["tcp_rotation"]).as_quat(),
            wrench=r["wrench"].copy(), linear_speed=float(np.linalg.norm(twist[:3])),
            angular_speed=float(np.linalg.norm(twist[3:])), state=State(int(r["state"])),
            fault=Fault(int(r["fault"])), fault_cause=self.fault_cause,
            controller_state=ControllerState(int(r["controller_state"])),
            estimator_status=EstimatorStatus(int(r["estimator_status"])),
            enable_held=bool(r["enable_held"]), enabled=bool(r["enabled"]),
            ready=bool(r["ready"]),
            needs_release=bool(r["enable_held"]) and not bool(r["enabled"]),
            axes_enabled=tuple(bool(a) for a in r["axes_enabled"]),
            frame="tool" if r["tool_frame"] else "base",
            mass=tuple(float(v) for v in r["mass"]),
            friction=tuple(float(v) for v in r["friction"]),
            stopping_friction=tuple(float(v) for v in r["stopping_friction"]),
            marks=self.marks[:int(r["mark_count"])], late_periods=int(r["late_periods"]),
            running=bool(r["running"]), end_cause=self.end_cause, notice=self.notice)
