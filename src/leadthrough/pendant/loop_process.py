"""The loop's process: the guiding loop, away from the pendant's interpreter.

The pendant's process starts this one (``multiprocessing``, *spawn*: a fresh interpreter, no
threads or locks inherited) with a :class:`LoopRecipe`, picklable settings from which this
process builds the driver and the loop's parts itself, and loads or compiles their Numba code
before it reports ready (with progress on the way). Then it runs
:class:`~leadthrough.session.loop.ServoPeriods` (driver, estimator, controller, interpolator)
open-ended, paced by the wall clock on a simulator and by the driver's ``step`` on a robot, and
shares nothing with the pendant but memory it writes without waiting
(:mod:`~leadthrough.pendant.shared_state`):

* **state out**: after every controller cycle, the snapshot (a sequence-locked record), every
  servo period its timing (a ring), every controller cycle a row of the recording (a ring);
* **requests in**: the pendant sends :mod:`~leadthrough.pendant.messages` requests through a
  pipe; at the start of each controller cycle, before the controller runs, this process takes
  what has arrived (``poll`` does not wait), so that a request takes effect at a cycle boundary
  and in the order sent. Refusals and results come back as notices in the snapshot. A
  malformed request is refused and counted, never raised; a snapshot whose slow part outgrows
  its record leaves out the oldest transitions (then marks) with a notice
  (:func:`~leadthrough.pendant.messages.fit_slow`); a lapsed lease on the enabling input is
  released here, every controller cycle.

If the pipe closes or the parent process is gone (checked every controller cycle), the loop
releases the enabling input, which the controller turns into a commanded stop, runs until the
robot is at rest, says so on standard error and exits.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.safety import State
from leadthrough.drivers.protocol import Driver
from leadthrough.errors import ControlError, LeadthroughError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.live_recording import LiveRecording
from leadthrough.pendant.loop_requests import RequestHandler
from leadthrough.pendant.messages import SlowState, fit_slow, numbers_size, snapshot_numbers
from leadthrough.pendant.shared_state import PeriodRing, SeqlockRecord, SharedBlock
from leadthrough.pendant.transitions import describe
from leadthrough.robot.description import Robot
from leadthrough.session.loop import ServoPeriods
from leadthrough.session.loop_config import LoopConfig, LoopParts, build_loop

__all__ = ["MAX_LAG_S", "DriverRecipe", "LoopProcessOptions", "LoopRecipe", "LoopSetup",
           "SharedNames", "run_loop_process"]

Array = NDArray[np.float64]

#: How far a simulated loop may fall behind the wall clock before it stops catching up [s].
MAX_LAG_S = 0.05


class LoopSetup(NamedTuple):
    """What a recipe builds in the loop's process.

    Attributes:
        driver: The robot (simulated or real).
        parts: Estimator, controller and interpolator (``build_loop``).
        settings: Recorded in the session file.
        applied_wrench: A simulator's truth, recorded for comparison; None for a robot.
        hand_force: The simulated hand's force now [N], shape (3,); None for a robot.
        simulator: Applies a :class:`~leadthrough.pendant.messages.SimulatorRequest` at loop
            time t [s] and returns a notice (or None); None for a robot.
    """

    driver: Driver
    parts: LoopParts
    settings: dict[str, object]
    applied_wrench: Callable[[], Array] | None = None
    hand_force: Callable[[], Array] | None = None
    simulator: Callable[[object, float], str | None] | None = None


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
    """A robot's driver and its loop (picklable: ``factory`` a module-level function).

    Attributes:
        robot: The robot.
        params: Its identified parameters.
        factory: Makes the driver from the robot and the controller's address.
        host: The controller's address.
    """

    robot: Robot
    params: ParamsFile
    factory: Callable[[Robot, str], Driver]
    host: str

    @property
    def with_truth(self) -> bool:
        """A robot has no truth to record."""
        return False

    def build(self) -> LoopSetup:
        """The driver (connected) and the loop's parts."""
        driver = self.factory(self.robot, self.host)
        parts = build_loop(self.robot, self.params, LoopConfig(), driver.dt)
        return LoopSetup(driver, parts, {"operator": "pendant", "host": self.host,
                                         "params_method": self.params.method})


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
    """The loop process's main: build, warm up, report ready, run until stopped."""
    blocks = [SharedBlock(name=n) for n in (names.record, names.periods, names.recording)]
    record = SeqlockRecord(blocks[0], numbers_size(names.n), names.blob_bytes)
    try:
        conn.send(("progress", "building the loop"))
        setup = recipe.build()
        conn.send(("progress", "loading the compiled code (Numba; compiles on first use)"))
        runner = _Runner(setup, names, blocks, record, conn, options)
        runner.start()
    except Exception as e:  # the pendant must learn why, not wait
        text = str(e) if isinstance(e, LeadthroughError) else f"{type(e).__name__}: {e}"
        conn.send(("error", text))
        return
    runner.run()


class _Runner:
    """The loop's periods, requests at cycle starts, and what it publishes."""

    def __init__(self, setup: LoopSetup, names: SharedNames, blocks: list[SharedBlock],
                 record: SeqlockRecord, conn: Connection, options: LoopProcessOptions) -> None:
        driver, parts = setup.driver, setup.parts
        every = round(parts.controller.config.dt / driver.dt)
        if every < 1 or abs(every * driver.dt - parts.controller.config.dt) > 1e-9:
            raise ControlError("controller cycle must be a multiple of the servo period",
                               field="controller.dt", value=parts.controller.config.dt,
                               expected=f"k × {driver.dt} s")
        self.setup, self.every, self.conn, self.record = setup, every, conn, record
        self.paced = driver.simulated if options.paced is None else options.paced
        self.rt_priority = options.rt_priority
        self.loop = ServoPeriods(driver, parts.estimator, parts.controller,
                                 parts.interpolator, every, lambda _t: self.requests.held,
                                 setup.applied_wrench)
        self.requests = RequestHandler(parts.controller, self.loop, setup.simulator)
        self.periods = PeriodRing(blocks[1], names.timing_window)
        self.recording = LiveRecording(names.cycles, names.n, names.with_truth, blocks[2])
        self._numbers = np.zeros(numbers_size(names.n))
        self._no_push = np.zeros(3)
        self._event_count = -1
        self._cause = ""
        self.blob_bytes = names.blob_bytes
        self._left_out: str | None = None
        self._ppid = os.getppid()
        self.t_start = 0.0

    def start(self) -> None:
        """Scheduling, the first sample, warm-up, the first snapshot; then report ready."""
        self._schedule()
        self.t_start = self.loop.start()
        self._publish(self.t_start)
        self.conn.send(("ready", self.setup.settings, self.every))

    def run(self) -> None:
        """The periods until stopped (and at rest), then the last snapshot."""
        error = "stopped"
        try:
            self._periods()
        except LeadthroughError as e:
            error = str(e)
        except Exception as e:  # the loop must report, not vanish
            error = f"{type(e).__name__}: {e}"
        handler = self.requests
        if handler.lost is not None:
            c_out = self.loop.c_out
            print(f"leadthrough loop: {handler.lost}: commanded stop; "
                  f"{State(int(c_out.state)).name} "
                  f"at rest at {self.loop.fb.t:.3f} s, loop ended", file=sys.stderr, flush=True)
        self._publish(self.loop.fb.t, error)

    def _schedule(self) -> None:
        """Real-time scheduling of this process, if asked for (see ``rt_priority``)."""
        if self.rt_priority is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.rt_priority))
        except (AttributeError, OSError, ValueError) as e:
            self.requests.notice("warning", f"no real-time priority for the loop ({e}); it "
                                            "runs with ordinary scheduling")
        else:
            self.requests.notice("info", f"the loop runs under SCHED_FIFO, priority "
                                         f"{self.rt_priority}")

    def _periods(self) -> None:
        """The loop: periods until stopped (and then at rest), requests at cycle starts."""
        loop, dt, every, handler = self.loop, self.setup.driver.dt, self.every, self.requests
        t_start, periods = self.t_start, self.periods
        wall0 = time.perf_counter()
        i = 0
        while not (handler.stopping and self._at_rest()):
            t_loop = t_start + (i + 1) * dt
            deadline = None
            if self.paced:
                deadline = wall0 + (i + 1) * dt
                if time.perf_counter() - deadline > MAX_LAG_S:   # fell behind: no catching up
                    wall0 = time.perf_counter() - (i + 1) * dt
                    deadline = wall0 + (i + 1) * dt
            cycle = i % every == 0
            if cycle:
                handler.take(self.conn, t_loop)
                if os.getppid() != self._ppid:
                    handler.lose("the pendant's process ended")
            work = loop.period(i, t_loop, deadline)
            done = np.nan if deadline is None else (time.perf_counter() - deadline) * 1e6
            periods.store(i, work, done)
            if cycle:
                applied = self.setup.applied_wrench
                self.recording.store(t_loop, loop.fb, loop.cmd, loop.e_out, loop.c_out,
                                     applied() if applied is not None else None)
                self._publish(t_loop)
            i += 1

    def _at_rest(self) -> bool:
        c_out = self.loop.c_out
        return c_out.state in (State.IDLE, State.FAULT) and not c_out.twist_base.any()

    def _publish(self, t: float, error: str | None = None) -> None:
        """Write this cycle's snapshot (its slow part only if something in it changed)."""
        loop, ctl, handler = self.loop, self.setup.parts.controller, self.requests
        if ctl.event_count != self._event_count:
            self._event_count = ctl.event_count
            self._cause = describe(ctl.last_event)
            handler.changed = True
        c_out, e_out = loop.c_out, loop.e_out
        push = self.setup.hand_force() if self.setup.hand_force is not None else self._no_push
        snapshot_numbers(self._numbers, t, loop.fb.q, c_out.transform_tool_to_base,
                         e_out.wrench, c_out.twist_base,
                         (int(c_out.state), int(c_out.fault), int(e_out.status), handler.held),
                         push)
        blob = None
        if handler.changed or error is not None:
            handler.changed = False
            blob, left_out = fit_slow(
                SlowState(self._cause, ctl.config, handler.marks, tuple(handler.notices),
                          tuple(ctl.events), error, handler.refused, handler.lapsed),
                self.blob_bytes)
            if left_out is not None and left_out != self._left_out:
                self._left_out = left_out
                handler.notice("warning", left_out)      # in the next cycle's snapshot
        self.record.write(self._numbers, blob)
