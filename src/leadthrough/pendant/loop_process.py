"""The loop's process: the guiding loop, away from the pendant's interpreter.

The pendant's process starts this one (``multiprocessing``, *spawn*: a fresh interpreter, no
threads or locks inherited) with a :class:`LoopRecipe`, picklable settings from which this
process builds the driver and the loop's parts itself, and loads or compiles their Numba code
before it reports ready (with progress on the way). Then it runs the one guiding loop,
:func:`leadthrough.session.loop.run` on a :class:`~leadthrough.session.servo_loop.ServoLoop`,
with the same start, pacing, real-time set-up, watchdog, faults (driver, stale feedback, the
controller's state) and ways out as ``leadthrough guide``: a simulator paced by the wall clock,
a robot by its driver's ``step``. It shares nothing with the pendant but memory it writes
without waiting (:mod:`~leadthrough.pendant.shared_state`):

* **state out**: after every controller cycle, the snapshot (a sequence-locked record), every
  servo period its timing (a ring), every controller cycle a row of the recording (a ring);
* **requests in**: the pendant sends the loop's own requests
  (:mod:`leadthrough.session.requests`) through a pipe, which the loop reads every period
  without waiting (:class:`~leadthrough.session.requests.PipeRequests`) and serves in the
  order sent (:meth:`ServoLoop.serve <leadthrough.session.servo_loop.ServoLoop.serve>`).
  Refusals and results come back as notices in the snapshot. A malformed request is refused
  and counted, never raised; a snapshot whose slow part outgrows its record leaves out the
  oldest transitions (then marks) with a notice
  (:func:`~leadthrough.pendant.messages.fit_slow`); a lapsed lease on the enabling device is
  released by the loop itself, on its own clock.

If the pipe closes or the parent process is gone, the loop releases the enabling device,
which the controller turns into a commanded stop, runs until the robot is at rest, says so on
standard error and exits; on a real controller the driver's stop then ends the stream, as at
the end of every session.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from multiprocessing.connection import Connection
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingConfig
from leadthrough.control.safety import State
from leadthrough.drivers.controllers import connect
from leadthrough.drivers.protocol import Driver
from leadthrough.errors import LeadthroughError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.live_recording import LiveRecording
from leadthrough.pendant.messages import SlowState, fit_slow, numbers_size, snapshot_numbers
from leadthrough.pendant.shared_state import PeriodRing, SeqlockRecord, SharedBlock
from leadthrough.pendant.transitions import describe
from leadthrough.robot.description import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import check_setup, run
from leadthrough.session.loop_config import (
    LoopConfig,
    LoopOptions,
    LoopParts,
    build_loop,
    controller_cycle,
    warm_up_parts,
)
from leadthrough.session.loop_end import EndCause
from leadthrough.session.pacing import PeriodClock
from leadthrough.session.requests import PipeRequests
from leadthrough.session.servo_loop import ServoLoop, Simulator

__all__ = ["DriverRecipe", "LoopProcessOptions", "LoopRecipe", "LoopSetup", "SharedNames",
           "run_loop_process"]

Array = NDArray[np.float64]


class LoopSetup(NamedTuple):
    """What a recipe builds in the loop's process.

    Attributes:
        driver: The robot (simulated or real).
        parts: Estimator, controller and interpolator (``build_loop``).
        settings: Recorded in the session file.
        applied_wrench: A simulator's truth, recorded for comparison; None for a robot.
        hand_force: The simulated hand's force now [N], shape (3,); None for a robot.
        simulator: Applies a :class:`~leadthrough.session.requests.SimulatorRequest` at loop
            time t [s] and returns a notice (or None); None for a robot.
        options: How the loop meets the driver and the operator (the controller's enabling,
            mark and reset inputs, the watchdog); the pendant's process sets the real-time
            set-up and, on a simulator, the pacing.
    """

    driver: Driver
    parts: LoopParts
    settings: dict[str, object]
    applied_wrench: Callable[[], Array] | None = None
    hand_force: Callable[[], Array] | None = None
    simulator: Simulator | None = None
    options: LoopOptions = LoopOptions()


class LoopRecipe(Protocol):
    """Picklable settings from which the loop's process builds its loop."""

    @property
    def with_truth(self) -> bool:
        """Whether the setup records a simulator's truth (``applied_wrench``)."""
        ...

    def build(self) -> LoopSetup:
        """Build the driver and the loop's parts (in the loop's process)."""
        ...


@dataclass(frozen=True)
class DriverRecipe:
    """A real controller and its loop, as ``leadthrough guide --driver`` builds them
    (picklable).

    Attributes:
        robot: The robot.
        params: Its identified parameters (ready to guide: with the friction sweep).
        driver: The controller interface (``fanuc-j519``, ``ur-rtde``, ``kuka-rsi``:
            :data:`~leadthrough.drivers.controllers.CONTROLLERS`).
        host: The controller's address (RSI: the address to listen on).
        port: The interface's port (None: its own).
        robot_address: RSI only: the robot's ``HOST[:PORT]`` (None: the first sender).
        options: The controller's enabling, mark and reset inputs, the watchdog.
        guiding: The controller's settings (its cycle set from the controller's:
            :func:`~leadthrough.session.loop_config.controller_cycle`).
    """

    robot: Robot
    params: ParamsFile
    driver: str
    host: str
    port: int | None = None
    robot_address: str | None = None
    options: LoopOptions = field(default_factory=LoopOptions)
    guiding: GuidingConfig = field(default_factory=GuidingConfig)

    @property
    def with_truth(self) -> bool:
        """A robot has no truth to record."""
        return False

    def build(self) -> LoopSetup:
        """The loop's parts, their compiled code loaded, then the driver opened (the
        controller streams from the open on: nothing slow is left between it and the loop's
        start)."""
        driver = connect(self.driver, self.robot, self.host, self.port, self.robot_address)
        parts = self._parts(driver.dt)
        dt = driver.dt
        driver.open()
        try:
            if driver.dt != dt:    # the cycle the controller reported at open (UR CB3: 8 ms)
                parts = self._parts(driver.dt)
        except BaseException:
            driver.close()
            raise
        settings: dict[str, object] = {
            "operator": "pendant", "driver": self.driver, "host": self.host,
            "port": self.port, "params_method": self.params.method,
            "enable_input": self.options.enable_input, "mark_input": self.options.mark_input,
            "reset_input": self.options.reset_input}
        return LoopSetup(driver, parts, settings, options=self.options)

    def _parts(self, dt: float) -> LoopParts:
        parts = build_loop(self.robot, self.params, LoopConfig(guiding=replace(
            self.guiding, dt=controller_cycle(dt))), dt)
        warm_up_parts(parts, guide_start_pose(self.robot))
        return parts


@dataclass(frozen=True)
class SharedNames:
    """The shared memory blocks, by name, and their shapes."""

    record: str
    periods: str
    recording: str
    n: int
    blob_bytes: int
    timing_window: int
    cycles: int
    with_truth: bool


@dataclass(frozen=True)
class LoopProcessOptions:
    """How the loop runs: ``paced`` (None: when the driver is simulated) and ``rt_priority``
    (SCHED_FIFO priority, None: ordinary scheduling); see
    :class:`~leadthrough.pendant.backend.LiveSession`."""

    paced: bool | None = None
    rt_priority: int | None = None


def run_loop_process(recipe: LoopRecipe, names: SharedNames, conn: Connection,
                     options: LoopProcessOptions) -> None:
    """The loop process's main: build, start (warm up), report ready, run until it ends."""
    blocks = [SharedBlock(name=n) for n in (names.record, names.periods, names.recording)]
    record = SeqlockRecord(blocks[0], numbers_size(names.n), names.blob_bytes)
    try:
        conn.send(("progress", "building the loop"))
        setup = recipe.build()
        conn.send(("progress", "loading the compiled code (Numba; compiles on first use)"))
        publisher = _Publisher(setup, names, blocks, record, conn, options)
    except Exception as e:  # the pendant must learn why, not wait
        conn.send(("error", _text(e)))
        return
    publisher.run()


def _text(e: BaseException) -> str:
    return str(e) if isinstance(e, LeadthroughError) else f"{type(e).__name__}: {e}"


class _Publisher:
    """The loop (:func:`leadthrough.session.loop.run`) and what it publishes each period."""

    def __init__(self, setup: LoopSetup, names: SharedNames, blocks: list[SharedBlock],
                 record: SeqlockRecord, conn: Connection, options: LoopProcessOptions) -> None:
        driver, parts = setup.driver, setup.parts
        paced = driver.simulated if options.paced is None else options.paced
        realtime = (setup.options.realtime if options.rt_priority is None else
                    replace(setup.options.realtime, priority=options.rt_priority))
        loop_options = replace(setup.options, paced=paced, realtime=realtime)
        requests = PipeRequests(conn, os.getppid())
        self.every = check_setup(driver, parts.estimator, parts.controller, None, loop_options,
                                 requests, None)
        self.setup, self.conn, self.record = setup, conn, record
        self.loop = ServoLoop(driver, parts.estimator, parts.controller, parts.interpolator,
                              self.every, loop_options, requests, None, setup.simulator)
        self.pacing = PeriodClock(driver.dt, paced, real_time=not driver.simulated,
                                  clock=self.loop.clock)
        self.periods = PeriodRing(blocks[1], names.timing_window)
        self.recording = LiveRecording(names.cycles, names.n, names.with_truth, blocks[2])
        self._numbers = np.zeros(numbers_size(names.n))
        self._no_push = np.zeros(3)
        self._event_count = -1
        self._cause = ""
        self.blob_bytes = names.blob_bytes
        self._left_out: str | None = None
        self._ready = False             # the loop has started and said so

    def run(self) -> None:
        """The loop until it ends (and at rest), then the last snapshot."""
        loop, error = self.loop, "stopped"
        try:
            run(loop, self.pacing, observe=self._period, started=self._started)
        except Exception as e:  # the loop must report, not vanish
            error = _text(e)
            if not self._ready:         # it failed to start: the pendant must learn why
                self.conn.send(("error", error))
                return
        end = loop.end
        if end is not None and end.cause is EndCause.OPERATOR_LOST:
            print(f"leadthrough loop: {loop.operator_lost}: commanded stop; "
                  f"{State(int(loop.c_out.state)).name} "
                  f"at rest at {loop.fb.t:.3f} s, loop ended", file=sys.stderr, flush=True)
        elif end is not None and end.cause is not EndCause.STOP_REQUESTED:
            error = f"{end.cause}: {end.detail}" if end.detail else str(end.cause)
        self._publish(loop.t if np.isfinite(loop.t) else loop.fb.t, error)

    def _started(self, t_start: float) -> None:
        """The loop has started: the first snapshot, then ready."""
        self._publish(t_start)
        self._ready = True
        self.conn.send(("ready", self.setup.settings, self.every))

    def _period(self, i: int, work_us: float) -> None:
        """After servo period ``i``: its timing; every controller cycle a row of the recording
        and the snapshot."""
        pacing = self.pacing
        done = ((pacing.clock.now() - pacing.next_start) * 1e6 if pacing.paced else np.nan)
        self.periods.store(i, work_us, done)
        if i % self.every == 0:
            loop, applied = self.loop, self.setup.applied_wrench
            self.recording.store(loop.t, loop.fb, loop.cmd, loop.e_out, loop.c_out,
                                 applied() if applied is not None else None)
            self._publish(loop.t)

    def _publish(self, t: float, error: str | None = None) -> None:
        """Write this cycle's snapshot (its slow part only if something in it changed)."""
        loop, ctl = self.loop, self.setup.parts.controller
        if ctl.event_count != self._event_count:
            self._event_count = ctl.event_count
            self._cause = describe(ctl.last_event)
            loop.changed = True
        c_out, e_out = loop.c_out, loop.e_out
        push = self.setup.hand_force() if self.setup.hand_force is not None else self._no_push
        snapshot_numbers(self._numbers, t, loop.fb.q, c_out.transform_tool_to_base,
                         e_out.wrench, c_out.twist_base,
                         # the controller's own state: a trip outside the cycle (a lost link
                         # ends the loop before another cycle) is not in c_out yet
                         (int(ctl.state), int(ctl.fault), int(e_out.status), loop.held),
                         push)
        blob = None
        if loop.changed or error is not None:
            loop.changed = False
            blob, left_out = fit_slow(
                SlowState(self._cause, ctl.config, loop.marks, tuple(loop.notices),
                          tuple(ctl.events), error, loop.refused, loop.lapsed),
                self.blob_bytes)
            if left_out is not None and left_out != self._left_out:
                self._left_out = left_out
                loop.notice("warning", left_out)      # in the next cycle's snapshot
        self.record.write(self._numbers, blob)
