"""The real-time guiding loop: driver → estimator (1 ms) → controller (10 ms) → interpolator →
driver, recording everything.

Per servo period (``driver.dt``, 1 ms):

1. write the interpolated joint command, ``driver.step()`` (a simulated driver advances one
   period; a real one blocks until the next), ``driver.read(fb)``;
2. a new sample goes through the external force estimator (eq. 27–30);
3. every ``controller_every`` periods (10 ms), the guiding controller takes the measured state,
   the estimated wrench and the enabling input and produces a joint setpoint; the interpolator
   turns it into 1 ms position + velocity commands;
4. the row is recorded (preallocated arrays) and the compute time of steps 2–3 is measured.

Before the first period the compiled code of all three parts is loaded (``warm_up``), so that
no cycle compiles. The enabling input is held only once the estimator reports OK (after its
warm-up and tare): guiding with an estimate that has not settled would start the robot on filter
transients.

The loop itself reads the clock, to pace (``paced=True``) and to measure; the algorithms it
drives never do. It never raises once running: a driver or controller problem shows as a
fault state in the record. The estimator sees every sample and the controller every tenth:
an estimator fault (a bad sample between two cycles) reaches the controller as
``Fault.ESTIMATOR``.

Python's cyclic garbage collector is paused while the loop runs (and restored after): a
collection stalls whichever cycle it falls in by tens of µs, and the loop creates no reference
cycles for it to find (its temporaries are freed by reference counting; a test checks this), so
pausing it costs no memory.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leadthrough.control.guiding import GuidingController
from leadthrough.control.interpolation import JointInterpolator
from leadthrough.control.safety import Event
from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import EstimatorStatus, ExternalForceEstimator
from leadthrough.session.record import Mark, SessionEvent, SessionLog

__all__ = ["LoopResult", "ServoPeriods", "SessionBuffers", "run_session", "transition_event"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LoopResult:
    """A finished session.

    Attributes:
        log: Everything recorded.
        cycle_us: Compute time of each controller cycle's servo period (estimator +
            controller + IK + limits + interpolation) [µs], shape (cycles,).
        servo_us: Compute time of the other servo periods (estimator + interpolation) [µs].
    """

    log: SessionLog
    cycle_us: Array
    servo_us: Array


def run_session(
    driver: Driver,
    estimator: ExternalForceEstimator,
    controller: GuidingController,
    interpolator: JointInterpolator,
    duration_s: float,
    *,
    deadman: Callable[[float], bool] | None = None,
    marks: Sequence[Mark] = (),
    applied_wrench: Callable[[], Array] | None = None,
    paced: bool = False,
    settings: dict[str, object] | None = None,
) -> LoopResult:
    """Run a guiding session.

    Args:
        driver: The robot (simulated or real).
        estimator: External force estimator, configured with ``frame="base"`` and the driver's
            period.
        controller: Guiding controller; its cycle must be a multiple of the driver's period.
        interpolator: Controller cycle → servo period interpolation.
        duration_s: Session length [s].
        deadman: Enabling input as a function of time (default: held throughout).
        marks: Operator "mark point" presses, recorded as events.
        applied_wrench: A simulator's truth: the wrench applied this period (base frame),
            recorded for comparison; None for a real robot.
        paced: Pace the loop to the wall clock (real time) instead of running flat out.
        settings: Recorded in the session file.

    Returns:
        The recording and the compute times.

    Raises:
        ControlError: Mismatched periods or frames (checked before anything runs), or no
            feedback on the first read.
    """
    every = _check_setup(driver, estimator, controller, duration_s)
    dt = driver.dt
    steps = round(duration_s / dt)
    loop = _Loop(driver, estimator, controller, interpolator, every, deadman, applied_wrench)
    rec = _Buffers(steps, driver.n, applied_wrench is not None)
    t_start = loop.start()
    cycle_us = np.zeros(steps // every + 1)
    servo_us = np.zeros(steps)
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        wall0 = time.perf_counter()
        for i in range(steps):
            deadline = wall0 + (i + 1) * dt if paced else None
            t_loop = t_start + (i + 1) * dt   # the loop's clock: advances on stale feedback too
            servo_us[i] = loop.period(i, t_loop, deadline)
            loop.store(rec, i, t_loop)
    finally:
        if gc_was_enabled:
            gc.enable()
    is_cycle = np.arange(steps) % every == 0
    cycle_us[:int(is_cycle.sum())] = servo_us[is_cycle]
    events = [_transition(e) for e in controller.events]
    events += [SessionEvent(t=m.t, kind="mark", label=m.label) for m in marks
               if m.t <= rec.time[-1]]
    events.sort(key=lambda e: e.t)
    log = rec.to_log(controller.robot.name, events, settings or {})
    return LoopResult(log=log, cycle_us=cycle_us[:int(is_cycle.sum())],
                      servo_us=servo_us[~is_cycle])


def _check_setup(driver: Driver, estimator: ExternalForceEstimator,
                 controller: GuidingController, duration_s: float) -> int:
    """The loop's settings checked against each other; returns the servo periods per
    controller cycle."""
    dt = driver.dt
    every = round(controller.config.dt / dt)
    if every < 1 or abs(every * dt - controller.config.dt) > 1e-9:
        raise ControlError("controller cycle must be a multiple of the servo period",
                           field="controller.dt", value=controller.config.dt,
                           expected=f"k × {dt} s")
    if abs(estimator.config.dt - dt) > 1e-12 or estimator.config.frame != "base":
        raise ControlError("estimator must run at the servo period in the base frame",
                           field="estimator", value=(estimator.config.dt, estimator.config.frame),
                           expected=f"(dt={dt}, frame='base')")
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ControlError("must be > 0", field="duration_s", value=duration_s,
                           expected="> 0 s")
    return every


class _Loop:
    """One servo period of the loop at a time (preallocated inputs and outputs)."""

    def __init__(self, driver: Driver, estimator: ExternalForceEstimator,
                 controller: GuidingController, interpolator: JointInterpolator, every: int,
                 deadman: Callable[[float], bool] | None,
                 applied_wrench: Callable[[], Array] | None) -> None:
        self.driver, self.estimator, self.controller = driver, estimator, controller
        self.interpolator, self.every = interpolator, every
        self.deadman, self.applied_wrench = deadman, applied_wrench
        self.e_in, self.e_out = estimator.make_input(), estimator.make_output()
        # the feedback's arrays are the estimator input's and the command's velocity is its
        # qd_cmd (the command sent this period until the interpolator writes the next at its
        # end): the driver fills what the estimator reads, with no copies in the period
        self.e_in.q[:] = self.e_in.current[:] = np.nan
        self.fb = DriverFeedback(t=float("nan"), q=self.e_in.q, current=self.e_in.current,
                                 sequence=-1)
        self.cmd = JointCommand(q=np.zeros(driver.n), qd=self.e_in.qd_cmd)
        self.c_in, self.c_out = controller.make_input(), controller.make_output()
        cfg = controller.config
        self.settle_s, self.cycle_s = cfg.settle_s, cfg.dt
        self.rezero_samples = round(cfg.rezero_s / driver.dt)

    def start(self) -> float:
        """The first sample: every part reset there, their compiled code loaded; returns the
        sample's time [s]."""
        driver, fb = self.driver, self.fb
        driver.step()
        if not driver.read(fb):
            raise ControlError("no feedback on the first read (the robot must report a "
                               "position to start from)", field="driver",
                               value=type(driver).__name__,
                               expected="a fresh sample on the first read")
        q0 = fb.q.copy()
        self.estimator.reset(q0)
        self.controller.reset(q0, fb.t)
        self.interpolator.reset(q0)
        for part in (self.estimator, self.controller, self.interpolator):
            part.warm_up()
        self.interpolator.update(self.cmd)
        return fb.t

    def period(self, i: int, t_loop: float, deadline: float | None) -> float:
        """Servo period ``i``: send the command, step, read, estimate, every ``every``
        periods the controller cycle, interpolate. Returns the compute time [µs]."""
        driver, fb, cmd = self.driver, self.fb, self.cmd
        driver.write(cmd)
        if deadline is not None:
            _sleep_until(deadline)
        driver.step()
        fresh = driver.read(fb)
        t0 = time.perf_counter()
        if fresh:
            self.e_in.t = fb.t
            self.estimator.update(self.e_in, self.e_out)
        if i % self.every == 0:
            self._cycle(t_loop)
        self.interpolator.update(cmd)
        return (time.perf_counter() - t0) * 1e6

    def _cycle(self, t_loop: float) -> None:
        """The controller cycle and its setpoint for the interpolator."""
        c_in, c_out, e_out, fb = self.c_in, self.c_out, self.e_out, self.fb
        c_in.t = t_loop
        c_in.sequence = fb.sequence
        c_in.q[:] = fb.q
        c_in.current[:] = fb.current
        c_in.wrench_base[:] = e_out.wrench
        status = e_out.status
        held = True if self.deadman is None else self.deadman(t_loop)
        c_in.deadman = held and status == EstimatorStatus.OK
        c_in.estimator_status = int(status)
        self.controller.update(c_in, c_out)
        if self.rezero_samples:
            _zero_velocity_update(self.estimator, c_out.rest_s, self.settle_s, self.cycle_s,
                                  self.rezero_samples)
        self.interpolator.set_target(c_out.q, c_out.qd)

    def store(self, rec: _Buffers, i: int, t_loop: float) -> None:
        """Record servo period ``i``."""
        fb, cmd, e_out, c_out = self.fb, self.cmd, self.e_out, self.c_out
        rec.store(i, t_loop, fb.q, fb.current, e_out.tau_ext, e_out.wrench, cmd.q, cmd.qd,
                  c_out.transform_tool_to_base, c_out.twist_base, int(c_out.state),
                  int(c_out.fault),
                  self.applied_wrench() if self.applied_wrench is not None else None)


def _zero_velocity_update(estimator: ExternalForceEstimator, rest_s: float, settle_s: float,
                          cycle_s: float, samples: int) -> None:
    """Re-zero the estimator once the commanded motion has been at rest for ``settle_s``
    (in the first controller cycle past it); abandon the re-zero if the motion restarts."""
    if rest_s == 0.0:
        if estimator.rezeroing:
            estimator.cancel_rezero()
    elif settle_s <= rest_s < settle_s + cycle_s:
        estimator.rezero(samples)


def _transition(e: Event) -> SessionEvent:
    cause = e.cause.name if e.fault.name == "NONE" else f"{e.cause.name}:{e.fault.name}"
    return SessionEvent(t=e.t, kind="transition",
                        label=f"{e.from_state.name}->{e.to_state.name}", cause=cause)


def _sleep_until(deadline: float) -> None:
    remaining = deadline - time.perf_counter()
    if remaining > 0:
        time.sleep(remaining)


class _Buffers:
    """Preallocated session arrays."""

    def __init__(self, steps: int, n: int, with_truth: bool) -> None:
        self.time = np.zeros(steps)
        self.q = np.zeros((steps, n))
        self.current = np.zeros((steps, n))
        self.tau_ext = np.zeros((steps, n))
        self.wrench = np.zeros((steps, 6))
        self.q_cmd = np.zeros((steps, n))
        self.qd_cmd = np.zeros((steps, n))
        self.tcp = np.zeros((steps, 3))
        self.rot = np.zeros((steps, 3, 3))
        self.twist = np.zeros((steps, 6))
        self.state = np.zeros(steps, dtype=np.int64)
        self.fault = np.zeros(steps, dtype=np.int64)
        self.applied = np.zeros((steps, 6)) if with_truth else None

    def store(self, i: int, t: float, q: Array, current: Array, tau_ext: Array, wrench: Array,
              q_cmd: Array, qd_cmd: Array, transform: Array, twist: Array, state: int,
              fault: int, applied: Array | None) -> None:
        self.time[i] = t
        self.q[i] = q
        self.current[i] = current
        self.tau_ext[i] = tau_ext
        self.wrench[i] = wrench
        self.q_cmd[i] = q_cmd
        self.qd_cmd[i] = qd_cmd
        self.tcp[i] = transform[:3, 3]
        self.rot[i] = transform[:3, :3]
        self.twist[i] = twist
        self.state[i] = state
        self.fault[i] = fault
        if self.applied is not None and applied is not None:
            self.applied[i] = applied

    def to_log(self, robot: str, events: list[SessionEvent],
               settings: dict[str, object]) -> SessionLog:
        quat = Rotation.from_matrix(self.rot).as_quat()  # x, y, z, w
        return SessionLog(robot=robot, time=self.time, q=self.q, current=self.current,
                          tau_ext=self.tau_ext, wrench_base=self.wrench, q_cmd=self.q_cmd,
                          qd_cmd=self.qd_cmd, tcp_cmd_base=self.tcp, tcp_cmd_quat=quat,
                          twist_cmd_base=self.twist, state=self.state, fault=self.fault,
                          wrench_applied_base=self.applied, events=events, settings=settings)


#: One servo period at a time, the preallocated recording and the transition events of
#: :func:`run_session`, for a runner that drives the periods itself (the pendant's live
#: session, :mod:`leadthrough.pendant.backend`).
ServoPeriods = _Loop
SessionBuffers = _Buffers
transition_event = _transition
