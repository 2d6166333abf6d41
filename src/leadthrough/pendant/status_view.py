"""The pendant's status panel: the safety state in large type, and what the operator needs to
see at a glance (speed, force, frame and axes, the law's settings, the loop's timing).

A pure function of the loop's snapshot, rendered as HTML for viser's ``add_html``. Elements a
test or a screen reader looks for carry ids: ``lt-state`` (with ``data-state``), ``lt-cause``,
``lt-speed``, ``lt-force``, ``lt-push``, ``lt-frame``, ``lt-enable``, ``lt-fault``. On a robot
the enabling row is the controller's enabling input as the loop reads it (the page cannot
enable there), and the fault row keeps the latched fault in view once the session has stopped.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding_types import AXIS_NAMES
from leadthrough.control.safety import State
from leadthrough.pendant.backend import LoopSnapshot

__all__ = ["StatusExtras", "status_html"]

#: Background of the state banner (a colour-blind safe set: the word is always shown too).
STATE_COLORS = {State.IDLE: "#4f5b66", State.GUIDING: "#1b7f3b", State.STOPPING: "#b36b00",
                State.FAULT: "#c62828"}


@dataclass(frozen=True)
class StatusExtras:
    """What the status shows besides the snapshot.

    Attributes:
        armed: Guiding armed on the pendant.
        device: The (simulated) enabling device pressed; None on a robot (a physical input).
        push_n: The mouse's push on the simulated tool [N], shape (3,), or None.
        period_us: Median and max compute time of the loop's recent periods [µs].
        params: Where the identified parameters come from (one line).
    """

    armed: bool
    device: bool | None
    push_n: NDArray[np.float64] | None
    period_us: tuple[float, float]
    params: str


def _row(key: str, label: str, value: str) -> str:
    return (f'<div style="display:flex;justify-content:space-between;padding:2px 0">'
            f'<span style="color:#555">{label}</span>'
            f'<span id="lt-{key}" style="font-weight:600">{html.escape(value)}</span></div>')


def status_html(snap: LoopSnapshot | None, extras: StatusExtras) -> str:
    """The status panel's HTML (``snap`` None: the loop has not started)."""
    if snap is None:
        return ('<div id="lt-state" data-state="STARTING" style="font-size:40px;'
                'font-weight:800;padding:12px;color:#fff;background:#777">STARTING</div>')
    state = snap.state.name if snap.error is None else "STOPPED"
    color = STATE_COLORS.get(snap.state, "#777") if snap.error is None else "#222"
    cause = snap.error if snap.error is not None else snap.cause
    cfg = snap.settings
    axes = " ".join(name if on else "·" for name, on in zip(AXIS_NAMES, cfg.axes_enabled,
                                                            strict=True))
    force = snap.wrench_base[:3]
    vf = cfg.virtual_friction
    if extras.device is None:     # a robot: its own enabling device, read by the loop
        enable = ("controller's enabling input "
                  + ("pressed" if snap.enabled else "released"))
    else:
        enable = ("armed" if extras.armed else "not armed") + (
            ", enabling device pressed" if extras.device else ", enabling device released")
    rows = [
        _row("speed", "TCP speed", f"{1e3 * snap.speed:.0f} mm/s"),
        _row("force", "estimated force",
             f"{np.linalg.norm(force):.0f} N ({', '.join(f'{v:+.0f}' for v in force)})"),
    ]
    if extras.push_n is not None:
        rows.append(_row("push", "mouse push (sim)", f"{np.linalg.norm(extras.push_n):.0f} N"))
    rows += [
        _row("frame", "frame · axes", f"{cfg.frame} · {axes}"),
        _row("law", "mass · friction",
             f"{vf.mass[0]:g} kg, {vf.mass[3]:g} kg·m² · {vf.friction[0]:g} N, "
             f"{vf.friction[3]:g} N·m" + (" (auto)" if cfg.friction_mode == "auto" else "")),
        _row("enable", "enabling", enable),
        _row("fault", "fault", snap.fault.name),
        _row("estimator", "estimator", snap.estimator.name),
        _row("loop", "loop period work",
             f"{extras.period_us[0]:.0f} µs median, {extras.period_us[1]:.0f} µs max"),
        _row("time", "loop time", f"{snap.time:.1f} s"),
        _row("params", "parameters", extras.params),
    ]
    return (f'<div id="lt-state" data-state="{state}" style="font-size:44px;font-weight:800;'
            f'letter-spacing:1px;padding:10px 14px;color:#fff;background:{color};'
            f'border-radius:6px;text-align:center">{state}</div>'
            f'<div id="lt-cause" style="font-size:18px;font-weight:600;padding:4px 2px 8px;'
            f'min-height:1.2em">{html.escape(cause)}</div>'
            f'<div style="font-size:14px">{"".join(rows)}</div>')
