"""The codes of the safety layer: its states, its faults and the causes of its transitions.

Defined once, here, as ``IntEnum``: the supervisor's compiled rules
(:mod:`leadthrough.control.safety_rules`) store and compare these very members (Numba treats
them as integer constants), the recordings store their values, and Python reads them back as
members.

States::

    IDLE ──deadman pressed──▶ GUIDING ──deadman released──▶ STOPPING ──at rest──▶ IDLE
      any state ──fault──▶ FAULT (latched) ──clear_fault() at rest──▶ IDLE
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["Cause", "Fault", "State"]


class State(IntEnum):
    """State of the guiding controller."""

    IDLE = 0
    GUIDING = 1
    STOPPING = 2
    FAULT = 3


class Fault(IntEnum):
    """Why the controller is in FAULT (``NONE`` otherwise)."""

    NONE = 0
    #: t, q, current or wrench not finite, or an input array of the wrong size (value: NaN,
    #: index: -1).
    NONFINITE_INPUT = 1
    #: Measured joint position outside its limits by more than the tolerance (value: q [rad]).
    POSITION_RANGE = 2
    #: |measured current| above max_current·factor (value: current [A]).
    CURRENT_RANGE = 3
    #: Sequence number not advancing for ``stale_cycles`` cycles (value: the sequence number).
    STALE_FEEDBACK = 4
    #: |q_measured − q_commanded| above the limit (value: the error [rad]).
    FOLLOWING_ERROR = 5
    #: ‖force‖ or ‖torque‖ of the estimated wrench above the threshold (value: the norm, index
    #: 0 force, 1 torque).
    COLLISION = 6
    #: A commanded joint within the margin of its limit and moving toward it (value: q [rad]).
    JOINT_LIMIT = 7
    #: The TCP plus its braking distance would leave the workspace box (value: clearance [m]).
    WORKSPACE = 8
    #: Manipulability below the stop threshold and falling (value: μ).
    SINGULARITY = 9
    #: The IK residual above its limit (value: ‖log6‖ [m, rad]).
    TRACKING = 10
    #: ``update`` called before the first ``reset`` (no commanded position yet).
    NOT_STARTED = 11
    #: The force estimator latched a fault since the last cycle (a non-finite or wrong-size
    #: sample between the controller's cycles, or an overflow; value: the estimator's status).
    ESTIMATOR = 12
    #: The robot controller reports a stop or a fault of its own: emergency or protective stop,
    #: not ready, a command refused (value: the driver's ``ControllerState``). Tripped by the
    #: guiding loop.
    CONTROLLER_STATE = 13
    #: The driver raised: the link to the controller failed (tripped by the guiding loop).
    DRIVER_ERROR = 14
    #: A driver call blocked beyond the loop's watchdog timeout (value: how long [s]; tripped
    #: by the guiding loop).
    DRIVER_TIMEOUT = 15


class Cause(IntEnum):
    """Cause of a state transition."""

    DEADMAN_PRESSED = 0
    DEADMAN_RELEASED = 1
    STOPPED = 2
    FAULT = 3
    FAULT_CLEARED = 4
    RESET = 5
