"""The loop's side of the operator's channel (:mod:`leadthrough.session.requests`): serving the
requests, in the loop's thread, and publishing the snapshot
(:mod:`leadthrough.session.snapshot`).

* **Marks** are taken at once, at the loop's time.
* **Settings** (frame, axes, virtual mass and friction) wait until the commanded motion is at
  rest (:meth:`ServoLoop.at_rest <leadthrough.session.servo_loop.ServoLoop.at_rest>`), then go
  to :meth:`GuidingController.retune <leadthrough.control.guiding.GuidingController.retune>`.
  The friction may not go below the session's configured friction (the floor chosen for the
  estimate's noise: lower, the robot drifts at rest) nor above half the collision thresholds
  (moving the robot would then trip the collision fault); the mass needs the virtual-friction
  law, the friction fixed friction (eq. 36 sets its own).
* **Fault reset**: at rest, with the robot controller reporting OK, the feedback finite and the
  robot within the following-error limit of its command (beyond it the reported position cannot
  be trusted to restart from: an encoder or a following fault), unless the controller stopped
  the robot itself (``Fault.CONTROLLER_STATE``: it stopped short of the commanded stop). Every
  part restarts at the measured position (after an E-stop the robot stopped where it was,
  short of the commanded stop); the estimator warms up and tares again,
  and guiding needs a fresh press.

A request that cannot be served is refused with a note: a ``loop`` event in the recording and
the snapshot's ``notice``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from leadthrough.control.guiding_types import GuidingConfig
from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.protocol import ControllerState
from leadthrough.errors import ControlError
from leadthrough.session.requests import Request, RequestKind

if TYPE_CHECKING:
    from leadthrough.session.servo_loop import ServoLoop

__all__ = ["apply_deferred", "publish", "publish_settings", "reset_fault", "serve"]


def serve(loop: ServoLoop, request: Request | None, t: float) -> None:
    """Serve one request (marks and resets at once, settings once at rest)."""
    if request is None:
        return
    if request.kind is RequestKind.MARK:
        loop.mark(t, request.value)
    elif request.kind is RequestKind.RESET_FAULT:
        reset_fault(loop, t)
    else:
        loop.deferred.append(request)


def apply_deferred(loop: ServoLoop, t: float) -> None:
    """Apply the settings requests that waited for rest, in order."""
    for request in loop.deferred:
        try:
            config = _new_config(loop, request)
            loop.controller.retune(config)
        except ControlError as e:
            loop.note(t, f"{request.kind} refused", e.message if e.expected is None
                      else f"{e.message} (expected {e.expected})")
            continue
        loop.note(t, str(request.kind), str(request.value))
    loop.deferred.clear()
    if loop.board is not None:
        publish_settings(loop)


def _new_config(loop: ServoLoop, request: Request) -> GuidingConfig:
    """The controller's settings with the request applied (checked against the session's
    bounds)."""
    cfg = loop.controller.config
    vf = cfg.virtual_friction
    kind, value = request.kind, request.value
    if kind is RequestKind.SET_FRAME:
        return replace(cfg, frame=value)
    if kind is RequestKind.SET_AXES:
        return replace(cfg, axes_enabled=value)
    if kind is RequestKind.SET_MASS:
        if cfg.controller != "virtual-friction":
            raise ControlError("no virtual mass in this law", expected="the virtual-friction law")
        return replace(cfg, virtual_friction=replace(vf, mass=value))
    if cfg.friction_mode != "fixed":
        raise ControlError("the friction is automatic (eq. 36)", expected="fixed friction")
    friction, stopping = value
    safety = cfg.safety
    ceiling = (0.5 * safety.max_force,) * 3 + (0.5 * safety.max_torque,) * 3
    if not all(lo <= f <= hi for f, lo, hi in zip(friction, loop.friction_floor, ceiling,
                                                    strict=True)):
        raise ControlError("friction outside the session's range",
                           expected=f"{loop.friction_floor} .. {ceiling} [N, N·m]")
    stopping = stopping if stopping is not None else tuple(
        max(s, f) for s, f in zip(vf.stopping_friction, friction, strict=True))
    return replace(cfg, virtual_friction=replace(vf, friction=friction,
                                                 stopping_friction=stopping))


def reset_fault(loop: ServoLoop, t: float) -> None:
    """Clear a latched fault and restart at the measured position (see the module doc)."""
    refusal = _reset_refusal(loop)
    if refusal is not None:
        loop.note(t, "reset refused", refusal)
        return
    try:
        loop.restart(loop.fb.q.copy(), t)
    except ControlError as e:
        loop.note(t, "reset refused", str(e))
        return
    loop.note(t, "fault reset", "restarted at the measured position; the estimator tares "
                                "again (hands off), then press the enabling device")


def _reset_refusal(loop: ServoLoop) -> str | None:
    """Why a fault reset cannot be made now (None: it can)."""
    if loop.controller.state != State.FAULT:
        return "no fault is latched"
    if not loop.at_rest():
        return "the stop is not complete"
    state = int(loop.fb.state)
    if state != ControllerState.NORMAL:
        name = (ControllerState(state).name if state in ControllerState._value2member_map_
                else f"code {state}")
        return f"the robot controller reports {name}"
    q, q_cmd = loop.fb.q, loop.c_out.q
    if not np.isfinite(q).all():
        return "the measured position is not finite"
    error = np.abs(q - q_cmd)
    limit = loop.controller.config.safety.following_error_limit
    # after the controller's own stop the robot is short of the commanded stop, where it
    # reports: its position is good to restart from
    if loop.controller.fault != Fault.CONTROLLER_STATE and error.max() > limit:
        j = int(np.argmax(error))
        return (f"joint {j + 1} is {error[j]:.4f} rad from its command (limit {limit} rad): "
                "check the robot and its encoders, then restart the session")
    return None


def publish_settings(loop: ServoLoop) -> None:
    """The controller's live settings into the snapshot."""
    board = loop.board
    if board is None or board.fields is None:
        return
    cfg, f = loop.controller.config, board.fields
    board.begin()
    f.axes_enabled = cfg.axes_enabled
    f.tool_frame = cfg.frame == "tool"
    f.mass = cfg.virtual_friction.mass
    f.friction = cfg.virtual_friction.friction
    f.stopping_friction = cfg.virtual_friction.stopping_friction
    board.end()


def publish(loop: ServoLoop, i: int, t: float) -> None:
    """The loop's state of this controller cycle into the snapshot (no allocation but the
    views of the pose's slices)."""
    board = loop.board
    if board is None or board.fields is None:
        return
    f, fb, c_out = board.fields, loop.fb, loop.c_out
    board.begin()
    f.t, f.period = t, i
    f.q, f.q_cmd = fb.q, loop.cmd.q
    pose = c_out.transform_tool_to_base
    f.tcp_rotation, f.tcp_position = pose[:3, :3], pose[:3, 3]
    f.wrench, f.twist = loop.e_out.wrench, c_out.twist_base
    f.state, f.fault = c_out.state, c_out.fault
    f.controller_state, f.estimator_status = fb.state, loop.e_out.status
    f.enable_held, f.enabled, f.ready = loop.held, loop.enabling.engaged, loop.ready
    f.friction = c_out.friction
    f.mark_count, f.late_periods, f.running = len(loop.marks), loop.late, True
    board.end()
