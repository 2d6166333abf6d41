"""The operator's requests as the loop's process applies them, at a controller cycle's start.

:meth:`RequestHandler.take` reads what the pendant has sent through the pipe without waiting
(``Connection.poll`` with no timeout) and applies it in order: the enabling input, clearing a
fault (only at rest, :meth:`GuidingController.clear_fault
<leadthrough.control.guiding.GuidingController.clear_fault>`), marks (the measured pose of this
cycle), changes of settings (:meth:`GuidingController.adjust
<leadthrough.control.guiding.GuidingController.adjust>`, refused or clamped with a notice), the
simulator's requests, and the pendant's stop. A closed pipe is a lost pendant: the enabling
input is released (the controller's commanded stop) and the loop ends once at rest.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from multiprocessing.connection import Connection

from leadthrough.control.guiding import GuidingController
from leadthrough.control.safety import State
from leadthrough.errors import ControlError
from leadthrough.pendant.messages import (
    Adjust,
    ClearFault,
    MarkedPoint,
    MarkPoint,
    Notice,
    SetEnable,
    SimulatorRequest,
    Stop,
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
    """

    def __init__(self, controller: GuidingController, loop: ServoPeriods,
                 simulator: Callable[[object, float], str | None] | None) -> None:
        self.controller, self.loop, self.simulator = controller, loop, simulator
        #: The enabling input as the loop sees it.
        self.held = False
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
        """Apply the requests that have arrived, in order (never waits)."""
        if not self._conn_open:
            return
        try:
            while conn.poll():
                self.apply(conn.recv(), t)
        except (EOFError, OSError):
            self.lose("the pendant's link closed")

    def lose(self, why: str) -> None:
        """The pendant is gone: release the enabling input and end at rest."""
        if self.lost is None:
            self.lost = why
            self._conn_open = False
            self.held, self.stopping = False, True

    def apply(self, req: object, t: float) -> None:
        """One request at loop time ``t`` [s]."""
        ctl = self.controller
        if isinstance(req, SetEnable):
            self.held = bool(req.held) and self.lost is None
        elif isinstance(req, Stop):
            self.held, self.stopping = False, True
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
