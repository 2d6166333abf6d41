"""The guiding controller's record: its settings and its state from one cycle to the next.

One NumPy structured record (:func:`controller_dtype`) that the compiled cycle
(:mod:`leadthrough.control.guiding_cycle`) reads by field; :class:`GuidingController
<leadthrough.control.guiding.GuidingController>` writes it with attribute access
(:mod:`leadthrough.state_records`) through the functions here: the settings a
:class:`~leadthrough.control.guiding_types.GuidingConfig` becomes (:func:`write_settings`, the
operator's part :func:`write_live_settings`), the state before the first reset
(:func:`write_initial_state`) and at a reset (:func:`write_reset_state`). Twists and wrenches
are 6-vectors in the controller's frame, linear first; poses are a rotation (3, 3) and a
position [m] (3,).
"""

from __future__ import annotations

import math
from enum import IntEnum
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.release import (
    RELEASE_DROP,
    RELEASE_HOLD,
    RELEASE_SMOOTHING_S,
    RELEASE_WINDOW_S,
)
from leadthrough.state_records import Fields

if TYPE_CHECKING:
    from leadthrough.control.guiding_types import GuidingConfig

__all__ = ["Law", "controller_dtype", "write_initial_state", "write_live_settings",
           "write_reset_state", "write_settings"]

Array = NDArray[np.float64]


class Law(IntEnum):
    """The force-following law the cycle runs (``GuidingConfig.controller``)."""

    #: Virtual mass and friction, eq. 31–33 (:mod:`leadthrough.control.virtual_friction`).
    VIRTUAL_FRICTION = 0
    #: The velocity baseline [14] (:mod:`leadthrough.control.velocity_baseline`).
    VELOCITY = 1


@cache
def controller_dtype(n: int) -> np.dtype[Any]:
    """The controller's record for ``n`` joints: settings, then state."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    six, pose = (f8, (6,)), (f8, (3, 3))
    return np.dtype([
        # settings
        ("dt", f8),                              # controller cycle [s]
        ("tool_frame", b1),                      # the law's frame is the tool's (else base)
        ("law", i8),                             # Law
        ("law_coefficients", *six),              # dt/M (virtual friction) or K (velocity)
        ("velocity_alpha", f8),                  # 1 − e^(−dt/T) of the velocity law
        ("axis_mask", *six),                     # 1.0 for an enabled axis, 0.0 for a disabled
        ("hold_s", f8),                          # settle_s + rezero_s [s]
        ("release_drop", f8), ("release_hold", f8),                            # release.py
        ("release_alpha", f8), ("release_forget", f8),
        ("hand_release", b1),                    # HandReleaseConfig.enabled
        ("hand_drop_fraction", f8), ("hand_lockout_s", f8), ("hand_window_s", f8),  # [-, s, s]
        ("hand_alpha", f8), ("hand_forget", f8), ("hand_rise_forget", f8),  # per cycle
        ("drift_rate", f8), ("drift_span_s", f8),   # rest_drift.py: 1/drift_s [1/s], [s]
        ("drift_alpha_fast", f8), ("drift_alpha_slow", f8), ("drift_decay", f8),  # per cycle
        ("max_speed", f8, (2,)),                 # (v_max, ω_max) [m/s, rad/s]
        ("max_step", f8, (2,)),                  # (a_max·dt, α_max·dt) [m/s, rad/s]
        ("stop_fraction", f8),                   # IKConfig.stop_acceleration_fraction
        # state: flags
        ("started", b1),                         # reset() was called
        ("kinematics_fresh", b1),                # the IK's kinematics are the setpoint's ...
        ("kinematics_new", b1),                  # ... and were computed since the last cycle
        ("residual_fresh", b1),                  # residual is that of the commanded pose
        ("resync", b1),                          # hold the setpoint's pose as the commanded one
        ("hand_released", b1),                   # the hand let go: stopping (hand_release.py)
        ("hand_settled", b1),                    # ... and the drives have settled at rest
        ("hand_level_taken", b1),                # ... once since the letting go
        # state: scalars
        ("rest_s", f8),                          # time at rest [s] (0 while moving)
        ("release_s", f8),                       # time since the last release at rest [s]
        ("hand_release_s", f8),                  # time since the hand let go in motion [s]
        ("hand_settle_s", f8),                   # since it, or a fall back from the level [s]
        ("stop_plan", f8),                       # cycles of the stop the last check planned
        ("residual", f8),                        # ‖log6(T(q_cmd)⁻¹·T_cmd)‖ [m, rad]
        ("speed_scale", f8), ("ik_scale", f8),
        # state: per axis
        ("twist", *six),                         # commanded twist of the last cycle
        ("desired_twist", *six),                 # the law's
        ("next_twist", *six),                    # after the limits (or the stop)
        ("wrench", *six),                        # the law's input: frame, mask
        ("friction", *six), ("stopping_friction", *six),   # δ, δ_s [N, N·m]
        ("release_smooth", *six), ("release_peak", *six),  # release.py
        ("hand_smooth", *six), ("hand_peak", *six), ("hand_reference", *six),  # hand_release
        ("hand_level_reference", *six),          # hand_release.level_let_go's
        ("hand_peak_age", f8, (2,)),             # time since each part's peak [s]
        ("drift_fast", *six), ("drift_slow", *six),  # rest_drift.py: the two smoothings
        ("rest_baseline", *six),                 # rest_drift.py: b
        ("rest_wrench", *six),                   # the law's input at rest: w − b
        # state: the commanded TCP pose and the next one
        ("pose_rotation", *pose), ("pose_position", f8, (3,)),
        ("next_rotation", *pose), ("next_position", f8, (3,)),
        # state: per joint [rad, rad/s]
        ("q_cmd", f8, (n,)), ("qd_cmd", f8, (n,)),   # the setpoint and its velocity
        ("qd_dls", f8, (n,)),                    # the DLS velocity before the joint bounds
        ("q_next", f8, (n,)), ("qd_next", f8, (n,)),   # the IK step's result
        ("q_measured", f8, (n,)),                # last finite measurement before a reset
    ])


def write_settings(s: Fields, cfg: GuidingConfig) -> None:
    """The record's settings from ``cfg`` (the state untouched).

    Args:
        s: The controller's record.
        cfg: The controller's settings.
    """
    s.dt = cfg.dt
    write_live_settings(s, cfg)
    if cfg.controller != "virtual-friction":
        s.velocity_alpha = cfg.velocity_baseline.alpha(cfg.dt)
    s.hold_s = cfg.settle_s + cfg.rezero_s
    # rest_drift.py: the release detector's smoothing and window measure the drift's rate
    s.drift_rate = 1.0 / cfg.drift_s if cfg.drift_s > 0.0 else 0.0
    s.drift_span_s = RELEASE_WINDOW_S - RELEASE_SMOOTHING_S
    s.drift_alpha_fast = cfg.dt / (RELEASE_SMOOTHING_S + cfg.dt)
    s.drift_alpha_slow = cfg.dt / (RELEASE_WINDOW_S + cfg.dt)
    s.drift_decay = math.exp(-cfg.dt / cfg.drift_s) if cfg.drift_s > 0.0 else 0.0
    s.release_drop = RELEASE_DROP
    s.release_hold = RELEASE_HOLD
    s.release_alpha = cfg.dt / (RELEASE_SMOOTHING_S + cfg.dt)
    s.release_forget = math.exp(-cfg.dt / RELEASE_WINDOW_S)
    hr = cfg.hand_release
    s.hand_release = hr.enabled and cfg.controller == "virtual-friction"
    s.hand_drop_fraction = hr.drop_fraction
    s.hand_lockout_s, s.hand_window_s, s.hand_alpha = hr.lockout_s, hr.window_s, hr.alpha(
        cfg.dt)
    s.hand_forget, s.hand_rise_forget = hr.forget(cfg.dt), hr.rise_forget(cfg.dt)
    s.max_speed = cfg.limits.max_speed
    s.max_step = cfg.limits.max_step(cfg.dt)
    s.stop_fraction = cfg.ik.stop_acceleration_fraction


def write_live_settings(s: Fields, cfg: GuidingConfig) -> None:
    """The settings an operator may change: the frame, the law's coefficients, the axis
    mask and the friction (eq. 36 replaces it at the next cycle when automatic).

    Args:
        s: The controller's record.
        cfg: The controller's settings.
    """
    s.tool_frame = cfg.frame == "tool"
    if cfg.controller == "virtual-friction":
        s.law, s.law_coefficients = Law.VIRTUAL_FRICTION, cfg.virtual_friction.dt_over_mass(
            cfg.dt)
    else:
        s.law, s.law_coefficients = Law.VELOCITY, cfg.velocity_baseline.gain
    s.axis_mask = [1.0 if a else 0.0 for a in cfg.axes_enabled]
    s.friction = cfg.virtual_friction.friction
    s.stopping_friction = cfg.virtual_friction.stopping_friction


def write_initial_state(s: Fields) -> None:
    """The state before the first reset (after :func:`write_settings`).

    Args:
        s: The controller's record.
    """
    s.q_measured = math.nan       # the last finite q before the first reset
    s.rest_s = s.release_s = s.stop_plan = math.inf
    s.ik_scale = s.speed_scale = 1.0


def write_reset_state(s: Fields, rotation: Array, position: Array, has_box: bool) -> None:
    """The state of a (re)start at rest, after the setpoint, its kinematics and its friction
    are written: the law's twist and the detectors cleared, the commanded TCP pose the
    setpoint's, started.

    Args:
        s: The controller's record.
        rotation: The setpoint's TCP rotation, shape (3, 3).
        position: The setpoint's TCP position [m], shape (3,).
        has_box: Whether a workspace box is set (its stop is then checked from the first cycle).
    """
    s.twist = s.release_peak = s.release_smooth = s.rest_baseline = 0.0
    s.drift_fast = s.drift_slow = 0.0
    s.hand_smooth = s.hand_peak = s.hand_reference = s.hand_peak_age = 0.0
    s.hand_level_reference = 0.0
    s.hand_released = s.hand_settled = s.hand_level_taken = False
    s.hand_release_s = s.hand_settle_s = math.inf
    s.pose_rotation = rotation
    s.pose_position = position
    s.residual_fresh = s.resync = False
    s.started = True
    s.stop_plan = 0.0 if has_box else math.inf
    s.release_s = s.rest_s = math.inf
