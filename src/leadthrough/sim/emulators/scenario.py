"""What an emulated controller is told to do besides answering: its options, the digital
inputs it reports (enabling device, mark button) and the faults it injects.

Times are simulation times [s] since the emulator started (1 ms per simulator step); in real
time they are wall-clock seconds as long as the emulator keeps up.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from leadthrough.errors import SimulationError
from leadthrough.sim.emulators.operator import OperatorPlan

__all__ = ["INPUT_NAMES", "EmulatorOptions", "FaultPlan", "InputSchedule", "Window", "input_bits"]

INPUT_NAMES = ("enable", "mark", "reset")
"""Digital inputs the emulators report: the enabling device, the mark button and the fault
reset button (bits 0, 1, 2: J519 DI[1..3], UR DI0-2, KUKA $IN[1..3])."""


@dataclass(frozen=True)
class Window:
    """A time window ``start <= t < end`` [s]."""

    start: float
    end: float = math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and self.end > self.start):
            raise SimulationError("bad window", field="window", value=(self.start, self.end),
                                  expected="finite start < end [s]")

    def __contains__(self, t: float) -> bool:
        return self.start <= t < self.end


def _within(t: float, windows: tuple[Window, ...]) -> bool:
    return any(t in w for w in windows)


@dataclass(frozen=True)
class InputSchedule:
    """Digital inputs over time: each input is on inside its windows.

    Attributes:
        enable: Windows where the enabling device is held.
        mark: Windows where the mark button is pressed.
        reset: Windows where the fault reset button is pressed.
        callback: If given, called with the time [s] instead; returns {name: state} for the
            names of :data:`INPUT_NAMES` (missing names are off).
    """

    enable: tuple[Window, ...] = ()
    mark: tuple[Window, ...] = ()
    reset: tuple[Window, ...] = ()
    callback: Callable[[float], Mapping[str, bool]] | None = None

    def state(self, t: float) -> dict[str, bool]:
        """{input name: on} at time ``t`` [s]."""
        if self.callback is not None:
            got = self.callback(t)
            return {name: bool(got.get(name, False)) for name in INPUT_NAMES}
        return {name: _within(t, getattr(self, name)) for name in INPUT_NAMES}


def input_bits(state: Mapping[str, bool]) -> int:
    """The inputs as one word: bit k is the input ``INPUT_NAMES[k]`` (UR's DI0-2, KUKA's
    $IN[1..3])."""
    return sum(int(state[name]) << k for k, name in enumerate(INPUT_NAMES))


@dataclass(frozen=True)
class FaultPlan:
    """Faults the emulator injects.

    Attributes:
        loss_rate: Probability that an outgoing packet is dropped, 0..1 (independent draws).
        loss_bursts: Windows in which every outgoing packet is dropped (missing replies).
        late: Windows in which outgoing packets leave ``late_by`` late.
        late_by: Delay of late packets [s].
        close_at: Time at which the emulator closes its sockets (None: never).
        nan_q: Windows in which the reported joint positions are NaN.
        estop_at: Time of an emergency stop (None: never).
        protective_stop_at: Time of a protective stop (None: never).
    """

    loss_rate: float = 0.0
    loss_bursts: tuple[Window, ...] = ()
    late: tuple[Window, ...] = ()
    late_by: float = 0.0
    close_at: float | None = None
    nan_q: tuple[Window, ...] = ()
    estop_at: float | None = None
    protective_stop_at: float | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss_rate <= 1.0:
            raise SimulationError("out of range", field="faults.loss_rate",
                                  value=self.loss_rate, expected="0..1")
        if not (math.isfinite(self.late_by) and 0.0 <= self.late_by <= 1.0):
            raise SimulationError("out of range", field="faults.late_by", value=self.late_by,
                                  expected="0..1 s")

    def drop(self, t: float, rng: np.random.Generator) -> bool:
        """Whether the packet sent at ``t`` is lost."""
        if _within(t, self.loss_bursts):
            return True
        return self.loss_rate > 0.0 and bool(rng.random() < self.loss_rate)

    def delay(self, t: float) -> float:
        """How late the packet sent at ``t`` leaves [s]."""
        return self.late_by if _within(t, self.late) else 0.0

    def nan(self, t: float) -> bool:
        """Whether positions reported at ``t`` are NaN."""
        return _within(t, self.nan_q)


@dataclass(frozen=True)
class EmulatorOptions:
    """Settings shared by the emulated controllers.

    Attributes:
        host: Address to listen on (J519, RTDE) or to send to (RSI).
        cycle_ms: Controller cycle [ms]; None: the controller's default (J519 8, RTDE 2
            e-Series / 8 CB3, RSI 4).
        watchdog: Silence the controller tolerates before its controlled stop [s]; None:
            the controller's default (J519 3 cycles, RTDE the URScript timeout 0.05 s, RSI
            the context's Timeout in cycles).
        inputs: Digital inputs to report.
        faults: Faults to inject.
        realtime: Pace the 1 ms steps with the wall clock (False: as fast as possible,
            for scripted tests of the controller logic only).
        q0: Start pose [rad]; None: the robot's neutral pose.
        generation: RTDE only: ``"e-series"`` (500 Hz, version 5.x) or ``"cb3"`` (125 Hz,
            version 3.x).
        operator: A scripted operator at the robot (enabling device, pushes, marks; see
            :mod:`leadthrough.sim.emulators.operator`), or None.
    """

    host: str = "127.0.0.1"
    cycle_ms: int | None = None
    watchdog: float | None = None
    inputs: InputSchedule = field(default_factory=InputSchedule)
    faults: FaultPlan = field(default_factory=FaultPlan)
    realtime: bool = True
    q0: tuple[float, ...] | None = None
    generation: str = "e-series"
    operator: OperatorPlan | None = None

    def __post_init__(self) -> None:
        if self.cycle_ms is not None and self.cycle_ms not in (2, 4, 8, 12):
            raise SimulationError("unsupported cycle", field="cycle_ms", value=self.cycle_ms,
                                  expected="2, 4, 8 or 12 ms")
        if self.watchdog is not None and not (0.0 < self.watchdog <= 10.0):
            raise SimulationError("out of range", field="watchdog", value=self.watchdog,
                                  expected="0 < watchdog <= 10 s")
        if self.generation not in ("e-series", "cb3"):
            raise SimulationError("unknown generation", field="generation",
                                  value=self.generation, expected="e-series or cb3")
