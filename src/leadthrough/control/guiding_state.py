"""The guiding controller's record: its settings and its state from one cycle to the next.

One NumPy structured record (:func:`controller_dtype`) that the compiled cycle
(:mod:`leadthrough.control.guiding_cycle`) reads by field; :class:`GuidingController
<leadthrough.control.guiding.GuidingController>` fills the settings once and reads the state
with attribute access (:mod:`leadthrough.state_records`). Twists and wrenches are 6-vectors in
the controller's frame, linear first; poses are a rotation (3, 3) and a position [m] (3,).
"""

from __future__ import annotations

from enum import IntEnum
from functools import cache
from typing import Any

import numpy as np

__all__ = ["Law", "controller_dtype"]


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
        ("release_drop", f8), ("release_alpha", f8), ("release_forget", f8),   # release.py
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
        # state: scalars
        ("rest_s", f8),                          # time at rest [s] (0 while moving)
        ("release_s", f8),                       # time since the last release at rest [s]
        ("hand_release_s", f8),                  # time since the hand let go in motion [s]
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

