"""Checks shared by the wire codecs of the real-controller protocols.

The codecs (:mod:`leadthrough.drivers.fanuc_j519.packets`, :mod:`leadthrough.drivers.ur_rtde.
protocol`, :mod:`leadthrough.drivers.kuka_rsi.messages`) are pure functions on bytes or strings.
Malformed input never trips an ``assert``: it raises :class:`PacketError` (a
:class:`~leadthrough.errors.DataError`) naming the protocol and packet (``source``), the field, the
offending value and the accepted range, and carrying a :class:`BadPacket` code: one family of
codes for every way a packet can be refused, so that the transports count them by kind
(:attr:`~leadthrough.drivers.link.LinkStats.bad`) instead of raising.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum
from typing import Any

from leadthrough.errors import DataError

__all__ = ["BadPacket", "PacketError", "check_finite", "check_length", "check_uint",
           "check_value", "packet_code"]


class BadPacket(StrEnum):
    """Why a packet was refused: the codes the transports count (:class:`PacketError`'s
    ``code``, :attr:`~leadthrough.drivers.link.LinkStats.bad`)."""

    SIZE = "size"                  # wrong size, or over the protocol's cap
    SYNTAX = "syntax"              # not well-formed (XML), not ASCII, truncated
    FORBIDDEN = "forbidden"        # a construct the protocol never uses: DTD, entity, PI
    STRUCTURE = "structure"        # wrong root, element missing, duplicated, nested, unknown
    FIELD = "field"                # a field outside its grammar or range (digits, width)
    NONFINITE = "nonfinite"        # NaN or infinity where the protocol has a finite number
    VALUE = "value"                # an enumerated field (type, version, recipe id) not allowed
    UNKNOWN_TYPE = "unknown_type"  # a message type the protocol does not define
    SEQUENCE = "sequence"          # a time stamp or counter that jumped (too far, or by a
    #                                fraction of a cycle)
    STALE = "stale"                # a time stamp not newer than the last one taken (a packet
    #                                delivered late behind a newer one, or repeated)
    FOREIGN = "foreign"            # from another sender than the controller's address
    BUDGET = "budget"              # dropped unparsed: the cycle's parse budget was spent
    UNEXPECTED = "unexpected"      # the codec failed in a way it does not name (a defect)


class PacketError(DataError):
    """A packet refused by a codec (see the module doc).

    Args:
        message: What is wrong.
        code: The kind of refusal.
        **kw: ``source``, ``field``, ``value``, ``expected`` as for every package error.

    Attributes:
        code: The kind of refusal (:class:`BadPacket`).
    """

    def __init__(self, message: str, *, code: BadPacket, **kw: Any) -> None:
        self.code = code
        super().__init__(message, **kw)


def packet_code(error: DataError) -> BadPacket:
    """The :class:`BadPacket` code of a codec's error (``SYNTAX`` for a plain ``DataError``)."""
    return error.code if isinstance(error, PacketError) else BadPacket.SYNTAX


def check_length(source: str, data: bytes, expected: int) -> None:
    """Raise unless a packet has exactly ``expected`` bytes.

    Args:
        source: Protocol and packet name, e.g. ``"J519 status packet"``.
        data: The packet.
        expected: Its size [bytes].

    Raises:
        DataError: Naming the size found and the size expected.
    """
    if len(data) != expected:
        raise PacketError("wrong packet size", code=BadPacket.SIZE, source=source,
                          field="length", value=len(data), expected=f"{expected} bytes")


def check_value(source: str, field: str, value: int, allowed: Sequence[int] | range) -> None:
    """Raise unless an integer field holds one of the allowed values.

    Args:
        source: Protocol and packet name.
        field: Field name.
        value: Decoded (or to-be-encoded) value.
        allowed: Accepted values.

    Raises:
        DataError: Naming the field, the value and the accepted values.
    """
    if value not in allowed:
        if isinstance(allowed, range):
            expected = f"{allowed.start}..{allowed.stop - 1}"
        else:
            expected = "one of " + ", ".join(str(a) for a in allowed)
        raise PacketError("unexpected value", code=BadPacket.VALUE, source=source, field=field,
                          value=value, expected=expected)


def check_uint(source: str, field: str, value: int, bits: int) -> None:
    """Raise unless ``value`` fits an unsigned integer field of ``bits`` bits.

    Args:
        source: Protocol and packet name.
        field: Field name.
        value: Value to encode.
        bits: Field width [bits].

    Raises:
        DataError: Naming the field, the value and the range.
    """
    if not (isinstance(value, int) and 0 <= value < (1 << bits)):
        raise PacketError("does not fit the field", code=BadPacket.FIELD, source=source,
                          field=field, value=value,
                          expected=f"integer 0..{(1 << bits) - 1} (uint{bits})")


def check_finite(source: str, field: str, values: Sequence[float], count: int) -> None:
    """Raise unless ``values`` holds ``count`` finite numbers.

    Args:
        source: Protocol and packet name.
        field: Field name.
        values: The numbers.
        count: How many are expected.

    Raises:
        DataError: Naming the field, the values and what was expected.
    """
    if len(values) != count:
        raise PacketError("wrong number of values", code=BadPacket.STRUCTURE, source=source,
                          field=field, value=len(values), expected=f"{count} values")
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise PacketError("not finite", code=BadPacket.NONFINITE, source=source,
                              field=f"{field}[{i}]", value=v, expected="a finite number")
