"""FANUC Stream Motion (J519) limit query and answer: the controller's velocity, acceleration
and jerk limit tables, axis by axis (packet type 3; layout in
:mod:`leadthrough.drivers.fanuc_j519.packets`, sources cited there).

Each answer holds two 20-entry tables (no payload, full payload) of one limit of one axis, in
deg/s, deg/s² or deg/s³; FANUC's ROS 2 client interpolates them over the TCP speed in steps
of ``max_cartesian_speed / 20`` and over the payload.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum

from leadthrough.drivers.wire import check_finite, check_length, check_value

__all__ = ["ANSWER_SIZE", "LIMIT_TABLE", "QUERY_SIZE", "LimitAnswer", "LimitKind",
           "LimitQuery"]

VERSION = 1
MAX_AXES = 9
LIMIT_TABLE = 20
LIMITS_TYPE = 3
_QUERY = struct.Struct(">IIII")
_ANSWER = struct.Struct(">IIIIII20f20f")
QUERY_SIZE, ANSWER_SIZE = _QUERY.size, _ANSWER.size


class LimitKind(IntEnum):
    """``threshold_type`` of a limit query."""

    VELOCITY = 0      # deg/s
    ACCELERATION = 1  # deg/s^2
    JERK = 2          # deg/s^3


def _check_head(source: str, ptype: int, version: int) -> None:
    check_value(source, "packet_type", ptype, (LIMITS_TYPE,))
    check_value(source, "version_no", version, (VERSION,))


@dataclass(frozen=True)
class LimitQuery:
    """Asks for one axis' limit table (device → robot, 16 bytes).

    Attributes:
        axis: Axis number 1-9.
        kind: Which limit.
    """

    axis: int
    kind: LimitKind
    version: int = VERSION

    def encode(self) -> bytes:
        """The 16 bytes on the wire."""
        check_value("J519 limit query", "axis_number", self.axis, range(1, MAX_AXES + 1))
        return _QUERY.pack(LIMITS_TYPE, self.version, self.axis, int(self.kind))

    @classmethod
    def decode(cls, data: bytes) -> LimitQuery:
        """Parse 16 bytes.

        Raises:
            DataError: Wrong size, type, version, axis or threshold type.
        """
        src = "J519 limit query"
        check_length(src, data, _QUERY.size)
        ptype, version, axis, kind = _QUERY.unpack(data)
        _check_head(src, ptype, version)
        check_value(src, "axis_number", axis, range(1, MAX_AXES + 1))
        check_value(src, "threshold_type", kind, (0, 1, 2))
        return cls(axis=axis, kind=LimitKind(kind), version=version)


@dataclass(frozen=True)
class LimitAnswer:
    """One axis' limit table (robot → device, 184 bytes).

    Attributes:
        axis: Axis number 1-9.
        kind: Which limit (units deg/s, deg/s², deg/s³).
        max_cartesian_speed: TCP speed covered by the table [mm/s].
        interval: TCP-speed step of the table [mm/s] (assumption, see the module doc).
        no_payload: 20 limits without payload.
        full_payload: 20 limits at full payload.
    """

    axis: int
    kind: LimitKind
    max_cartesian_speed: int
    interval: int
    no_payload: tuple[float, ...] = field(default=(0.0,) * LIMIT_TABLE)
    full_payload: tuple[float, ...] = field(default=(0.0,) * LIMIT_TABLE)
    version: int = VERSION

    def encode(self) -> bytes:
        """The 184 bytes on the wire."""
        src = "J519 limit answer"
        check_finite(src, "no_payload", self.no_payload, LIMIT_TABLE)
        check_finite(src, "full_payload", self.full_payload, LIMIT_TABLE)
        return _ANSWER.pack(LIMITS_TYPE, self.version, self.axis, int(self.kind),
                            self.max_cartesian_speed, self.interval, *self.no_payload,
                            *self.full_payload)

    @classmethod
    def decode(cls, data: bytes) -> LimitAnswer:
        """Parse 184 bytes.

        Raises:
            DataError: Wrong size, type, version, axis or threshold type.
        """
        src = "J519 limit answer"
        check_length(src, data, _ANSWER.size)
        v = _ANSWER.unpack(data)
        _check_head(src, v[0], v[1])
        check_value(src, "axis_number", v[2], range(1, MAX_AXES + 1))
        check_value(src, "threshold_type", v[3], (0, 1, 2))
        return cls(axis=v[2], kind=LimitKind(v[3]), max_cartesian_speed=v[4], interval=v[5],
                   no_payload=tuple(v[6:26]), full_payload=tuple(v[26:46]), version=v[1])
