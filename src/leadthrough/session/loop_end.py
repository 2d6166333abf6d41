"""How the guiding loop ends: the state of its link to the driver, why it ended, and the end
as recorded (:class:`~leadthrough.session.servo_loop.ServoLoop` keeps them;
:func:`~leadthrough.session.loop.run_session` returns the end)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, StrEnum

from leadthrough.control.safety_states import Fault, State

__all__ = ["EndCause", "Link", "LoopEnd"]


class Link(IntEnum):
    """The state of the link to the driver."""

    #: The driver's calls succeed.
    OK = 0
    #: One failed (an exception, or an exchange beyond the watchdog's timeout): a fault is
    #: latched and the stop is commanded.
    SUSPECT = 1
    #: A second failure, or a blocked call aborted: nothing more is sent.
    LOST = 2


class EndCause(StrEnum):
    """Why a loop ended."""

    #: ``duration_s`` ran out, and the commanded motion came to rest.
    DURATION = "duration"
    #: ``LoopRequests.stop``, and the commanded motion came to rest.
    STOP_REQUESTED = "stop requested"
    #: The driver failed twice (or a blocked call was aborted): no more commands were sent.
    LINK_LOST = "link lost"
    #: The operator's channel closed (the pendant's process gone): the enabling device
    #: released, and the commanded motion came to rest.
    OPERATOR_LOST = "operator lost"
    #: A stop did not bring the commanded motion to rest within ``stop_timeout_s``.
    STOP_TIMEOUT = "stop timeout"


@dataclass(frozen=True)
class LoopEnd:
    """How a loop ended.

    Attributes:
        cause: Why.
        t: The loop's time at the end [s].
        state: The controller's safety state at the end.
        fault: The latched fault (``Fault.NONE`` if none).
        detail: More, in words (the driver's error, ...).
    """

    cause: EndCause
    t: float
    state: State
    fault: Fault
    detail: str = ""
