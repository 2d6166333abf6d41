"""The pendant: a web app for the person at the robot, served by ``leadthrough pendant``.

Why viser: it is a library made for showing robots in the browser (a three.js scene kept in
sync over a websocket, with URDF support through yourdfpy, GUI panels, and transform gizmos the
user can drag), it serves its prebuilt client from the Python package with no other service and
no network access, and it works in a tablet's browser. meshcat, the other candidate, shows a
scene but has no GUI controls or draggable gizmos; a hand-written three.js page would have to
re-implement both (viser docs: https://viser.studio).

Structure: the loop runs in a process of its own (:mod:`leadthrough.pendant.backend`); this module
reads its snapshot :data:`UI_HZ` times a second on a thread of its own and updates the page
(:mod:`~leadthrough.pendant.status_view`, :mod:`~leadthrough.pendant.scene_view`,
:mod:`~leadthrough.pendant.controls`); the operator's actions become requests to the loop.
Nothing on the page waits for the loop and the loop never waits for the page.

Who may act: one page controls the pendant, the first to take control ("Take control"); every
other page is read-only (its actions are refused with a notice to that page alone, and a setting
it changes snaps back). Another page asking for control gets it when the page in control
confirms, or when that page disconnects. Arming, the enabling device, marking, settings,
pushing and exports are the controlling page's only.

Safety on the page: guiding needs the pendant armed *and* the enabling device held. On the
simulator the page provides that device as hold-to-run: pressed only while the pointer is held
on its button, which sends a heartbeat (:data:`~leadthrough.pendant.controls.HOLD_HZ`); each
heartbeat holds the enabling input for :data:`LEASE_S` (a lease the loop's process enforces by
itself, every controller cycle, even if this process stalls), so letting go, the pointer
leaving, the page losing focus or becoming hidden (``page_guard.js``), a frozen or closed page
all release it within the lease and one controller cycle. A release by a missed heartbeat
holds until the pointer lets go of the button and presses it again: heartbeats that resume
after a stall of the page (or of this process) do not enable again. On a robot the enabling
device is the robot's own wired input and the page cannot enable guiding by itself. The page
in control disconnecting releases the enabling device and disarms.

Every request is checked here before it is sent (types, finite numbers, ranges, labels:
:func:`~leadthrough.pendant.messages.check_request`) and again in the loop's process; a bad one
is refused to the page that sent it and never reaches the loop. Text from the operator or the
loop (labels, notices, errors) is shown as text, never as HTML or Markdown. Exports: one at a
time, :data:`EXPORT_INTERVAL_S` apart, at most :data:`MAX_EXPORTS` a run.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import viser

from leadthrough.control.safety import State
from leadthrough.errors import LeadthroughError
from leadthrough.labels import is_label
from leadthrough.pendant.access import DEFAULT_MAX_CLIENTS, Gate, new_token, serve_gated
from leadthrough.pendant.backend import (
    Adjust,
    ClearFault,
    LiveSession,
    LoopSnapshot,
    MarkPoint,
    SetEnable,
)
from leadthrough.pendant.controls import Controls, text_html
from leadthrough.pendant.export import export_taught
from leadthrough.pendant.messages import LEASE_S, RequestError, check_request
from leadthrough.pendant.push import Hand, PushSpring
from leadthrough.pendant.scene_view import SceneView
from leadthrough.pendant.status_view import StatusExtras, status_html
from leadthrough.pendant.taught_points import TaughtPoints

__all__ = ["EXPORT_INTERVAL_S", "LEASE_S", "MAX_EXPORTS", "PANEL_HZ", "TELL_EVERY_S",
           "TOLD_KEPT", "UI_HZ", "Pendant", "wait_for_clients"]

#: Updates of the 3D view per second.
UI_HZ = 20.0
#: Updates of the panels (status, controls, messages) per second, besides changes of state.
PANEL_HZ = 5.0
#: Least time between two exports [s] (each copies the whole session).
EXPORT_INTERVAL_S = 5.0
#: Exports a run makes at most.
MAX_EXPORTS = 50
#: Least time between two equal refusals told to one page [s].
TELL_EVERY_S = 1.0
#: Messages kept per page (:meth:`Pendant.told`).
TOLD_KEPT = 20


class Pendant:
    """The pendant's web server on a live session.

    Args:
        live: The running loop.
        out: Folder of the exports.
        hand: The simulated hand the mouse pushes with; None on a robot.
        bind: Address to serve on (``0.0.0.0`` for a tablet on the network).
        port: Port to serve on (the next free one if taken).
        spring: The mouse's push (simulator).
        params_note: Where the loop's parameters come from, shown on the page.
        token: The secret in the page's URL (:mod:`~leadthrough.pendant.access`); None: a
            new random one.
        allow_remote: Whether ``bind`` may be other than this machine's loopback address.
        max_clients: Pages connected at once.

    Raises:
        DataError: A bad token, or a remote ``bind`` without ``allow_remote``.
    """

    def __init__(self, live: LiveSession, out: Path, *, hand: Hand | None = None,
                 bind: str = "127.0.0.1", port: int = 8080,
                 spring: PushSpring | None = None, params_note: str = "",
                 token: str | None = None, allow_remote: bool = False,
                 max_clients: int = DEFAULT_MAX_CLIENTS) -> None:
        self.live, self.robot, self.out, self.hand = live, live.robot, Path(out), hand
        self.spring = spring if spring is not None else PushSpring()
        self.params_note = params_note
        self.gate = Gate(new_token() if token is None else token, bind,
                         allow_remote=allow_remote, max_clients=max_clients)
        self.server: viser.ViserServer = serve_gated(self.gate, host=bind, port=port,
                                                     verbose=False)
        self.server.gui.configure_theme(control_width="large", show_logo=False,
                                        show_share_button=False, brand_color=(236, 112, 20))
        self.server.initial_camera.position = (1.95, -0.6, 1.3)
        self.server.initial_camera.look_at = (0.55, 0.12, 0.6)
        self.scene = SceneView(self.server, self.robot, hand is not None)
        self.controls = Controls(self.server.gui, self, live.config,
                                 hand is not None)
        self.points = TaughtPoints()
        self._armed = False
        #: The controlling page's last heartbeat of the enabling device (time.monotonic()
        #: [s]); None: released.
        self._beat: float | None = None
        #: A heartbeat lapsed: the device is held again only after a let-go and a new press.
        self._fresh_press = False
        self._sent_held = False
        self._holding = False
        self._controller: int | None = None
        self._asking: int | None = None
        self._modal: Any = None
        self._told: dict[int, deque[str]] = {}
        self._told_at: dict[tuple[int, str], float] = {}
        self._roles: dict[int, Any] = {}
        self._export_lock = threading.Lock()
        self._exports, self._export_at = 0, -math.inf
        #: Exports a run makes at most, and their least interval [s].
        self.max_exports, self.export_interval_s = MAX_EXPORTS, EXPORT_INTERVAL_S
        #: How long one heartbeat holds the enabling device [s] (:data:`LEASE_S`).
        self.lease_s = LEASE_S
        self._lock = threading.RLock()
        self._notices: deque[str] = deque(maxlen=6)
        self._seen_notice = 0
        self._panels_at = 0.0
        self._panels_state: tuple[State, str | None] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._refresh_loop, name="leadthrough-pendant",
                                        daemon=True)
        self.server.on_client_connect(self._connected)
        self.server.on_client_disconnect(self._disconnected)

    @property
    def url(self) -> str:
        """Where the page is served, with its token (on all addresses: on 127.0.0.1)."""
        return self.gate.url(self.server.get_host(), self.server.get_port())

    def start(self) -> None:
        """Start refreshing the page."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the page (the loop is the caller's to stop)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self.server.stop()

    # ------------------------------------------------------------ who controls
    @property
    def controller(self) -> int | None:
        """The page in control (its viser client id), or None."""
        return self._controller

    @property
    def asking(self) -> int | None:
        """The page that asked for control and waits for the answer, or None."""
        return self._asking

    @property
    def armed(self) -> bool:
        """Whether guiding is armed on the pendant."""
        return self._armed

    def may_act(self, client: int, what: str) -> bool:
        """Whether page ``client`` is the page in control; if not, that page alone is told
        why ``what`` was refused (at most once a second per refusal) and nothing is done."""
        with self._lock:
            if client >= 0 and client == self._controller:
                return True
            why = ("no page has control: 'Take control' first" if self._controller is None
                   else "this page is read-only: another page has control ('Take control' "
                        "asks it to hand over)")
            self.tell(client, f"{what} refused: {why}", throttle=True)
            return False

    def take_control(self, client: int) -> None:
        """Page ``client`` takes control if no page has it; otherwise the page in control is
        asked to hand over (:meth:`answer_control`), and ``client`` gets control when it
        confirms or when it disconnects."""
        with self._lock:
            if client < 0:
                return
            if self._controller is None:
                self._hand_over(client, "no page had control")
            elif client == self._controller:
                self.tell(client, "this page has control already")
            else:
                self._asking = client
                self.tell(client, "asked the page in control to hand over: this page gets "
                                  "control when it confirms, or when it disconnects")
                self._ask(self._controller, client)

    def answer_control(self, client: int, hand_over: bool) -> None:
        """The page in control answers a request for control: hand over or keep it."""
        with self._lock:
            asking = self._asking
            if client != self._controller or asking is None:
                self.tell(client, "no request for control to answer", throttle=True)
                return
            self._asking = None
            self._close_ask()
            if hand_over:
                self._hand_over(asking, "handed over by the page that had it")
            else:
                self.tell(asking, "the page in control kept control")

    @property
    def needs_fresh_press(self) -> bool:
        """Whether the enabling device was released by a missed heartbeat and is held again
        only after the pointer let go of it and pressed it anew."""
        return self._fresh_press

    def told(self, client: int) -> tuple[str, ...]:
        """What page ``client`` was told (refusals, control), the latest :data:`TOLD_KEPT`,
        oldest first."""
        with self._lock:
            return tuple(self._told.get(client, ()))

    def tell(self, client: int, text: str, *, throttle: bool = False) -> None:
        """Tell page ``client`` alone (a notification on that page, as text).

        Args:
            client: The page.
            text: The message.
            throttle: Skip it if the same was told to that page under a second ago.
        """
        with self._lock:
            now = time.monotonic()
            if throttle:
                if now - self._told_at.get((client, text), -math.inf) < TELL_EVERY_S:
                    return
                if len(self._told_at) > 1000:
                    self._told_at.clear()
                self._told_at[(client, text)] = now
            self._told.setdefault(client, deque(maxlen=TOLD_KEPT)).append(text)
            handle = self.server.get_clients().get(client)
        if handle is not None:
            with contextlib.suppress(Exception):    # a page going away: nothing to tell
                handle.add_notification("Pendant", text, auto_close_seconds=6.0,
                                        color="orange")

    def _hand_over(self, to: int | None, why: str) -> None:
        """Control to page ``to`` (None: no page), from a released enabling device and
        disarmed guiding."""
        self._armed, self._beat, self._fresh_press = False, None, False
        self._send_enable(force=True)
        self._release_hand()
        old, self._controller = self._controller, to
        if old is not None and old != to:
            self.tell(old, "control handed over: this page is read-only now")
        if to is not None:
            self.tell(to, f"this page has control ({why}); arm guiding to guide")
        self._show_roles()

    def _ask(self, controller: int, asking: int) -> None:
        """Ask the page in control (a dialog on that page) to hand over to ``asking``."""
        self.tell(controller, f"page {asking} asks for control")
        handle = self.server.get_clients().get(controller)
        if handle is None:
            return
        self._close_ask()
        with contextlib.suppress(Exception), handle.gui.add_modal("Control requested") as modal:
            handle.gui.add_html(text_html([f"Page {asking} asks for control of the robot. "
                                           "Handing over disarms guiding."]))
            give = handle.gui.add_button("Hand over control", color="orange")
            keep = handle.gui.add_button("Keep control", color="green")
            give.on_click(lambda e: self.answer_control(_client_of(e), True))
            keep.on_click(lambda e: self.answer_control(_client_of(e), False))
            self._modal = modal

    def _close_ask(self) -> None:
        modal, self._modal = self._modal, None
        if modal is not None:
            with contextlib.suppress(Exception):
                modal.close()

    def _connected(self, client: Any) -> None:
        with self._lock:
            cid = int(client.client_id)
            with contextlib.suppress(Exception):
                self._roles[cid] = client.gui.add_html(text_html([self._role(cid)]), order=1)

    def _disconnected(self, client: Any) -> None:
        """A page went: its view is dropped; if it had control, the enabling device is
        released, guiding disarmed, and control passes to a page that asked for it."""
        cid = int(client.client_id)
        with self._lock:
            self._roles.pop(cid, None)
            self._told.pop(cid, None)
            if cid == self._asking:
                self._asking = None
            if cid == self._controller:
                asking, self._asking = self._asking, None
                self._modal = None
                self._hand_over(asking, "the page that had it disconnected")

    def _role(self, client: int) -> str:
        if client == self._controller:
            return "This page has control."
        if self._controller is None:
            return "Read-only: no page has control ('Take control')."
        return f"Read-only: page {self._controller} has control."

    def _show_roles(self) -> None:
        for cid, handle in list(self._roles.items()):
            with contextlib.suppress(Exception):
                handle.content = text_html([self._role(cid)])
        self.controls.show_controller("no page has control" if self._controller is None
                                      else f"page {self._controller} has control")

    # ------------------------------------------------------------ the operator's actions
    def arm(self, client: int, on: bool) -> None:
        """Arm or disarm guiding (disarming releases the enabling input); the page in
        control only."""
        with self._lock:
            if not self.may_act(client, "arming"):
                return
            self._armed = bool(on)
            self._send_enable(force=True)

    def hold_device(self, client: int) -> None:
        """A heartbeat of the page's hold-to-run enabling device (sent :data:`~leadthrough.
        pendant.controls.HOLD_HZ` times a second while the pointer is held on it): pressed
        for :attr:`lease_s` (:data:`LEASE_S`) from now, then released unless the next one
        comes. The page in
        control only; on a robot there is none (its own enabling device enables)."""
        with self._lock:
            if self.hand is None:
                self.tell(client, "no enabling device on the page: the robot's own enabling "
                                  "device enables guiding", throttle=True)
                return
            if not self.may_act(client, "the enabling device"):
                return
            now = time.monotonic()
            if self._beat is not None and now - self._beat > self.lease_s:
                self._lapse()               # (this pendant stalled: the loop dropped it too)
                return
            if self._fresh_press:
                self.tell(client, "enabling device released after a missed heartbeat: let go "
                                  "of it and press it again", throttle=True)
                return
            self._beat = now
            self._send_enable()

    def release_device(self, client: int) -> None:
        """The pointer let go of the enabling device: released at once."""
        with self._lock:
            if client != self._controller:
                return          # a read-only page holds nothing to let go of
            self._beat, self._fresh_press = None, False
            self._send_enable(force=True)

    def _device_held(self) -> bool:
        return self._beat is not None and time.monotonic() - self._beat <= self.lease_s

    def _send_enable(self, *, force: bool = False) -> None:
        """The enabling input as the pendant has it: held (armed, and a heartbeat within
        the lease, which the loop enforces too) or released (sent when it changes, or
        ``force``)."""
        if self._armed and self._beat is not None and self.hand is not None:
            self.live.send(SetEnable(True, until=self._beat + self.lease_s))
            self._sent_held = True
        elif self._sent_held or force:
            self.live.send(SetEnable(False))
            self._sent_held = False

    def _watch_heartbeat(self) -> None:
        """Release the enabling device once the page in control missed its heartbeats for
        :data:`LEASE_S` (the loop drops the lease by itself too)."""
        with self._lock:
            if self._beat is not None and time.monotonic() - self._beat > self.lease_s:
                self._lapse()

    def _lapse(self) -> None:
        """A missed heartbeat: released, and held again only after the pointer let go of the
        device and pressed it anew (heartbeats that resume after a stall of the page or of
        this process do not press it again)."""
        self._beat, self._fresh_press = None, True
        self._send_enable(force=True)
        if self._controller is not None:
            self.tell(self._controller, "enabling device released: no heartbeat from this "
                                        f"page for {1e3 * self.lease_s:.0f} ms; let go of it "
                                        "and press it again")

    def clear_fault(self, client: int) -> None:
        """Ask the loop to clear a latched fault (the page in control only)."""
        if self.may_act(client, "clearing a fault"):
            self.live.send(ClearFault())

    def mark(self, client: int, label: str | None) -> None:
        """Mark the current pose as ``label``, or as the next waypoint (None); a label
        outside the label charset (:func:`leadthrough.labels.check_label`) is refused to
        that page and nothing is sent."""
        if not self.may_act(client, "marking"):
            return
        request = MarkPoint(label if label is not None else self.points.next_waypoint())
        if self._checked(client, request, "mark"):
            self.live.send(request)

    def delete_point(self, client: int, label: str) -> None:
        """Remove a taught point (the page in control only)."""
        if self.may_act(client, "editing points") and self._point(client, label):
            self._edit(client, lambda: self.points.delete(label))

    def move_point(self, client: int, label: str, step: int) -> None:
        """Move a taught point up (−1) or down (+1) the list (the page in control only)."""
        if not (self.may_act(client, "editing points") and self._point(client, label)):
            return
        if not isinstance(step, int) or isinstance(step, bool) or step not in (-1, 1):
            self.tell(client, "move refused: a step is -1 (up) or +1 (down)")
            return
        self._edit(client, lambda: self.points.move(label, step))

    def _point(self, client: int, label: Any) -> bool:
        if is_label(label):
            return True
        self.tell(client, "edit refused: not a taught point's label")
        return False

    def _edit(self, client: int, change: Any) -> None:
        try:
            change()
        except LeadthroughError as e:
            self.tell(client, f"not changed: {e}")
        self._show_points()

    def adjust(self, client: int, **change: Any) -> None:
        """Ask the loop to change the frame, axes, mass or friction (see :class:`Adjust`);
        the page in control only, the values checked before they are sent."""
        if not self.may_act(client, "changing settings"):
            return
        try:
            request = Adjust(**change)
        except TypeError as e:
            self.tell(client, f"settings refused: {e}")
            return
        if self._checked(client, request, "settings"):
            self.live.send(request)

    def _checked(self, client: int, request: object, what: str) -> bool:
        """Whether ``request`` is well formed; if not, that page is told and nothing is
        sent."""
        try:
            check_request(request)
        except RequestError as e:
            self.tell(client, f"{what} refused: {e}")
            return False
        return True

    def export(self, client: int) -> str:
        """Write the session, the points and the taught path (the page in control only; one
        export at a time, :attr:`export_interval_s` apart, at most :attr:`max_exports` a
        run); returns what was written, or why not, as text."""
        if not self.may_act(client, "export"):
            return "not exported: this page is read-only"
        if not self._export_lock.acquire(blocking=False):
            return self._not_exported(client, "an export is under way")
        try:
            now = time.monotonic()
            if self._exports >= self.max_exports:
                return self._not_exported(client, f"{self.max_exports} exports is the most a "
                                                  "run makes (restart the pendant for more)")
            wait = self._export_at + self.export_interval_s - now
            if wait > 0:
                return self._not_exported(client, f"exports are {self.export_interval_s:g} s "
                                                  f"apart (again in {wait:.0f} s)")
            self._export_at, self._exports = now, self._exports + 1
            try:
                points = list(self.points.points)
                done = export_taught(self.live.session_log(points), points, self.robot,
                                     self.out)
            except LeadthroughError as e:
                return self._not_exported(client, str(e))
        finally:
            self._export_lock.release()
        files = ", ".join(p.name for p in done.files.values())
        note = f" ({done.note})" if done.note else ""
        return f"exported to {done.folder}: {files}{note}"

    def _not_exported(self, client: int, why: str) -> str:
        self.tell(client, f"not exported: {why}")
        return f"not exported: {why}"

    def push(self, client: int, force_n: Any) -> None:
        """Push the simulated tool with a force [N], base frame (simulator only; the page in
        control only; refused unless 3 finite numbers within the hand's limit)."""
        if self.hand is None or not self.may_act(client, "pushing"):
            return
        try:
            self.hand.push(force_n)
        except RequestError as e:
            self.tell(client, f"push refused: {e}")

    def release_push(self, client: int) -> None:
        """Let go of the simulated tool (the page in control only)."""
        if self.may_act(client, "pushing"):
            self._release_hand()

    def _release_hand(self) -> None:
        self._holding = False
        if self.hand is not None:
            self.hand.release()

    # ------------------------------------------------------------ the page
    def _refresh_loop(self) -> None:
        while not self._stop.wait(1.0 / UI_HZ):
            try:
                self._watch_heartbeat()
                self.refresh()
            except Exception as e:  # a page error must not end the page's updates
                self._notices.append(f"warning: page update failed: {type(e).__name__}: {e}")

    def refresh(self) -> None:
        """Bring the page up to the loop's latest snapshot (called :data:`UI_HZ` times a
        second by the pendant's thread): the 3D view every time, the panels at
        :data:`PANEL_HZ` or on a change of state. Nothing is done while no browser is
        connected."""
        if not self.server.get_clients():
            return
        snap = self.live.snapshot()
        extras = self._extras()
        now = time.monotonic()
        state = None if snap is None else (snap.state, snap.error)
        panels = now - self._panels_at >= 1.0 / PANEL_HZ or state != self._panels_state
        with self.server.atomic():
            if panels:
                self._panels_at, self._panels_state = now, state
                self.controls.status.content = status_html(snap, extras)
            if snap is None:
                return
            self.scene.update(snap.q, snap.wrench_base[:3], extras.push_n)
            self._push_from_handle(snap.settings.virtual_friction.mass[0])
            if self.points.sync(snap.marks):
                self._show_points()
            if panels:
                self.controls.sync(snap.settings, extras.armed, extras.device)
                self._show_notices(snap)

    def _show_notices(self, snap: LoopSnapshot) -> None:
        """The loop's new notices and the page's own, latest last (as text)."""
        for notice in snap.notices:
            if notice.number > self._seen_notice:
                self._seen_notice = notice.number
                self._notices.append(f"{notice.level}: {notice.text}")
        self.controls.show_messages(list(self._notices))

    def _push_from_handle(self, mass_kg: float) -> None:
        """While the page in control drags the handle the hand holds it through the spring;
        let go after. A drag from a read-only page, or a handle not at a finite place within
        reach, pushes nothing (that page is told)."""
        if self.hand is None:
            return
        dragging, ended, handle = self.scene.drag_state()
        by = self.scene.drag_client
        if dragging and by is not None and self.may_act(by, "pushing"):
            try:
                self.spring.hold(self.hand, handle, mass_kg)
                self._holding = True
            except RequestError as e:
                self.tell(by, f"push refused: {e}", throttle=True)
                if self._holding:
                    self._release_hand()
        elif ended or self._holding:
            self._release_hand()

    def _show_points(self) -> None:
        points = self.points.points
        self.controls.show_points(points)
        self.scene.show_points(points)

    def _extras(self) -> StatusExtras:
        periods = self.live.period_times().work_us
        stats = (float(np.median(periods)), float(periods.max())) if periods.size else (0., 0.)
        return StatusExtras(armed=self._armed,
                            device=self._device_held() if self.hand is not None else None,
                            push_n=None if self.hand is None else self.hand.force_base,
                            period_us=stats, params=self.params_note)


def _client_of(event: Any) -> int:
    """The page an event came from (-1: none)."""
    client = getattr(event, "client_id", None)
    return -1 if client is None else int(client)


def wait_for_clients(pendant: Pendant, count: int = 1, timeout_s: float = 30.0) -> bool:
    """Whether ``count`` browsers connected within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if len(pendant.server.get_clients()) >= count:
            return True
        time.sleep(0.05)
    return False
