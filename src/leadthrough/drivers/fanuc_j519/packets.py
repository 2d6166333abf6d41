"""FANUC Stream Motion (option J519), packet format version 1: the wire codec.

UDP to the controller's port 60015, every field big-endian (network order), no padding. The
external device sends a start packet, then the controller sends one status packet per
interpolation cycle (8 ms; 4 ms where the controller supports it) and the device answers each
with a command packet carrying the status packet's sequence number; a stop packet ends the
exchange. The limit query asks, axis by axis, for the controller's velocity, acceleration and
jerk limit tables. Joint values are degrees (float32), motor currents amperes (float32).

=========================  =====  ==========================================================
packet (direction)         bytes  fields (offset: type name)
=========================  =====  ==========================================================
start (device → robot)         8  0: u32 packet_type = 0, 4: u32 version_no = 1
stop (device → robot)          8  0: u32 packet_type = 2, 4: u32 version_no = 1
status (robot → device)      132  0: u32 packet_type = 0, 4: u32 version_no, 8: u32
                                  sequence_no, 12: u8 status, 13: u8 read_io_type, 14: u16
                                  read_io_index, 16: u16 read_io_mask, 18: u16 read_io_value,
                                  20: u32 time_stamp, 24: f32[9] position (X Y Z W P R E1-3),
                                  60: f32[9] joint_angle [deg], 96: f32[9] current [A]
command (device → robot)      64  0: u32 packet_type = 1, 4: u32 version_no, 8: u32
                                  sequence_no, 12: u8 last_data, 13: u8 read_io_type, 14: u16
                                  read_io_index, 16: u16 read_io_mask, 18: u8 data_style
                                  (0 Cartesian, 1 joint), 19: u8 write_io_type, 20: u16
                                  write_io_index, 22: u16 write_io_mask, 24: u16
                                  write_io_value, 26: u16 unused, 28: f32[9] command_pos
limit query (device → r.)     16  0: u32 packet_type = 3, 4: u32 version_no, 8: u32 axis
                                  (1-9), 12: u32 threshold_type (0 velocity [deg/s],
                                  1 acceleration [deg/s²], 2 jerk [deg/s³])
limit answer (robot → d.)    184  0: u32 packet_type = 3, 4: u32 version_no, 8: u32 axis,
                                  12: u32 threshold_type, 16: u32 max_cartesian_speed, 20: u32
                                  interval, 24: f32[20] no_payload, 104: f32[20] full_payload
=========================  =====  ==========================================================

Status bits (``status``): bit 0 ready for commands, bit 1 command received, bit 2 system ready
(SYSRDY), bit 3 robot in motion; FANUC's sample client requires bits 0 and 2 (``status & 5 ==
5``) on every status packet of a motion.

Sources:
    * FANUC's J519 sample client ``StreamITP.cpp`` (FANUC America; public copies of the
      example shipped with the option): the version 1 structs, packet types 0/1/2/3, port
      60015, the handshake (command sequence number = status sequence number, ``last_data``
      on the final command, the ``status & 5`` check) and the limit-query exchange.
    * FANUC America's ROS 2 driver (``stream_motion/packets.hpp``, ``fanuc_client.cpp``,
      Apache-2.0, 2025): field names and table numbers of the manual (Table 3.3(a)-(d),
      B.3(a)/(b)), the threshold units (deg/s, deg/s², deg/s³), the 20-entry limit tables
      (no payload / full payload) that its client interpolates over the TCP speed with
      ``max_cartesian_speed / 20`` steps, and the later packet versions (types 200-205, not
      implemented here).
    * G.A. vd. Hoorn's FANUC Stream Motion ROS driver (reference for the same v1 layout).
    * Valstad Shipworks' ``fanuc_ucl`` (``src/stmo/proto.rs``, Rust): the same status and
      command layouts field by field, the status bits (ready for commands, command received,
      SYSRDY, in motion) and the I/O type codes (0 none, 1 DI, 2 DO, 8 RI, 9 RO, ...).

Documented assumptions (the manual itself, B-84904EN, is not public): ``time_stamp`` is the
controller clock in milliseconds; ``interval`` in the limit answer is the table's TCP-speed
step [mm/s]; ``read_io_value`` carries 16 ports starting at ``read_io_index`` (bit 0) masked
by ``read_io_mask``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from leadthrough.drivers.fanuc_j519.limits import ANSWER_SIZE, QUERY_SIZE, LimitAnswer, LimitQuery
from leadthrough.drivers.wire import (
    BadPacket,
    PacketError,
    check_finite,
    check_length,
    check_uint,
    check_value,
)

__all__ = [
    "DEFAULT_PORT",
    "MAX_AXES",
    "VERSION",
    "CommandPacket",
    "IoType",
    "LimitAnswer",
    "LimitQuery",
    "PacketType",
    "StartPacket",
    "StatusBits",
    "StatusPacket",
    "StopPacket",
    "decode_client_packet",
    "decode_robot_packet",
]

DEFAULT_PORT = 60015
VERSION = 1
MAX_AXES = 9


class PacketType(IntEnum):
    """``packet_type`` values of version 1 (status and start share 0, limit query/answer 3)."""

    START = 0
    STATUS = 0
    COMMAND = 1
    STOP = 2
    LIMITS = 3


class StatusBits(IntFlag):
    """Bits of the status packet's ``status`` byte."""

    READY = 1            # ready to accept motion commands
    COMMAND_RECEIVED = 2
    SYSTEM_READY = 4     # SYSRDY: servo power on, no alarm
    IN_MOTION = 8


class IoType(IntEnum):
    """I/O type codes (KAREL port codes, as ``fanuc_ucl`` has them; see the module doc)."""

    NONE = 0
    DI = 1
    DO = 2


_HEAD = struct.Struct(">II")
_STATUS = struct.Struct(">IIIBBHHHI9f9f9f")
_COMMAND = struct.Struct(">IIIBBHHBBHHHH9f")


def _axes(values: tuple[float, ...] | list[float], source: str, name: str) -> tuple[float, ...]:
    """Pad to 9 axes (unused axes are 0) after checking the count and finiteness."""
    if not 1 <= len(values) <= MAX_AXES:
        raise PacketError("wrong number of axes", code=BadPacket.STRUCTURE, source=source,
                          field=name, value=len(values), expected=f"1..{MAX_AXES} values")
    check_finite(source, name, values, len(values))
    return tuple(float(v) for v in values) + (0.0,) * (MAX_AXES - len(values))


def _check_version(source: str, version: int) -> None:
    check_value(source, "version_no", version, (VERSION,))


@dataclass(frozen=True)
class StartPacket:
    """Asks the controller to start sending status packets (device → robot, 8 bytes)."""

    version: int = VERSION

    def encode(self) -> bytes:
        """The 8 bytes on the wire."""
        return _HEAD.pack(PacketType.START, self.version)


@dataclass(frozen=True)
class StopPacket:
    """Ends the exchange (device → robot, 8 bytes)."""

    version: int = VERSION

    def encode(self) -> bytes:
        """The 8 bytes on the wire."""
        return _HEAD.pack(PacketType.STOP, self.version)


@dataclass(frozen=True)
class StatusPacket:
    """The controller's state of one cycle (robot → device, 132 bytes).

    Attributes:
        sequence: Cycle counter; the command answering this packet carries the same number.
        status: :class:`StatusBits`.
        read_io_type, read_io_index, read_io_mask, read_io_value: The I/O read requested by
            the last command and its value.
        timestamp: Controller clock [ms] (assumption, see the module doc).
        position: TCP X Y Z [mm], W P R [deg], E1-E3, 9 values.
        joints: Joint angles J1-J9 [deg], 9 values (unused axes 0).
        current: Motor currents J1-J9 [A], 9 values.
        version: Packet format version.
    """

    sequence: int
    status: int
    joints: tuple[float, ...]
    current: tuple[float, ...]
    position: tuple[float, ...] = (0.0,) * MAX_AXES
    timestamp: int = 0
    read_io_type: int = 0
    read_io_index: int = 0
    read_io_mask: int = 0
    read_io_value: int = 0
    version: int = VERSION

    @property
    def ready(self) -> bool:
        """Bits 0 and 2 set: the controller accepts motion commands."""
        return self.status & 5 == 5

    @property
    def in_motion(self) -> bool:
        """Bit 3: the robot is moving."""
        return bool(self.status & StatusBits.IN_MOTION)

    def encode(self) -> bytes:
        """The 132 bytes on the wire (joint and current tuples may be shorter than 9)."""
        src = "J519 status packet"
        check_uint(src, "sequence_no", self.sequence, 32)
        check_uint(src, "status", self.status, 8)
        check_uint(src, "time_stamp", self.timestamp, 32)
        return _STATUS.pack(
            PacketType.STATUS, self.version, self.sequence, self.status, self.read_io_type,
            self.read_io_index, self.read_io_mask, self.read_io_value, self.timestamp,
            *_pad(self.position), *_pad(self.joints), *_pad(self.current))

    @classmethod
    def decode(cls, data: bytes) -> StatusPacket:
        """Parse 132 bytes (see the module table).

        Raises:
            DataError: Wrong size, packet type or version.
        """
        src = "J519 status packet"
        check_length(src, data, _STATUS.size)
        v = _STATUS.unpack(data)
        check_value(src, "packet_type", v[0], (PacketType.STATUS,))
        _check_version(src, v[1])
        return cls(sequence=v[2], status=v[3], read_io_type=v[4], read_io_index=v[5],
                   read_io_mask=v[6], read_io_value=v[7], timestamp=v[8],
                   position=tuple(v[9:18]), joints=tuple(v[18:27]), current=tuple(v[27:36]),
                   version=v[1])


def _pad(values: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(values[:MAX_AXES]) + (0.0,) * (MAX_AXES - len(values))


@dataclass(frozen=True)
class CommandPacket:
    """The device's answer to one status packet (device → robot, 64 bytes).

    Attributes:
        sequence: The sequence number of the status packet answered.
        positions: Joint targets [deg] (``data_style`` 1) or TCP pose (0); 1-9 values, padded
            with zeros; all finite.
        last_data: True on the final command of a motion.
        data_style: 1 joint angles, 0 Cartesian.
        read_io_type, read_io_index, read_io_mask: I/O to report in the next status packets.
        write_io_type, write_io_index, write_io_mask, write_io_value: I/O to write.
        version: Packet format version.
    """

    sequence: int
    positions: tuple[float, ...]
    last_data: bool = False
    data_style: int = 1
    read_io_type: int = 0
    read_io_index: int = 0
    read_io_mask: int = 0
    write_io_type: int = 0
    write_io_index: int = 0
    write_io_mask: int = 0
    write_io_value: int = 0
    version: int = VERSION

    def encode(self) -> bytes:
        """The 64 bytes on the wire.

        Raises:
            DataError: A field does not fit or a position is not finite (nothing is sent).
        """
        src = "J519 command packet"
        check_uint(src, "sequence_no", self.sequence, 32)
        check_value(src, "data_style", self.data_style, (0, 1))
        for name in ("read_io_index", "read_io_mask", "write_io_index", "write_io_mask",
                     "write_io_value"):
            check_uint(src, name, getattr(self, name), 16)
        check_uint(src, "read_io_type", self.read_io_type, 8)
        check_uint(src, "write_io_type", self.write_io_type, 8)
        pos = _axes(self.positions, src, "command_pos")
        return _COMMAND.pack(
            PacketType.COMMAND, self.version, self.sequence, int(self.last_data),
            self.read_io_type, self.read_io_index, self.read_io_mask, self.data_style,
            self.write_io_type, self.write_io_index, self.write_io_mask, self.write_io_value,
            0, *pos)

    @classmethod
    def decode(cls, data: bytes) -> CommandPacket:
        """Parse 64 bytes; non-finite positions are kept (the receiver judges them).

        Raises:
            DataError: Wrong size, packet type, version, last_data or data_style.
        """
        src = "J519 command packet"
        check_length(src, data, _COMMAND.size)
        v = _COMMAND.unpack(data)
        check_value(src, "packet_type", v[0], (PacketType.COMMAND,))
        _check_version(src, v[1])
        check_value(src, "last_data", v[3], (0, 1))
        check_value(src, "data_style", v[7], (0, 1))
        return cls(sequence=v[2], last_data=bool(v[3]), read_io_type=v[4],
                   read_io_index=v[5], read_io_mask=v[6], data_style=v[7],
                   write_io_type=v[8], write_io_index=v[9], write_io_mask=v[10],
                   write_io_value=v[11], positions=tuple(v[13:22]), version=v[1])


def decode_robot_packet(data: bytes) -> StatusPacket | LimitAnswer:
    """Parse a packet sent by the controller (status or limit answer), told apart by size.

    Raises:
        DataError: Neither 132 nor 184 bytes, or a malformed packet.
    """
    if len(data) == _STATUS.size:
        return StatusPacket.decode(data)
    if len(data) == ANSWER_SIZE:
        return LimitAnswer.decode(data)
    raise PacketError("wrong packet size", code=BadPacket.SIZE,
                      source="J519 packet from the robot", field="length",
                      value=len(data), expected=f"{_STATUS.size} (status) or {ANSWER_SIZE} "
                      "(limit answer) bytes")


def decode_client_packet(data: bytes) -> StartPacket | StopPacket | CommandPacket | LimitQuery:
    """Parse a packet sent by the external device (what the controller receives).

    Raises:
        DataError: Unknown size or packet type, or a malformed packet.
    """
    src = "J519 packet from the device"
    if len(data) == _HEAD.size:
        ptype, version = _HEAD.unpack(data)
        check_value(src, "packet_type", ptype, (PacketType.START, PacketType.STOP))
        _check_version(src, version)
        return StartPacket(version) if ptype == PacketType.START else StopPacket(version)
    if len(data) == _COMMAND.size:
        return CommandPacket.decode(data)
    if len(data) == QUERY_SIZE:
        return LimitQuery.decode(data)
    raise PacketError("wrong packet size", code=BadPacket.SIZE, source=src, field="length",
                      value=len(data),
                      expected=f"{_HEAD.size} (start/stop), {_COMMAND.size} (command) or "
                      f"{QUERY_SIZE} (limit query) bytes")
