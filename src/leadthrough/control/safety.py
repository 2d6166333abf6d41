"""Safety layer of hand guiding: states, faults, and the log of every transition.

States (:mod:`leadthrough.control.safety_states`)::

    IDLE ──deadman pressed──▶ GUIDING ──deadman released──▶ STOPPING ──at rest──▶ IDLE
      any state ──fault──▶ FAULT (latched) ──clear_fault() at rest──▶ IDLE

* Guiding needs the enabling input (deadman) held. By default a press only counts after the
  deadman was seen released (after start-up, a reset or a cleared fault), so nothing starts by
  itself.
* STOPPING and FAULT both decelerate the commanded twist to zero at the acceleration limit (never
  a position jump; the guiding controller does the motion); FAULT then holds and latches until
  :meth:`SafetySupervisor.clear_fault`.
* Faults (:class:`Fault`): non-finite input; measured position or current out of range; stale
  feedback (sequence number not advancing for N cycles); following error (measured vs commanded
  joint position); estimated wrench above a collision threshold (while guiding or stopping:
  see below); a joint near its limit and
  moving toward it; the workspace box (the TCP plus its braking distance would come closer to
  a face than a small margin); singularity (manipulability below a stop threshold and falling;
  below a higher threshold the speed is scaled down); the IK not reaching its target. The first
  fault is latched with the offending value and index; later ones are not recorded.
* The collision threshold is not checked in IDLE. The robot then holds still with the enabling
  device released: there is no motion to stop, and the estimate drifts at rest with the drives'
  torque against the gears' static friction (:mod:`leadthrough.control.rest_drift`). On the
  simulated er20 over FANUC J519 it passed 150 N 9 s after a seam's release and latched a
  COLLISION that nobody had caused, to be cleared by the operator. A press with the estimate
  still above the threshold trips COLLISION instead of starting guiding.

Every transition is logged as an :class:`Event` (time, from, to, cause, fault, value, index).
The log is a preallocated ring of the last ``max_events`` transitions (older ones dropped,
counted in ``events_dropped``): logging allocates nothing; :attr:`SafetySupervisor.events`
builds the :class:`Event` objects when asked.

The rules are compiled (:mod:`leadthrough.control.safety_rules`) and run on the supervisor's
record, so that the guiding cycle runs them inside its own compiled call; the methods here run
the same functions, one call each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.control import safety_rules as rules
from leadthrough.control.limits import CartesianLimits
from leadthrough.control.safety_states import Cause, Fault, State
from leadthrough.errors import ControlError, check_fields
from leadthrough.robot.description import Robot
from leadthrough.state_records import new_record, view

__all__ = [
    "Cause",
    "Event",
    "Fault",
    "SafetyConfig",
    "SafetySupervisor",
    "State",
]

Array = NDArray[np.float64]
_INF3 = (math.inf,) * 3


@dataclass(frozen=True)
class Event:
    """One logged state transition.

    Attributes:
        t: Time of the cycle [s] (the input's t).
        from_state: State before.
        to_state: State after.
        cause: Why.
        fault: The fault, for ``cause == FAULT``.
        value: The offending value (see :class:`Fault`), NaN if none.
        index: Joint or axis index, -1 if none.
    """

    t: float
    from_state: State
    to_state: State
    cause: Cause
    fault: Fault = Fault.NONE
    value: float = math.nan
    index: int = -1


def _event(e: np.void) -> Event:
    """An :class:`Event` from a row of the event ring."""
    return Event(float(e["t"]), State(e["from_state"]), State(e["to_state"]), Cause(e["cause"]),
                 Fault(e["fault"]), float(e["value"]), int(e["index"]))


def _finite(values: tuple[float, ...], n: int) -> bool:
    return len(values) == n and all(not math.isnan(v) for v in values)


@dataclass(frozen=True)
class SafetyConfig:
    """Thresholds of the safety layer, validated once.

    Attributes:
        stale_cycles: Faults after this many consecutive cycles without a new sequence number.
        following_error_limit: Max |q_measured − q_commanded| per joint [rad].
        max_force: Collision threshold on ‖force‖ of the estimated wrench [N].
        max_torque: Collision threshold on ‖torque‖ of the estimated wrench [N·m].
        current_range_factor: Measured |current| above factor·max_current is out of range.
        position_tolerance: Measured q beyond a joint limit by more than this is out of range
            [rad].
        joint_limit_margin: A commanded joint this close to its limit and moving toward it
            faults [rad]; larger than the IK's own margin, so the stop is a controlled one.
        workspace_min: Lower corner of the TCP workspace box in the base frame [m] (−inf: none).
        workspace_max: Upper corner [m] (+inf: none).
        workspace_margin: The commanded TCP is kept this far inside the box [m]; it absorbs the
            IK's residual (micrometres), so that the joint commands too, not only the Cartesian
            command, stay inside.
        slow_manipulability: Below this μ the speed limits are scaled down linearly.
        stop_manipulability: Below this μ, while μ is falling, the controller faults.
        min_speed_scale: Scale at (and below) ``stop_manipulability`` (> 0, so that the arm can
            be moved out of a singular pose after a reset).
        tracking_error_limit: Max ‖log6(T(q)⁻¹·T_target)‖ of the IK [m and rad, mixed].
        require_deadman_edge: Guiding starts only on a press seen after a release.
        max_events: Length of the transition log (oldest dropped).
    """

    stale_cycles: int = 3
    following_error_limit: float = 0.05
    max_force: float = 150.0
    max_torque: float = 50.0
    current_range_factor: float = 1.1
    position_tolerance: float = 0.01
    joint_limit_margin: float = 0.05
    workspace_min: tuple[float, float, float] = (-math.inf, -math.inf, -math.inf)
    workspace_max: tuple[float, float, float] = _INF3
    workspace_margin: float = 0.001
    slow_manipulability: float = 0.04
    stop_manipulability: float = 0.01
    min_speed_scale: float = 0.1
    tracking_error_limit: float = 0.005
    require_deadman_edge: bool = True
    max_events: int = 1000

    def __post_init__(self) -> None:
        pos = [(name, math.isfinite(getattr(self, name)) and getattr(self, name) > 0,
                "finite and > 0")
               for name in ("following_error_limit", "max_force", "max_torque",
                            "tracking_error_limit")]
        check_fields("safety", self, [
            ("stale_cycles", self.stale_cycles >= 1, ">= 1"),
            *pos,
            ("current_range_factor", self.current_range_factor >= 1, ">= 1"),
            ("position_tolerance", self.position_tolerance >= 0, ">= 0 rad"),
            ("joint_limit_margin", 0 <= self.joint_limit_margin < 0.5, "0 <= margin < 0.5 rad"),
            ("workspace_min", _finite(self.workspace_min, 3), "3 values (−inf for none) [m]"),
            ("workspace_max", _finite(self.workspace_max, 3) and all(
                lo < hi for lo, hi in zip(self.workspace_min, self.workspace_max, strict=True)),
             "3 values > workspace_min (+inf for none) [m]"),
            ("workspace_margin", 0 <= self.workspace_margin < 0.5 * min(
                hi - lo for lo, hi in zip(self.workspace_min, self.workspace_max, strict=True)),
             ">= 0 and less than half the box [m]"),
            ("stop_manipulability", self.stop_manipulability >= 0, ">= 0"),
            ("slow_manipulability", self.slow_manipulability > self.stop_manipulability,
             "> stop_manipulability"),
            ("min_speed_scale", 0 < self.min_speed_scale <= 1, "0 < scale <= 1"),
            ("max_events", self.max_events >= 1, ">= 1"),
        ], ControlError)


class SafetySupervisor:
    """The state machine and the fault checks (no motion: the guiding controller moves).

    Args:
        robot: The robot (joint limits, max currents).
        config: Thresholds.
        limits: Cartesian limits (braking distance for the workspace box).

    Attributes:
        record: The supervisor's record (:func:`~leadthrough.control.safety_rules.supervisor_dtype`:
            settings and state), read by field.
        event_ring: The last ``max_events`` transitions (``safety_rules.EVENT_DTYPE``).
    """

    def __init__(self, robot: Robot, config: SafetyConfig, limits: CartesianLimits) -> None:
        self.config = cfg = config
        self.limits = limits
        self.record = new_record(rules.supervisor_dtype(robot.n))
        self.event_ring = np.zeros(cfg.max_events, dtype=rules.EVENT_DTYPE)
        s = self._s = view(self.record)
        s.position_middle = 0.5 * (robot.lower_limits + robot.upper_limits)
        s.position_half_range = (0.5 * (robot.upper_limits - robot.lower_limits)
                                 + cfg.position_tolerance)
        s.max_current = robot.max_current * cfg.current_range_factor
        s.lower_margin = robot.lower_limits + cfg.joint_limit_margin
        s.upper_margin = robot.upper_limits - cfg.joint_limit_margin
        s.following_limit = cfg.following_error_limit
        s.max_force, s.max_torque = cfg.max_force, cfg.max_torque
        s.stop_manipulability = cfg.stop_manipulability
        s.slow_span = cfg.slow_manipulability - cfg.stop_manipulability
        s.min_speed_scale = cfg.min_speed_scale
        s.tracking_limit = cfg.tracking_error_limit
        s.workspace_margin = cfg.workspace_margin
        s.max_linear_acceleration = limits.max_linear_acceleration
        s.box_low, s.box_high = cfg.workspace_min, cfg.workspace_max
        s.has_box = bool(np.isfinite(cfg.workspace_min + cfg.workspace_max).any())
        s.stale_cycles = cfg.stale_cycles
        s.require_edge = cfg.require_deadman_edge
        s.state, s.fault, s.fault_index = State.IDLE, Fault.NONE, -1
        s.fault_value = s.mu_previous = math.nan
        s.armed = not cfg.require_deadman_edge
        s.inputs_finite = True

    # ----------------------------------------------------------------- state
    @property
    def state(self) -> State:
        """The current state."""
        return State(self._s.state)

    @property
    def fault(self) -> Fault:
        """The latched fault (``Fault.NONE`` unless in FAULT)."""
        return Fault(self._s.fault)

    @property
    def fault_value(self) -> float:
        """The latched fault's offending value (see :class:`Fault`), NaN if none."""
        return float(self._s.fault_value)

    @property
    def fault_index(self) -> int:
        """The latched fault's joint or axis index, -1 if none."""
        return int(self._s.fault_index)

    @property
    def inputs_finite(self) -> bool:
        """Whether t, q, current and wrench of the last ``check_feedback`` were all finite."""
        return bool(self._s.inputs_finite)

    @property
    def events(self) -> list[Event]:
        """The logged transitions, oldest first (at most ``max_events``)."""
        return self.events_since(0)

    @property
    def event_count(self) -> int:
        """Transitions logged since construction (dropped ones included)."""
        return int(self._s.event_count)

    def events_since(self, count: int) -> list[Event]:
        """The transitions logged after the first ``count``, oldest first (those still in the
        ring)."""
        ring, total = self.event_ring, int(self._s.event_count)
        cap = ring.size
        return [_event(ring[k % cap]) for k in range(max(0, total - cap, count), total)]

    @property
    def last_event(self) -> Event | None:
        """The latest transition, or None before the first."""
        count = int(self._s.event_count)
        if count == 0:
            return None
        return _event(self.event_ring[(count - 1) % self.event_ring.size])

    @property
    def events_dropped(self) -> int:
        """Number of transitions dropped from the bounded log (the oldest)."""
        return max(0, int(self._s.event_count) - self.event_ring.size)

    # ----------------------------------------------------------------- transitions
    def reset(self, t: float) -> None:
        """Back to IDLE, fault cleared, counters restarted (logged as RESET)."""
        rules.reset(self.record[0], self.event_ring, t)

    def trip(self, t: float, fault: Fault, value: float = math.nan, index: int = -1) -> None:
        """Enter FAULT (no-op if already there: the first fault is kept)."""
        rules.trip(self.record[0], self.event_ring, t, int(fault), value, index)

    def clear_fault(self, t: float, at_rest: bool) -> bool:
        """Leave FAULT for IDLE, only once the commanded motion is at rest.

        Returns:
            Whether the fault was cleared.
        """
        return bool(rules.clear_fault(self.record[0], self.event_ring, t, at_rest))

    def deadman(self, t: float, held: bool) -> None:
        """IDLE → GUIDING on a press, GUIDING → STOPPING on a release."""
        rules.deadman(self.record[0], self.event_ring, t, held)

    def stopped(self, t: float, at_rest: bool) -> None:
        """STOPPING → IDLE once the commanded motion is at rest."""
        rules.stopped(self.record[0], self.event_ring, t, at_rest)

    # ----------------------------------------------------------------- checks
    def check_feedback(self, t: float, sequence: int, q: Array, current: Array, wrench: Array,
                       q_commanded: Array) -> None:
        """Input faults: non-finite, stale, out of range, following error, collision (not in
        IDLE: module docstring).

        Args:
            t: Time [s].
            sequence: Feedback sequence number (must advance every cycle).
            q: Measured joint positions [rad], shape (n,).
            current: Measured motor currents [A], shape (n,).
            wrench: Estimated wrench [N, N·m], shape (6,), force first (any frame: norms only).
            q_commanded: Joint position commanded for now [rad], shape (n,).
        """
        rules.check_feedback(self.record[0], self.event_ring, t, sequence, q, current, wrench,
                             q_commanded)

    def check_motion(self, t: float, manipulability: float, q_commanded: Array,
                     qd_commanded: Array, residual: float) -> None:
        """Motion faults: singularity, joint limit, IK tracking.

        Args:
            t: Time [s].
            manipulability: μ at the commanded joint position.
            q_commanded: Commanded joint position [rad], shape (n,).
            qd_commanded: Commanded joint velocity of the last cycle [rad/s], shape (n,).
            residual: IK residual ‖log6(T(q)⁻¹·T_target)‖ [m, rad].
        """
        rules.check_motion(self.record[0], self.event_ring, t, manipulability, q_commanded,
                           qd_commanded, residual)

    def speed_scale(self, manipulability: float) -> float:
        """Factor of the speed limits near a singularity: (μ − μ_stop)/(μ_slow − μ_stop) of
        ``stop_manipulability`` and ``slow_manipulability``, clipped to
        [``min_speed_scale``, 1]."""
        return float(rules.speed_scale(self.record[0], manipulability))

    @property
    def has_box(self) -> bool:
        """Whether a workspace box is configured (a finite face)."""
        return bool(self._s.has_box)

    def workspace_clearance(self, position: Array, linear_speed: float,
                            stop_time: float = 0.0) -> float:
        """Distance left between the TCP's braking ball and the workspace box [m].

        Args:
            position: TCP position in the base frame [m], shape (3,).
            linear_speed: ‖v‖ of the TCP [m/s].
            stop_time: Lower bound on the time a stop takes [s] (the joints' own).

        Returns:
            min over the faces of (distance to the face) − margin − braking distance; negative:
            the TCP could not stop inside the box (less the margin). +inf without a box. The
            braking distance is ½·‖v‖·max(‖v‖/a_max, ``stop_time``).
        """
        return float(rules.workspace_clearance(self.record[0],
                                               np.asarray(position, dtype=float),
                                               linear_speed, stop_time))
