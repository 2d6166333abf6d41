"""Universal Robots Real-Time Data Exchange (RTDE), protocol version 2: the wire codec.

TCP port 30004, big-endian. Every message is ``uint16 size`` (whole message, header included),
``uint8 type``, then the payload:

==============================  ====  =====================================================
message                         type  payload (client → controller / controller → client)
==============================  ====  =====================================================
REQUEST_PROTOCOL_VERSION        86 V  uint16 version / uint8 accepted
GET_URCONTROL_VERSION           118 v (none) / uint32 major, minor, bugfix, build
TEXT_MESSAGE                    77 M  uint8 length, message, uint8 length, source, uint8 level
CONTROL_PACKAGE_SETUP_OUTPUTS   79 O  float64 frequency [Hz], names "a,b,c" / uint8 recipe
                                      id, types "VECTOR6D,DOUBLE,..." (NOT_FOUND per unknown
                                      name)
CONTROL_PACKAGE_SETUP_INPUTS    73 I  names / uint8 recipe id, types (IN_USE when another
                                      client writes the variable, NOT_FOUND when unknown)
CONTROL_PACKAGE_START           83 S  (none) / uint8 accepted
CONTROL_PACKAGE_PAUSE           80 P  (none) / uint8 accepted
DATA_PACKAGE                    85 U  uint8 recipe id, then the recipe's fields in order
==============================  ====  =====================================================

Field types: BOOL (uint8 0/1), UINT8, UINT32, UINT64, INT32, DOUBLE (float64), VECTOR3D,
VECTOR6D, VECTOR6INT32, VECTOR6UINT32.

Sources:
    * Universal Robots, "Real-Time Data Exchange (RTDE) Guide" and the RTDE chapter of the
      e-Series manual (universal-robots.com/manuals/.../Real_Time_Data_Exchange_RTDE.htm):
      message types, payloads, field list and types, the NOT_FOUND / IN_USE answers, the
      125 Hz (CB3) / 500 Hz (e-Series) maximum output frequency.
    * Universal Robots' Python client ``RTDE_Python_Client_Library`` (``rtde/rtde.py``,
      ``rtde/serialize.py``, BSD): message codes, header ``>HB``, the v2 text message layout
      and the per-type struct formats.
    * SDU Robotics' ``ur_rtde`` (``rtde_receive_interface.cpp``): the handshake order a real
      client uses (protocol version, controller version, frequency from the major version,
      output setup, start).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from leadthrough.drivers.wire import BadPacket, PacketError, check_length, check_uint, check_value
from leadthrough.errors import DataError

__all__ = [
    "DEFAULT_PORT",
    "HEADER",
    "INPUT_TYPES",
    "OUTPUT_TYPES",
    "PROTOCOL_VERSION",
    "ControllerVersion",
    "FrameReader",
    "MessageType",
    "Recipe",
    "TextMessage",
    "decode_accepted",
    "decode_setup_inputs",
    "decode_setup_outputs",
    "decode_setup_reply",
    "decode_version_request",
    "encode_accepted",
    "encode_setup_inputs",
    "encode_setup_outputs",
    "encode_setup_reply",
    "encode_version_request",
    "frame",
]

DEFAULT_PORT = 30004
PROTOCOL_VERSION = 2
HEADER = struct.Struct(">HB")
MAX_MESSAGE = 0xFFFF


class MessageType(IntEnum):
    """RTDE message type codes (the ASCII letter of each)."""

    REQUEST_PROTOCOL_VERSION = 86
    GET_URCONTROL_VERSION = 118
    TEXT_MESSAGE = 77
    DATA_PACKAGE = 85
    CONTROL_PACKAGE_SETUP_OUTPUTS = 79
    CONTROL_PACKAGE_SETUP_INPUTS = 73
    CONTROL_PACKAGE_START = 83
    CONTROL_PACKAGE_PAUSE = 80


# type name -> (struct format of its values, count)
FIELD_FORMATS: dict[str, tuple[str, int]] = {
    "BOOL": ("?", 1), "UINT8": ("B", 1), "UINT32": ("I", 1), "UINT64": ("Q", 1),
    "INT32": ("i", 1), "DOUBLE": ("d", 1), "VECTOR3D": ("ddd", 3), "VECTOR6D": ("d" * 6, 6),
    "VECTOR6INT32": ("i" * 6, 6), "VECTOR6UINT32": ("I" * 6, 6),
}

_OUTPUTS_FIXED = {
    "timestamp": "DOUBLE", "target_q": "VECTOR6D", "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D", "target_current": "VECTOR6D", "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D", "actual_current": "VECTOR6D",
    "actual_digital_input_bits": "UINT64", "actual_digital_output_bits": "UINT64",
    "robot_mode": "INT32", "joint_mode": "VECTOR6INT32", "safety_mode": "INT32",
    "safety_status": "INT32", "runtime_state": "UINT32", "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32", "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE", "actual_execution_time": "DOUBLE",
}
OUTPUT_TYPES: dict[str, str] = {
    **_OUTPUTS_FIXED,
    **{f"output_int_register_{i}": "INT32" for i in range(48)},
    **{f"output_double_register_{i}": "DOUBLE" for i in range(48)},
    **{f"output_bit_register_{i}": "BOOL" for i in range(64, 128)},
}
"""Output variables the codec knows (the RTDE guide's names and types)."""

INPUT_TYPES: dict[str, str] = {
    **{f"input_int_register_{i}": "INT32" for i in range(48)},
    **{f"input_double_register_{i}": "DOUBLE" for i in range(48)},
    **{f"input_bit_register_{i}": "BOOL" for i in range(64, 128)},
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
}
"""Input variables the codec knows (general-purpose registers and the speed slider)."""


def frame(mtype: int, payload: bytes = b"") -> bytes:
    """One message: header (size, type) + payload.

    Raises:
        DataError: The message would exceed 65535 bytes.
    """
    size = HEADER.size + len(payload)
    if size > MAX_MESSAGE:
        raise DataError("message too long", source="RTDE message", field="size", value=size,
                        expected=f"<= {MAX_MESSAGE} bytes")
    return HEADER.pack(size, mtype) + payload


class FrameReader:
    """Splits a TCP byte stream into RTDE messages."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        """Append received bytes."""
        self._buf += data

    def next(self) -> tuple[int, bytes] | None:
        """The next complete message (type, payload), or None until more bytes arrive.

        Raises:
            DataError: A header announces fewer than 3 bytes (the stream is corrupt).
        """
        if len(self._buf) < HEADER.size:
            return None
        size, mtype = HEADER.unpack_from(self._buf)
        if size < HEADER.size:
            raise PacketError("corrupt header", code=BadPacket.SIZE, source="RTDE stream",
                              field="size", value=size, expected=">= 3 bytes")
        if len(self._buf) < size:
            return None
        payload = bytes(self._buf[HEADER.size:size])
        del self._buf[:size]
        return mtype, payload


def encode_version_request(version: int = PROTOCOL_VERSION) -> bytes:
    """Payload of REQUEST_PROTOCOL_VERSION: uint16 version."""
    check_uint("RTDE protocol version request", "version", version, 16)
    return struct.pack(">H", version)


def decode_version_request(payload: bytes) -> int:
    """The version asked for in REQUEST_PROTOCOL_VERSION."""
    check_length("RTDE protocol version request", payload, 2)
    return int(struct.unpack(">H", payload)[0])


def encode_accepted(accepted: bool) -> bytes:
    """Payload of the controller's answer to a version request, START or PAUSE."""
    return struct.pack(">B", int(accepted))


def decode_accepted(payload: bytes, source: str) -> bool:
    """Parse a uint8 accepted flag (0 or 1).

    Raises:
        DataError: Not 1 byte, or a value other than 0 / 1.
    """
    check_length(source, payload, 1)
    check_value(source, "accepted", payload[0], (0, 1))
    return bool(payload[0])


@dataclass(frozen=True)
class ControllerVersion:
    """GET_URCONTROL_VERSION answer (4 × uint32)."""

    major: int
    minor: int
    bugfix: int
    build: int

    def encode(self) -> bytes:
        """The 16-byte payload."""
        return struct.pack(">IIII", self.major, self.minor, self.bugfix, self.build)

    @classmethod
    def decode(cls, payload: bytes) -> ControllerVersion:
        """Parse the 16-byte payload."""
        check_length("RTDE controller version", payload, 16)
        return cls(*struct.unpack(">IIII", payload))


@dataclass(frozen=True)
class TextMessage:
    """TEXT_MESSAGE, protocol version 2.

    Attributes:
        message: Text (at most 255 bytes UTF-8).
        source: Sender name (at most 255 bytes).
        level: 0 exception, 1 error, 2 warning, 3 info.
    """

    message: str
    source: str
    level: int

    def encode(self) -> bytes:
        """Payload: uint8 length, message, uint8 length, source, uint8 level."""
        msg, src = self.message.encode()[:255], self.source.encode()[:255]
        return bytes([len(msg)]) + msg + bytes([len(src)]) + src + bytes([self.level])

    @classmethod
    def decode(cls, payload: bytes) -> TextMessage:
        """Parse a version-2 text message.

        Raises:
            DataError: The lengths do not add up to the payload size.
        """
        src = "RTDE text message"
        n = payload[0] if payload else 0
        m = payload[1 + n] if len(payload) > 1 + n else 0
        check_length(src, payload, 3 + n + m)
        return cls(payload[1:1 + n].decode(errors="replace"),
                   payload[2 + n:2 + n + m].decode(errors="replace"), payload[2 + n + m])


def _names(payload: bytes, source: str) -> list[str]:
    try:
        text = payload.decode("ascii")
    except UnicodeDecodeError as e:
        raise PacketError("names are not ASCII", code=BadPacket.SYNTAX, source=source,
                          field="variables", value=payload[:40],
                          expected="comma-separated ASCII names") from e
    # a trailing comma is accepted: SDU's ur_rtde sends one, and real controllers take it
    names = text.removesuffix(",").split(",")
    if not text or any(not n for n in names):
        raise PacketError("empty variable name", code=BadPacket.FIELD, source=source,
                          field="variables", value=text,
                          expected="comma-separated non-empty names")
    return names


def encode_setup_outputs(frequency: float, names: Sequence[str]) -> bytes:
    """Payload of CONTROL_PACKAGE_SETUP_OUTPUTS: float64 frequency [Hz] + names."""
    return struct.pack(">d", frequency) + ",".join(names).encode("ascii")


def decode_setup_outputs(payload: bytes) -> tuple[float, list[str]]:
    """Parse CONTROL_PACKAGE_SETUP_OUTPUTS into (frequency [Hz], names)."""
    src = "RTDE setup outputs"
    if len(payload) < 9:
        raise PacketError("payload too short", code=BadPacket.SIZE, source=src, field="length",
                          value=len(payload),
                          expected=">= 9 bytes (frequency and at least one name)")
    return float(struct.unpack_from(">d", payload)[0]), _names(payload[8:], src)


def encode_setup_inputs(names: Sequence[str]) -> bytes:
    """Payload of CONTROL_PACKAGE_SETUP_INPUTS: names."""
    return ",".join(names).encode("ascii")


def decode_setup_inputs(payload: bytes) -> list[str]:
    """Parse CONTROL_PACKAGE_SETUP_INPUTS into names."""
    return _names(payload, "RTDE setup inputs")


def encode_setup_reply(recipe_id: int, types: Sequence[str]) -> bytes:
    """Payload of the controller's answer to a setup: uint8 recipe id + types."""
    check_uint("RTDE setup reply", "recipe_id", recipe_id, 8)
    return bytes([recipe_id]) + ",".join(types).encode("ascii")


def decode_setup_reply(payload: bytes) -> tuple[int, list[str]]:
    """Parse a setup answer into (recipe id, types); types may hold NOT_FOUND / IN_USE."""
    src = "RTDE setup reply"
    if not payload:
        raise PacketError("empty payload", code=BadPacket.SIZE, source=src, field="length",
                          value=0, expected=">= 1 byte")
    return payload[0], payload[1:].decode("ascii", errors="replace").split(",")


@dataclass(frozen=True)
class Recipe:
    """A configured recipe: the layout of the DATA_PACKAGEs that carry it.

    Attributes:
        recipe_id: Id given by the controller (1-255).
        names: Variable names, in order.
        types: Their types (keys of :data:`FIELD_FORMATS`).
    """

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]
    _struct: struct.Struct = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        src = "RTDE recipe"
        if len(self.names) != len(self.types):
            raise DataError("names and types differ in number", source=src, field="types",
                            value=(len(self.names), len(self.types)), expected="one per name")
        for name, t in zip(self.names, self.types, strict=True):
            if t not in FIELD_FORMATS:
                raise DataError("unusable variable", source=src, field=name, value=t,
                                expected="one of " + ", ".join(FIELD_FORMATS))
        fmt = ">B" + "".join(FIELD_FORMATS[t][0] for t in self.types)
        object.__setattr__(self, "_struct", struct.Struct(fmt))

    @property
    def size(self) -> int:
        """Payload size of a DATA_PACKAGE of this recipe [bytes] (recipe id included)."""
        return int(self._struct.size)

    def encode(self, values: Mapping[str, Any]) -> bytes:
        """DATA_PACKAGE payload: recipe id, then each variable (vectors as sequences).

        Raises:
            DataError: A variable is missing or does not fit its type.
        """
        flat: list[Any] = [self.recipe_id]
        for name, t in zip(self.names, self.types, strict=True):
            try:
                v = values[name]
            except KeyError as e:
                raise DataError("missing value", source="RTDE data package", field=name,
                                expected=f"a {t}") from e
            count = FIELD_FORMATS[t][1]
            flat.extend(v if count > 1 else (v,))
        try:
            return bytes(self._struct.pack(*flat))
        except struct.error as e:
            raise DataError(f"values do not fit the recipe: {e}", source="RTDE data package",
                            field=",".join(self.names), expected=",".join(self.types)) from e

    def decode(self, payload: bytes) -> dict[str, Any]:
        """Parse a DATA_PACKAGE payload into {name: value} (vectors as tuples).

        Raises:
            DataError: Wrong size or recipe id.
        """
        src = "RTDE data package"
        check_length(src, payload, self.size)
        flat = self._struct.unpack(payload)
        check_value(src, "recipe_id", flat[0], (self.recipe_id,))
        out: dict[str, Any] = {}
        i = 1
        for name, t in zip(self.names, self.types, strict=True):
            count = FIELD_FORMATS[t][1]
            out[name] = tuple(flat[i:i + count]) if count > 1 else flat[i]
            i += count
        return out
