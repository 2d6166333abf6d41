"""Named real-time state: NumPy structured records that compiled code reads by field.

The real-time parts (the estimator, the guiding controller, its IK and safety supervisor, the
interpolator) keep their state in one record each: a NumPy structured array of one element whose
fields have names, units and shapes (``dtype`` builders next to each part). Numba compiles
functions that take such an array and read ``s = record[0]`` then ``s.q_cmd``, ``s.rest_s``
(field access is a pointer offset; nested arrays are views; nothing is allocated). Python calls
them with the array itself: Numba types a one-element array in a fraction of a microsecond, a
record scalar (``record[0]``) of a large layout in about ten. Python reads and writes the same
fields with attribute access through :func:`view` (:class:`Fields`: views made once, so an
access costs a dictionary lookup). Codes (states, faults, statuses) are ``IntEnum`` members
stored in integer fields; compiled code compares and assigns the members themselves, so every
code is defined once. Each layout is built once per size (``functools.cache`` on its builder):
Numba's dispatcher caches an array's type by its dtype, and compares an equal but new dtype
field by field on every call.

:class:`RecordView` turns a record into a typed public object (``GuidingOutput``,
``EstimatorOutput`` ...) whose attributes are :func:`field` descriptors: arrays are read-only
attributes (fill or read them in place: they are the record's own memory and cannot be rebound),
scalars read and write, codes come back as their ``IntEnum``.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import IntEnum
from typing import Any, Generic, TypeVar, overload

import numpy as np
from numpy.typing import NDArray

__all__ = ["Fields", "RecordView", "field", "new_record", "view"]

T = TypeVar("T")
E = TypeVar("E", bound=IntEnum)


def new_record(dtype: np.dtype[Any]) -> NDArray[np.void]:
    """A zeroed record: a structured array of one element (what compiled code takes)."""
    return np.zeros(1, dtype=dtype)


class Fields:
    """Attribute access to a record's fields, by views made once (same memory, no copy).

    Reading an array field returns its view (fill it in place); reading a scalar returns its
    value (a NumPy scalar); assigning a field copies the value into the record (an array is
    broadcast, a nested record assigned as a whole).

    Args:
        record: A record (:func:`new_record`).
    """

    def __init__(self, record: NDArray[np.void]) -> None:
        scalars: dict[str, NDArray[Any]] = {}
        arrays: dict[str, NDArray[Any]] = {}
        object.__setattr__(self, "_record", record)
        object.__setattr__(self, "_scalars", scalars)
        object.__setattr__(self, "_arrays", arrays)
        for name in record.dtype.names or ():
            kind = record.dtype[name]
            if kind.shape == () and kind.names is None:
                scalars[name] = record[name]              # shape (1,): read and write [0]
            elif kind.names is None:
                arrays[name] = record[name][0]            # the field's own memory
                object.__setattr__(self, name, arrays[name])
            else:
                object.__setattr__(self, name, record[name][0])   # a nested record

    def __getattr__(self, name: str) -> Any:
        try:
            return self._scalars[name][0]
        except KeyError:
            raise AttributeError(f"the record has no field {name!r}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self._scalars:
            self._scalars[name][0] = value
        elif name in self._arrays:
            self._arrays[name][...] = value
        elif name in (self._record.dtype.names or ()):
            self._record[name] = value
        else:
            raise AttributeError(f"the record has no field {name!r}")


def view(record: NDArray[np.void]) -> Fields:
    """Attribute access to a record's fields from Python (same memory, no copy)."""
    return Fields(record)


class RecordView:
    """A typed object over one record (see :func:`field`).

    Args:
        dtype: The record's layout.

    Attributes:
        record: The structured array of one element (what the compiled code takes).
    """

    __slots__ = ("_view", "record")

    def __init__(self, dtype: np.dtype[Any]) -> None:
        self.record = new_record(dtype)
        self._view = view(self.record)


class field(Generic[T]):  # noqa: N801 (a descriptor, used like a function)
    """A record field as an attribute of a :class:`RecordView`.

    Args:
        name: The field's name in the record.
        doc: What it is, with units and shape.
        convert: Applied to the value read (e.g. an ``IntEnum`` for a code, ``float``, ``bool``).
            Arrays are returned as they are (views) and are read-only attributes.
    """

    def __init__(self, name: str, doc: str, convert: Callable[[Any], T] | None = None) -> None:
        self.name = name
        self.__doc__ = doc
        self._convert = convert
        if isinstance(convert, type) and issubclass(convert, IntEnum):
            # a dictionary lookup costs a tenth of the enum's constructor
            by_value: dict[int, Any] = {int(m): m for m in convert}
            self._convert = lambda v: by_value[int(v)]

    @overload
    def __get__(self, obj: None, owner: type) -> field[T]: ...

    @overload
    def __get__(self, obj: RecordView, owner: type) -> T: ...

    def __get__(self, obj: RecordView | None, owner: type) -> T | field[T]:
        if obj is None:
            return self
        value = getattr(obj._view, self.name)
        return value if self._convert is None else self._convert(value)

    def __set__(self, obj: RecordView, value: T) -> None:
        if self._convert is None:
            # ``obj.q += dq`` computes in place, then assigns the field's own memory back
            current = getattr(obj._view, self.name)
            if not (isinstance(value, np.ndarray) and value.shape == current.shape
                    and value.__array_interface__["data"] == current.__array_interface__["data"]):
                raise AttributeError(
                    f"{self.name} is an array: fill it in place ({self.name}[:] = ...)")
            return
        setattr(obj._view, self.name, value)
