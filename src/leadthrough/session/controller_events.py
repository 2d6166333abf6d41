"""The guiding controller's state transitions as the session's events (what the log, the
pendant and ``teach`` read: :class:`~leadthrough.session_format.SessionEvent`).
"""

from __future__ import annotations

from leadthrough.control.safety import Event
from leadthrough.session_format import SessionEvent

__all__ = ["transition_event"]


def transition_event(e: Event) -> SessionEvent:
    """A controller's state transition as a session event (``cause`` or ``cause:fault``)."""
    cause = e.cause.name if e.fault.name == "NONE" else f"{e.cause.name}:{e.fault.name}"
    return SessionEvent(t=e.t, kind="transition",
                        label=f"{e.from_state.name}->{e.to_state.name}", cause=cause)
