"""Emulated robot controllers: the simulated robot behind the real controllers' wire protocols.

* ``fanuc-j519``: FANUC Stream Motion (J519), UDP server on port 60015
  (:class:`FanucJ519Emulator`);
* ``ur-rtde``: Universal Robots RTDE, TCP server on port 30004, with the behaviour of the
  shipped servo URScript program (:class:`UrRtdeEmulator`);
* ``kuka-rsi``: KUKA RSI, the robot side sending to the client's port 49152
  (:class:`KukaRsiEmulator`).

Each steps a :class:`~leadthrough.sim.robot.SimRobot` at 1 ms in real time behind its
controller cycle, with the controller's watchdog, limit checks, E-stop and protective stop,
digital inputs (:class:`InputSchedule`) and injectable faults (:class:`FaultPlan`); it logs
every command and :meth:`EmulatedController.report` confirms that nothing non-finite or beyond
the limits was executed. Run one with :func:`serve` (blocking), :func:`start` (background
thread) or the CLI's ``leadthrough emulate`` (its own process).
"""

from leadthrough.sim.emulators.arm import (
    ArmPhase,
    CommandRecord,
    EmulatedArm,
    MotionLimits,
    StopKind,
)
from leadthrough.sim.emulators.controller import EmulatedController, EmulatorReport
from leadthrough.sim.emulators.fanuc_j519 import FanucJ519Emulator
from leadthrough.sim.emulators.kuka_rsi import KukaRsiEmulator
from leadthrough.sim.emulators.runner import (
    DEFAULT_PORTS,
    EMULATORS,
    RunningEmulator,
    make_emulator,
    serve,
    start,
)
from leadthrough.sim.emulators.scenario import (
    INPUT_NAMES,
    EmulatorOptions,
    FaultPlan,
    InputSchedule,
    Window,
)
from leadthrough.sim.emulators.ur_rtde import UrRtdeEmulator

__all__ = [
    "DEFAULT_PORTS",
    "EMULATORS",
    "INPUT_NAMES",
    "ArmPhase",
    "CommandRecord",
    "EmulatedArm",
    "EmulatedController",
    "EmulatorOptions",
    "EmulatorReport",
    "FanucJ519Emulator",
    "FaultPlan",
    "InputSchedule",
    "KukaRsiEmulator",
    "MotionLimits",
    "RunningEmulator",
    "StopKind",
    "UrRtdeEmulator",
    "Window",
    "make_emulator",
    "serve",
    "start",
]
