"""The pendant's controls: guiding, teach, settings, as viser GUI elements (large buttons for a
tablet), and their synchronisation with the loop's snapshot.

Every control calls one :class:`Actions` method; nothing here talks to the loop. A setting
shown on a control follows the value in force (the snapshot's): after the operator changes it
the control keeps the new value for :data:`PENDING_S` while the loop applies it, then shows
what is in force, so a refused change (the robot is being guided) or a clamped one (outside
``GuidingConfig.operator_limits``) is visible on the control itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any, Protocol

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.guiding_types import AXIS_NAMES
from leadthrough.pendant.backend import MarkedPoint

__all__ = ["PENDING_S", "Actions", "Controls"]

#: How long a changed setting waits for the loop before the control shows the value in force [s].
PENDING_S = 1.0


class Actions(Protocol):
    """What the controls ask of the pendant."""

    def arm(self, on: bool) -> None: ...
    def press_device(self, on: bool) -> None: ...
    def clear_fault(self) -> None: ...
    def mark(self, label: str | None) -> None: ...
    def delete_point(self, label: str) -> None: ...
    def move_point(self, label: str, step: int) -> None: ...
    def export(self) -> str: ...
    def adjust(self, **change: Any) -> None: ...


class _Setting:
    """One control showing a setting in force, sending the operator's changes."""

    def __init__(self, handle: Any, in_force: Callable[[GuidingConfig], Any],
                 send: Callable[[Any], None]) -> None:
        self.handle, self.in_force, self._send = handle, in_force, send
        self.config: GuidingConfig | None = None
        self._pending_until = 0.0
        handle.on_update(lambda _: self._changed())

    def _changed(self) -> None:
        value = self.handle.value
        if self.config is not None and value != self.in_force(self.config):
            self._pending_until = time.monotonic() + PENDING_S
            self._send(value)

    def sync(self, config: GuidingConfig) -> None:
        self.config = config
        value = self.in_force(config)
        if self.handle.value != value and time.monotonic() >= self._pending_until:
            self.handle.value = value


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
        self._guiding(gui, actions, simulated)
        self._teach(gui, actions)
        self._settings(gui, config)
        self.messages = gui.add_markdown("", order=90)

    def _guiding(self, gui: Any, actions: Actions, simulated: bool) -> None:
        with gui.add_folder("Guiding", order=10):
            self.arm = gui.add_button("Arm guiding", color="green", icon="player-play")
            self.arm.on_click(lambda _: actions.arm(self.arm.label == "Arm guiding"))
            self.device = None
            if simulated:
                self.device = gui.add_button("Press enabling device", color="blue",
                                             hint="the simulator's stand-in for the "
                                                  "robot's three-position enabling switch")
                self.device.on_click(lambda _: actions.press_device(
                    self.device is not None and self.device.label == "Press enabling device"))
            gui.add_button("Clear fault", color="red").on_click(lambda _: actions.clear_fault())

    def _teach(self, gui: Any, actions: Actions) -> None:
        with gui.add_folder("Teach", order=20):
            marks = gui.add_button_group("Mark", ("P1", "P2", "Waypoint"))
            marks.on_click(lambda e: actions.mark(None if e.target.value == "Waypoint"
                                                  else e.target.value))
            self.points = gui.add_markdown("_no points yet_")
            self.selected = gui.add_dropdown("Point", ("-",))
            edit = gui.add_button_group("Edit point", ("Up", "Down", "Delete"))
            edit.on_click(lambda e: self._edit(e.target.value))
            export = gui.add_button("Export", color="indigo", icon="download")
            self.export_note = gui.add_markdown("")
            export.on_click(lambda _: self._export())

    def _edit(self, what: str) -> None:
        label = self.selected.value
        if label == "-":
            return
        if what == "Delete":
            self._actions.delete_point(label)
        else:
            self._actions.move_point(label, -1 if what == "Up" else 1)

    def _export(self) -> None:
        self.export_note.content = "_exporting ..._"
        self.export_note.content = self._actions.export()

    def _settings(self, gui: Any, config: GuidingConfig) -> None:
        lim, act = config.operator_limits, self._actions
        with gui.add_folder("Settings (while not guiding)", order=30):
            frame = gui.add_dropdown("Frame", ("base", "tool"), initial_value=config.frame)
            self._synced = [_Setting(frame, lambda c: c.frame,
                                     lambda v: act.adjust(frame=v))]
            for k, name in enumerate(AXIS_NAMES):
                box = gui.add_checkbox(f"axis {name}", config.axes_enabled[k])
                self._synced.append(_Setting(box, partial(_axis_in_force, k),
                                             partial(self._axis, k)))
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
                                             partial(self._law, key, k)))

    def _axis(self, k: int, on: bool) -> None:
        axes = list(self._config.axes_enabled)
        axes[k] = bool(on)
        self._actions.adjust(axes_enabled=tuple(axes))

    def _law(self, key: str, k: int, value: float) -> None:
        pair = list(getattr(self._config.virtual_friction, key)[::3])
        pair[k // 3] = float(value)
        self._actions.adjust(**{key: tuple(pair)})

    def sync(self, config: GuidingConfig, armed: bool, device: bool | None) -> None:
        """Show the settings in force and the enabling state."""
        self._config = config
        for setting in self._synced:
            setting.sync(config)
        self.arm.label = "Disarm" if armed else "Arm guiding"
        self.arm.color = "gray" if armed else "green"
        if self.device is not None:
            self.device.label = "Release enabling device" if device else "Press enabling device"

    def show_points(self, points: tuple[MarkedPoint, ...]) -> None:
        """List the taught points and offer them for editing."""
        if points:
            self.points.content = "\n".join(
                f"{k + 1}. **{p.label}** at {p.t:.2f} s" for k, p in enumerate(points))
        else:
            self.points.content = "_no points yet_"
        labels = tuple(p.label for p in points) or ("-",)
        current = self.selected.value
        self.selected.options = labels
        self.selected.value = current if current in labels else labels[-1]
