"""Starting an emulated controller: :func:`serve` (blocking, for the CLI) and
:func:`start` (a background thread, for tests and scripts).

The CLI's ``leadthrough emulate {fanuc-j519,ur-rtde,kuka-rsi} --robot R --seed N [--port P]``
(:mod:`leadthrough.cli.emulate_cmd`) builds one with :func:`make_emulator` and runs it in its
own process.
"""

from __future__ import annotations

import threading
from pathlib import Path

from leadthrough.errors import SimulationError
from leadthrough.robot.description import Robot, load_robot
from leadthrough.sim.emulators.controller import EmulatedController, EmulatorReport
from leadthrough.sim.emulators.fanuc_j519 import FanucJ519Emulator
from leadthrough.sim.emulators.kuka_rsi import KukaRsiEmulator
from leadthrough.sim.emulators.scenario import EmulatorOptions
from leadthrough.sim.emulators.ur_rtde import UrRtdeEmulator

__all__ = ["DEFAULT_PORTS", "EMULATORS", "RunningEmulator", "make_emulator", "serve", "start"]

EMULATORS: dict[str, type[EmulatedController]] = {
    "fanuc-j519": FanucJ519Emulator,
    "ur-rtde": UrRtdeEmulator,
    "kuka-rsi": KukaRsiEmulator,
}
DEFAULT_PORTS = {"fanuc-j519": 60015, "ur-rtde": 30004, "kuka-rsi": 49152}
"""J519 and RTDE listen on these; the RSI emulator sends to this port (the shipped config's)."""


def make_emulator(kind: str, robot: Robot | str | Path, seed: int = 0, port: int | None = None,
                  options: EmulatorOptions | None = None) -> EmulatedController:
    """Build an emulator (sockets not yet open).

    Args:
        kind: ``fanuc-j519``, ``ur-rtde`` or ``kuka-rsi``.
        robot: A robot, or a built-in name / robot TOML path; 6 joints.
        seed: Seeds the simulated robot and the fault draws.
        port: Listening port (J519, RTDE) or destination port (RSI); None: the default.
        options: Shared settings.

    Raises:
        SimulationError: Unknown kind, or a robot without 6 joints.
    """
    if kind not in EMULATORS:
        raise SimulationError("unknown emulator", field="kind", value=kind,
                              expected="one of " + ", ".join(EMULATORS))
    rob = robot if isinstance(robot, Robot) else load_robot(robot)
    if rob.n != 6:
        raise SimulationError("the emulated protocols carry 6 joints", field="robot",
                              value=f"{rob.name} ({rob.n} joints)", expected="a 6-joint robot")
    opts = options if options is not None else EmulatorOptions()
    return EMULATORS[kind](rob, seed, opts, DEFAULT_PORTS[kind] if port is None else port)


def serve(kind: str, robot: Robot | str | Path, seed: int = 0, port: int | None = None,
          options: EmulatorOptions | None = None,
          stop_event: threading.Event | None = None) -> EmulatorReport:
    """Run an emulator in this thread until ``stop_event`` is set (or a fault closes it).

    Returns:
        The session report.
    """
    emulator = make_emulator(kind, robot, seed, port, options)
    emulator.open()
    return emulator.run(stop_event if stop_event is not None else threading.Event())


class RunningEmulator:
    """An emulator serving in a background thread; use as a context manager.

    Attributes:
        emulator: The emulator (its :meth:`~EmulatedController.report` is live).
    """

    def __init__(self, emulator: EmulatedController) -> None:
        self.emulator = emulator
        self._stop = threading.Event()
        self._report: EmulatorReport | None = None
        self._error: BaseException | None = None
        emulator.open()
        self._thread = threading.Thread(target=self._run, name=f"emulator-{emulator.kind}",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self._report = self.emulator.run(self._stop)
        except BaseException as e:  # surfaced by stop()
            self._error = e

    @property
    def port(self) -> int:
        """The port in use."""
        return self.emulator.port

    @property
    def alive(self) -> bool:
        """Whether the emulator still serves."""
        return self._thread.is_alive()

    def stop(self, timeout: float = 5.0) -> EmulatorReport:
        """End the session and return its report.

        Raises:
            SimulationError: The emulator thread failed (its exception is the cause).
        """
        self._stop.set()
        self._thread.join(timeout)
        if self._error is not None:
            raise SimulationError(f"the emulator failed: {self._error!r}",
                                  field="emulator", value=self.emulator.kind) from self._error
        return self._report if self._report is not None else self.emulator.report()

    def __enter__(self) -> RunningEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start(kind: str, robot: Robot | str | Path, seed: int = 0, port: int | None = 0,
          options: EmulatorOptions | None = None) -> RunningEmulator:
    """Start an emulator in a background thread (port 0: a free port, read ``.port``)."""
    return RunningEmulator(make_emulator(kind, robot, seed, port, options))
