"""Checks shared by the wire codecs of the real-controller protocols.

The codecs (:mod:`leadthrough.drivers.fanuc_j519.packets`, :mod:`leadthrough.drivers.ur_rtde.
protocol`, :mod:`leadthrough.drivers.kuka_rsi.messages`) are pure functions on bytes or strings.
Malformed input never trips an ``assert``: it raises :class:`~leadthrough.errors.DataError` naming
the protocol and packet (``source``), the field, the offending value and the accepted range.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from leadthrough.errors import DataError

__all__ = ["check_finite", "check_length", "check_uint", "check_value"]


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
        raise DataError("wrong packet size", source=source, field="length", value=len(data),
                        expected=f"{expected} bytes")


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
        raise DataError("unexpected value", source=source, field=field, value=value,
                        expected=expected)


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
        raise DataError("does not fit the field", source=source, field=field, value=value,
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
        raise DataError("wrong number of values", source=source, field=field,
                        value=len(values), expected=f"{count} values")
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise DataError("not finite", source=source, field=f"{field}[{i}]", value=v,
                            expected="a finite number")
