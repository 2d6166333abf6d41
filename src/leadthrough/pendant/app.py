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

Safety on the page: guiding needs the pendant armed *and* the enabling device held. On the
simulator the page provides that device (a press/release button); on a robot it is the robot's
own physical input and the page cannot enable guiding by itself. Any browser disconnecting
releases the simulated enabling device and disarms.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import viser

from leadthrough.control.safety import State
from leadthrough.errors import LeadthroughError
from leadthrough.pendant.access import DEFAULT_MAX_CLIENTS, Gate, new_token, serve_gated
from leadthrough.pendant.backend import (
    Adjust,
    ClearFault,
    LiveSession,
    LoopSnapshot,
    MarkPoint,
    SetEnable,
)
from leadthrough.pendant.controls import Controls
from leadthrough.pendant.export import export_taught
from leadthrough.pendant.push import Hand, PushSpring
from leadthrough.pendant.scene_view import SceneView
from leadthrough.pendant.status_view import StatusExtras, status_html
from leadthrough.pendant.taught_points import TaughtPoints

__all__ = ["PANEL_HZ", "UI_HZ", "Pendant", "wait_for_clients"]

#: Updates of the 3D view per second.
UI_HZ = 20.0
#: Updates of the panels (status, controls, messages) per second, besides changes of state.
PANEL_HZ = 5.0


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
        self._armed, self._device = False, (False if hand is not None else None)
        self._lock = threading.Lock()
        self._notices: deque[str] = deque(maxlen=6)
        self._seen_notice = 0
        self._panels_at = 0.0
        self._panels_state: tuple[State, str | None] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._refresh_loop, name="leadthrough-pendant",
                                        daemon=True)
        self.server.on_client_disconnect(lambda _: self._disconnected())

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

    # ------------------------------------------------------------ the operator's actions
    def arm(self, on: bool) -> None:
        """Arm or disarm guiding (disarming releases the enabling input)."""
        with self._lock:
            self._armed = bool(on)
            self._send_enable()

    def press_device(self, on: bool) -> None:
        """Press or release the simulated enabling device (simulator only)."""
        with self._lock:
            if self._device is not None:
                self._device = bool(on)
                self._send_enable()

    def _send_enable(self) -> None:
        self.live.send(SetEnable(self._armed and self._device is True))

    def _disconnected(self) -> None:
        self.press_device(False)
        self.arm(False)
        self.release_push()

    def clear_fault(self) -> None:
        """Ask the loop to clear a latched fault."""
        self.live.send(ClearFault())

    def mark(self, label: str | None) -> None:
        """Mark the current pose as ``label``, or as the next waypoint (None)."""
        self.live.send(MarkPoint(label if label is not None else self.points.next_waypoint()))

    def delete_point(self, label: str) -> None:
        """Remove a taught point."""
        self._edit(lambda: self.points.delete(label))

    def move_point(self, label: str, step: int) -> None:
        """Move a taught point up (−1) or down (+1) the list."""
        self._edit(lambda: self.points.move(label, step))

    def _edit(self, change: Any) -> None:
        try:
            change()
        except LeadthroughError as e:
            self._notices.append(f"warning: {e}")
        self._show_points()

    def adjust(self, **change: Any) -> None:
        """Ask the loop to change the frame, axes, mass or friction (see :class:`Adjust`)."""
        self.live.send(Adjust(**change))

    def export(self) -> str:
        """Write the session, the points and the taught path; returns what was written (or
        why not), as Markdown."""
        try:
            points = list(self.points.points)
            done = export_taught(self.live.session_log(points), points, self.robot, self.out)
        except LeadthroughError as e:
            return f"**not exported**: {e}"
        files = ", ".join(f"`{p.name}`" for p in done.files.values())
        note = f"\n\n{done.note}" if done.note else ""
        return f"exported to `{done.folder}`: {files}{note}"

    def push(self, force_n: Any) -> None:
        """Push the simulated tool with a force [N], base frame (simulator only)."""
        if self.hand is not None:
            self.hand.push(force_n)

    def release_push(self) -> None:
        """Let go of the simulated tool."""
        if self.hand is not None:
            self.hand.release()

    # ------------------------------------------------------------ the page
    def _refresh_loop(self) -> None:
        while not self._stop.wait(1.0 / UI_HZ):
            try:
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
        """The loop's new notices and the page's own, latest last."""
        for notice in snap.notices:
            if notice.number > self._seen_notice:
                self._seen_notice = notice.number
                self._notices.append(f"{notice.level}: {notice.text}")
        text = "\n\n".join(self._notices)
        if self.controls.messages.content != text:
            self.controls.messages.content = text

    def _push_from_handle(self, mass_kg: float) -> None:
        """While the handle is dragged the hand holds it through the spring; let go after."""
        if self.hand is None:
            return
        dragging, ended, handle = self.scene.drag_state()
        if dragging:
            self.spring.hold(self.hand, handle, mass_kg)
        elif ended:
            self.hand.release()

    def _show_points(self) -> None:
        points = self.points.points
        self.controls.show_points(points)
        self.scene.show_points(points)

    def _extras(self) -> StatusExtras:
        periods = self.live.period_times().work_us
        stats = (float(np.median(periods)), float(periods.max())) if periods.size else (0., 0.)
        return StatusExtras(armed=self._armed, device=self._device,
                            push_n=None if self.hand is None else self.hand.force_base,
                            period_us=stats, params=self.params_note)


def wait_for_clients(pendant: Pendant, count: int = 1, timeout_s: float = 30.0) -> bool:
    """Whether ``count`` browsers connected within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if len(pendant.server.get_clients()) >= count:
            return True
        time.sleep(0.05)
    return False
