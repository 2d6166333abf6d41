"""The operator's requests as the loop's process applies them, at a controller cycle's start.

:meth:`RequestHandler.take` reads what the pendant has sent through the pipe without waiting
(``Connection.poll`` with no timeout) and applies it in order: the enabling input, clearing a
fault (only at rest, :meth:`GuidingController.clear_fault
<leadthrough.control.guiding.GuidingController.clear_fault>`), marks (the measured pose of this
cycle), changes of settings (:meth:`GuidingController.adjust
<leadthrough.control.guiding.GuidingController.adjust>`, refused or clamped with a notice), the
simulator's requests, and the pendant's stop. A closed pipe is a lost pendant: the enabling
input is released (the controller's commanded stop) and the loop ends once at rest.

Nothing a request carries ends the loop: each is checked again here
(:func:`~leadthrough.pendant.messages.check_request`) and applied under a guard; a malformed
one, or one whose effect fails, is refused with a notice and counted (:attr:`RequestHandler.
refused`). A hold of the enabling input with a lease (:attr:`SetEnable.until
<leadthrough.pendant.messages.SetEnable.until>`) is dropped by this process itself at the
first controller cycle after the lease, through the same release (a commanded stop), whether
or not the pendant's process is still sending.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from multiprocessing.connection import Connection

from leadthrough.control.guiding import GuidingController
from leadthrough.control.safety import State
from leadthrough.errors import ControlError, LeadthroughError
from leadthrough.pendant.messages import (
    Adjust,
    ClearFault,
    MarkedPoint,
    MarkPoint,
    Notice,
    SetEnable,
    SimulatorRequest,
    Stop,
    check_request,
)
from leadthrough.session.loop import ServoPeriods

__all__ = ["MAX_MARKS", "NOTICES_KEPT", "RequestHandler"]

#: Notices a snapshot carries (the latest).
NOTICES_KEPT = 20
#: Marks a session takes (a snapshot carries them all; the shared record has a fixed size).
MAX_MARKS = 1000


class RequestHandler:
    """The requests' effects and what they leave for the snapshot.

    Args:
        controller: The loop's controller.
        loop: The loop (its measured feedback, for marks).
        simulator: Applies simulator requests (None: refused, a robot).
        clock: The clock of enabling leases [s] (``time.monotonic``, the pendant's).
    """

    def __init__(self, controller: GuidingController, loop: ServoPeriods,
                 simulator: Callable[[object, float], str | None] | None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.controller, self.loop, self.simulator = controller, loop, simulator
        self.clock = clock
        #: The enabling input as the loop sees it.
        self.held = False
        #: When the hold lapses (the clock's time [s]); None: no lease.
        self.lease_until: float | None = None
        #: Requests refused (malformed, or their effect failed).
        self.refused = 0
        #: Holds dropped by a lapsed lease.
        self.lapsed = 0
        #: Whether the loop is to end (once at rest).
        self.stopping = False
        #: Why the pendant's link was lost, if it was.
        self.lost: str | None = None
        self.marks: tuple[MarkedPoint, ...] = ()
        self.notices: deque[Notice] = deque(maxlen=NOTICES_KEPT)
        self.notice_count = 0
        #: Whether marks, notices or settings changed since the last snapshot.
        self.changed = True
        self._conn_open = True

    def take(self, conn: Connection, t: float) -> None:
        """Apply the requests that have arrived, in order (never waits), then drop a hold
        whose lease has lapsed."""
        if self._conn_open:
            try:
                while conn.poll():
                    try:
                        req = conn.recv()
                    except (EOFError, OSError):
                        raise                   # the link itself: lost
                    except Exception as e:      # a message that does not unpickle
                        self.refuse("a message", e)
                        continue
                    self.apply(req, t)
            except (EOFError, OSError):
                self.lose("the pendant's link closed")
        self.check_lease()

    def check_lease(self) -> None:
        """Release the enabling input if its lease has lapsed (called every controller
        cycle)."""
        if self.held and self.lease_until is not None:
            late = self.clock() - self.lease_until
            if late > 0.0:
                self.held, self.lease_until = False, None
                self.lapsed += 1
                self.notice("warning", f"enabling device released: no heartbeat from the "
                                       f"page (lease lapsed {1e3 * late:.0f} ms before this "
                                       "cycle)")

    def refuse(self, what: str, error: BaseException) -> None:
        """Count and report a refused request."""
        self.refused += 1
        why = str(error) if isinstance(error, LeadthroughError) else \
            f"{type(error).__name__}: {error}"
        self.notice("warning", f"{what} refused: {why[:300]}")

    def lose(self, why: str) -> None:
        """The pendant is gone: release the enabling input and end at rest."""
        if self.lost is None:
            self.lost = why
            self._conn_open = False
            self.held, self.stopping, self.lease_until = False, True, None

    def apply(self, req: object, t: float) -> None:
        """One request at loop time ``t`` [s]; a malformed one, or one that fails, is refused
        with a notice (:meth:`refuse`), never raised."""
        try:
            check_request(req)
            self._apply(req, t)
        except Exception as e:  # nothing a request carries may end the loop
            if isinstance(req, SetEnable | Stop):   # when in doubt, released
                self.held, self.lease_until = False, None
            self.refuse(f"request {type(req).__name__}", e)

    def _apply(self, req: object, t: float) -> None:
        ctl = self.controller
        if isinstance(req, SetEnable):
            self.held = bool(req.held) and self.lost is None
            self.lease_until = req.until if self.held else None
            if self.held:
                self.check_lease()      # a heartbeat arriving after its own lease: none
        elif isinstance(req, Stop):
            self.held, self.stopping, self.lease_until = False, True, None
        elif isinstance(req, ClearFault):
            if ctl.state != State.FAULT:
                self.notice("warning", "no fault to clear")
            elif not ctl.clear_fault(t):
                self.notice("warning", "fault not cleared: the robot is still stopping")
        elif isinstance(req, MarkPoint) and len(self.marks) >= MAX_MARKS:
            self.notice("warning", f"not marked: {MAX_MARKS} marks is the most a session "
                                   "keeps (export, then restart)")
        elif isinstance(req, MarkPoint):
            self.marks = (*self.marks, MarkedPoint(req.label, t, self.loop.fb.q.copy()))
            self.notice("info", f"marked {req.label} at {t:.2f} s")
        elif isinstance(req, Adjust):
            self._adjust(req)
        elif isinstance(req, SimulatorRequest):
            if self.simulator is None:
                self.notice("warning", f"not a simulator: {type(req).__name__} refused")
            else:
                text = self.simulator(req, t)
                if text is not None:
                    self.notice("info", text)
        else:
            self.notice("warning", f"unknown request {type(req).__name__} ignored")

    def _adjust(self, req: Adjust) -> None:
        try:
            cfg = self.controller.adjust(frame=req.frame, axes_enabled=req.axes_enabled,
                                         mass=req.mass, friction=req.friction)
        except ControlError as e:
            self.notice("warning", f"not changed: {e}")
            return
        self.changed = True
        vf = cfg.virtual_friction
        if req.mass is not None and (vf.mass[0], vf.mass[3]) != tuple(req.mass):
            self.notice("warning", f"virtual mass clamped to {vf.mass[0]:g} kg, "
                                   f"{vf.mass[3]:g} kg·m²")
        if req.friction is not None and (vf.friction[0], vf.friction[3]) != tuple(req.friction):
            self.notice("warning", f"friction clamped to {vf.friction[0]:g} N, "
                                   f"{vf.friction[3]:g} N·m")

    def notice(self, level: str, text: str) -> None:
        """A message for the operator, in the next snapshot."""
        self.notice_count += 1
        self.notices.append(Notice(self.notice_count, level, text))
        self.changed = True
