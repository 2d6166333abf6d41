"""How the safety layer's transitions read on the pendant: the cause, or the fault with its
joint or axis and its value in units (:class:`~leadthrough.control.safety_states.Fault`)."""

from __future__ import annotations

import math

from leadthrough.control.safety import Event, Fault

__all__ = ["describe"]

#: How a fault's value and index read (:class:`~leadthrough.control.safety_states.Fault`).
_FAULT_UNITS: dict[Fault, str] = {
    Fault.POSITION_RANGE: "rad", Fault.CURRENT_RANGE: "A", Fault.FOLLOWING_ERROR: "rad",
    Fault.JOINT_LIMIT: "rad", Fault.WORKSPACE: "m", Fault.SINGULARITY: "μ",
    Fault.TRACKING: "m+rad"}


def describe(event: Event | None) -> str:
    """A transition in words: ``"DEADMAN_RELEASED"``, ``"FOLLOWING_ERROR: joint 3, 0.0512
    rad"``, ``"COLLISION: force 163 N"``."""
    if event is None:
        return ""
    fault = event.fault
    if fault == Fault.NONE:
        return event.cause.name
    value = "" if math.isnan(event.value) else f"{event.value:.3g}"
    if fault == Fault.COLLISION:
        what = ("force", "N") if event.index == 0 else ("torque", "N·m")
        return f"{fault.name}: {what[0]} {value} {what[1]}"
    unit = _FAULT_UNITS.get(fault)
    if unit is None or not value:
        return fault.name
    where = f"joint {event.index + 1}, " if event.index >= 0 and unit in ("rad", "A") else ""
    return f"{fault.name}: {where}{value} {unit}"
