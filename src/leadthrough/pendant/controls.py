"""The pendant's controls: control of the pendant, guiding, teach, settings, as viser GUI
elements (large buttons for a tablet), and their synchronisation with the loop's snapshot.

Every control calls one :class:`Actions` method with the page (viser client id) it came from;
the pendant decides whether that page may act (one controlling page, the others read-only);
nothing here talks to the loop. A setting shown on a control follows the value in force (the
snapshot's): after the operator changes it the control keeps the new value for
:data:`PENDING_S` while the loop applies it, then shows what is in force, so a refused change
(the robot is being guided, or a read-only page) or a clamped one (outside
``GuidingConfig.operator_limits``) is visible on the control itself.

The simulator's enabling device is hold-to-run: a button that sends a heartbeat
(:meth:`viser.GuiButtonHandle.on_hold`, :data:`HOLD_HZ`) while the pointer is down on it; its
click (the pointer let go on it) releases at once, and the pendant releases on a missing
heartbeat. Text that the operator or the loop wrote (labels, notices, an export's result) is
shown escaped, as text (:func:`text_html`), never as Markdown or HTML.
"""

from __future__ import annotations

import html
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, Protocol

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.guiding_types import AXIS_NAMES
from leadthrough.pendant.backend import MarkedPoint

__all__ = ["DEVICE_LABEL", "HOLD_HZ", "PENDING_S", "Actions", "Controls", "text_html"]

#: How long a changed setting waits for the loop before the control shows the value in force [s].
PENDING_S = 1.0
#: Heartbeats per second of the held enabling device (the pendant's lease lasts 0.2 s: three).
#: Below 20 Hz on purpose: viser's page sends the panel's messages through one sender that
#: passes one message per 50 ms and keeps only the latest of those that wait, so heartbeats
#: 50 ms apart or closer would replace the operator's clicks (a mark, a disarm) made while
#: the device is held; at 15 Hz a click waits at most 50 ms and is never lost.
HOLD_HZ = 15.0
#: The simulated enabling device's button.
DEVICE_LABEL = "Hold to enable"


def text_html(lines: Sequence[str], *, empty: str = "") -> str:
    """``lines`` as HTML text: escaped, one per line (``empty`` when there are none)."""
    body = "<br>".join(html.escape(line) for line in lines) if lines else \
        f"<i>{html.escape(empty)}</i>" if empty else ""
    return f'<div style="font-size:14px;overflow-wrap:anywhere">{body}</div>'


class Actions(Protocol):
    """What the controls ask of the pendant, each for the page (client id) it came from."""

    def take_control(self, client: int) -> None: ...
    def arm(self, client: int, on: bool) -> None: ...
    def hold_device(self, client: int) -> None: ...
    def release_device(self, client: int) -> None: ...
    def clear_fault(self, client: int) -> None: ...
    def mark(self, client: int, label: str | None) -> None: ...
    def delete_point(self, client: int, label: str) -> None: ...
    def move_point(self, client: int, label: str, step: int) -> None: ...
    def export(self, client: int) -> str: ...
    def adjust(self, client: int, **change: Any) -> None: ...
    def may_act(self, client: int, what: str) -> bool: ...


class _Setting:
    """One control showing a setting in force, sending the operator's changes (a change from
    a page that may not act is undone at once)."""

    def __init__(self, handle: Any, in_force: Callable[[GuidingConfig], Any],
                 send: Callable[[int, Any], None], may_act: Callable[[int, str], bool],
                 what: str) -> None:
        self.handle, self.in_force, self._send, self._may_act = handle, in_force, send, may_act
        self.what = what
        self.config: GuidingConfig | None = None
        self._pending_until = 0.0
        handle.on_update(lambda e: self._changed(_client(e)))

    def _changed(self, client: int) -> None:
        value = self.handle.value
        if self.config is None or value == self.in_force(self.config):
            return
        if not self._may_act(client, self.what):
            self.handle.value = self.in_force(self.config)     # shown as in force again
            return
        self._pending_until = time.monotonic() + PENDING_S
        self._send(client, value)

    def sync(self, config: GuidingConfig) -> None:
        self.config = config
        value = self.in_force(config)
        if self.handle.value != value and time.monotonic() >= self._pending_until:
            self.handle.value = value


def _client(event: Any) -> int:
    """The page an event came from (-1: none, refused by the pendant)."""
    client = getattr(event, "client_id", None)
    return -1 if client is None else int(client)


def _axis_in_force(k: int, config: GuidingConfig) -> bool:
    return config.axes_enabled[k]


def _law_in_force(key: str, k: int, config: GuidingConfig) -> float:
    return float(getattr(config.virtual_friction, key)[k])


class Controls:
    """The pendant's GUI.

    Args:
        gui: The viser server's ``gui``.
        actions: The pendant.
        config: The controller's settings at start (limits of the sliders).
        simulated: Show the simulated enabling device.
    """

    def __init__(self, gui: Any, actions: Actions, config: GuidingConfig,
                 simulated: bool) -> None:
        self._gui, self._actions, self._config = gui, actions, config
        self.status = gui.add_html("", order=0)
        self._control(gui, actions)
        self._guiding(gui, actions, simulated)
        self._teach(gui, actions)
        self._settings(gui, config)
        self.messages = gui.add_html("", order=90)

    def _control(self, gui: Any, actions: Actions) -> None:
        with gui.add_folder("Control", order=5):
            self.controller = gui.add_html(text_html(["no page has control"]))
            self.take = gui.add_button(
                "Take control", color="orange", icon="hand-stop",
                hint="one page controls the robot, the others are read-only; the page in "
                     "control confirms a hand-over")
            self.take.on_click(lambda e: actions.take_control(_client(e)))

    def _guiding(self, gui: Any, actions: Actions, simulated: bool) -> None:
        with gui.add_folder("Guiding", order=10):
            self.arm = gui.add_button("Arm guiding", color="green", icon="player-play")
            self.arm.on_click(lambda e: actions.arm(_client(e),
                                                    self.arm.label == "Arm guiding"))
            self.device = None
            if simulated:
                self.device = gui.add_button(
                    DEVICE_LABEL, color="blue",
                    hint="hold-to-run: the simulator's stand-in for the robot's three-position "
                         "enabling switch, pressed only while held")

                async def beat(event: Any) -> None:     # (async: in order with the release)
                    actions.hold_device(_client(event))

                async def let_go(event: Any) -> None:
                    actions.release_device(_client(event))

                self.device.on_hold(beat, callback_hz=HOLD_HZ)
                self.device.on_click(let_go)
            gui.add_button("Clear fault", color="red").on_click(
                lambda e: actions.clear_fault(_client(e)))

    def _teach(self, gui: Any, actions: Actions) -> None:
        with gui.add_folder("Teach", order=20):
            self.marks = gui.add_button_group("Mark", ("P1", "P2", "Waypoint"))
            self.marks.on_click(lambda e: actions.mark(_client(e), None if e.target.value ==
                                                  "Waypoint" else e.target.value))
            self.points = gui.add_html(text_html([], empty="no points yet"))
            self.selected = gui.add_dropdown("Point", ("-",))
            edit = gui.add_button_group("Edit point", ("Up", "Down", "Delete"))
            edit.on_click(lambda e: self._edit(_client(e), e.target.value))
            self.export = gui.add_button("Export", color="indigo", icon="download")
            self.export_note = gui.add_html("")
            self.export.on_click(lambda e: self._export(_client(e)))

    def _edit(self, client: int, what: str) -> None:
        label = self.selected.value
        if label == "-":
            return
        if what == "Delete":
            self._actions.delete_point(client, label)
        else:
            self._actions.move_point(client, label, -1 if what == "Up" else 1)

    def _export(self, client: int) -> None:
        if not self._actions.may_act(client, "export"):
            return
        self.export_note.content = text_html(["exporting ..."])
        self.export_note.content = text_html([self._actions.export(client)])

    def _settings(self, gui: Any, config: GuidingConfig) -> None:
        lim, act = config.operator_limits, self._actions
        may = act.may_act
        with gui.add_folder("Settings (while not guiding)", order=30):
            self.frame = frame = gui.add_dropdown("Frame", ("base", "tool"),
                                                  initial_value=config.frame)
            self._synced = [_Setting(frame, lambda c: c.frame,
                                     lambda client, v: act.adjust(client, frame=v), may,
                                     "change the frame")]
            for k, name in enumerate(AXIS_NAMES):
                box = gui.add_checkbox(f"axis {name}", config.axes_enabled[k])
                self._synced.append(_Setting(box, partial(_axis_in_force, k),
                                             partial(self._axis, k), may, "change the axes"))
            vf = config.virtual_friction
            for label, bounds, step, k, key in (
                    ("Mass [kg]", lim.linear_mass, 10.0, 0, "mass"),
                    ("Inertia [kg·m²]", lim.angular_mass, 5.0, 3, "mass"),
                    ("Friction [N]", lim.linear_friction, 1.0, 0, "friction"),
                    ("Friction [N·m]", lim.angular_friction, 1.0, 3, "friction")):
                value = getattr(vf, key)[k]
                slider = gui.add_slider(label, min=bounds[0], max=bounds[1], step=step,
                                        initial_value=min(max(value, bounds[0]), bounds[1]))
                self._synced.append(_Setting(slider, partial(_law_in_force, key, k),
                                             partial(self._law, key, k), may,
                                             f"change {key}"))

    def _axis(self, k: int, client: int, on: bool) -> None:
        axes = list(self._config.axes_enabled)
        axes[k] = bool(on)
        self._actions.adjust(client, axes_enabled=tuple(axes))

    def _law(self, key: str, k: int, client: int, value: float) -> None:
        pair = list(getattr(self._config.virtual_friction, key)[::3])
        pair[k // 3] = float(value)
        self._actions.adjust(client, **{key: tuple(pair)})

    def sync(self, config: GuidingConfig, armed: bool, device: bool | None) -> None:
        """Show the settings in force and the enabling state."""
        self._config = config
        for setting in self._synced:
            setting.sync(config)
        self.arm.label = "Disarm" if armed else "Arm guiding"
        self.arm.color = "gray" if armed else "green"
        if self.device is not None:
            self.device.color = "green" if device else "blue"

    def show_controller(self, text: str) -> None:
        """Say which page has control (as text)."""
        content = text_html([text])
        if self.controller.content != content:
            self.controller.content = content

    def show_messages(self, lines: Sequence[str]) -> None:
        """The latest notices, as text."""
        content = text_html(lines)
        if self.messages.content != content:
            self.messages.content = content

    def show_points(self, points: tuple[MarkedPoint, ...]) -> None:
        """List the taught points (as text) and offer them for editing."""
        self.points.content = text_html(
            [f"{k + 1}. {p.label} at {p.t:.2f} s" for k, p in enumerate(points)],
            empty="no points yet")
        labels = tuple(p.label for p in points) or ("-",)
        current = self.selected.value
        self.selected.options = labels
        self.selected.value = current if current in labels else labels[-1]
