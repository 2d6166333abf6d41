"""The person at an emulated robot: a scripted operator (``push-x``, ``seam``, ``random``, ...,
:mod:`leadthrough.sim.operator_scripts`) who presses the controller's enabling device, pushes the
tool and presses the mark button, as in the in-process guiding sessions.

The emulator cannot know when its client is ready to guide, so the operator's script runs on a
clock of its own: it starts ``delay_s`` after the stream's first accepted command (the client's
estimator tares and settles meanwhile); from then on the operator holds the enabling device for
the script's whole length (a fresh press), applies the script's wrench at the tool (into the
simulated plant: the client sees it only through the currents or joint torques it receives),
presses the mark button for ``MARK_S`` at each of the script's marks, and at the end releases
the enabling device. The seam operator's line starts where the tool is when the script starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import SimulationError
from leadthrough.sim.operator import ScriptedOperator
from leadthrough.sim.operator_scripts import OPERATOR_NAMES, make_operator

__all__ = ["MARK_S", "EmulatedOperator", "OperatorPlan"]

Array = NDArray[np.float64]

#: How long the emulated operator holds the mark button [s] (several controller cycles).
MARK_S = 0.1


@dataclass(frozen=True)
class OperatorPlan:
    """Which operator stands at the emulated robot.

    Attributes:
        name: Script name (one of :data:`~leadthrough.sim.operator_scripts.OPERATOR_NAMES`).
        seed: Seed of the script's random pushes (``random``), >= 0.
        delay_s: Time from the stream's first accepted command to the script's start [s].
    """

    name: str
    seed: int = 0
    delay_s: float = 3.0

    def __post_init__(self) -> None:
        if self.name not in OPERATOR_NAMES:
            raise SimulationError("unknown operator script", field="operator", value=self.name,
                                  expected="one of " + ", ".join(OPERATOR_NAMES))
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise SimulationError("bad seed", field="operator_seed", value=self.seed,
                                  expected="an integer >= 0")
        if not (math.isfinite(self.delay_s) and 0.0 <= self.delay_s <= 600.0):
            raise SimulationError("out of range", field="operator_delay", value=self.delay_s,
                                  expected="0 <= delay <= 600 s")


class EmulatedOperator:
    """The operator of a plan, on the emulator's clock (an
    :class:`~leadthrough.sim.operator.Operator` for the simulated robot).

    Args:
        plan: The script and its start.
    """

    def __init__(self, plan: OperatorPlan) -> None:
        self.plan = plan
        self.script: ScriptedOperator | None = None
        self.t0: float | None = None   # simulation time the script started [s]
        self._stream_t: float | None = None

    def stream_started(self, t: float) -> None:
        """The stream's first command was accepted at simulation time ``t`` [s]."""
        if self._stream_t is None:
            self._stream_t = t

    def due(self, t: float) -> bool:
        """Whether the script should start now (once)."""
        return (self.t0 is None and self._stream_t is not None
                and t >= self._stream_t + self.plan.delay_s)

    def start(self, t: float, tcp_position_base: Array) -> None:
        """Start the script at simulation time ``t`` [s], the tool at ``tcp_position_base`` [m]."""
        self.script = make_operator(self.plan.name, seed=self.plan.seed,
                                    tcp_start_base=tcp_position_base)
        self.t0 = t

    def wrench(self, t: float, tcp_position_base: Array) -> Array:
        """The script's wrench at the tool [N, N·m], base frame, shape (6,)."""
        if self.script is None or self.t0 is None or t < self.t0:
            return np.zeros(6)
        return self.script.wrench(t - self.t0, tcp_position_base)

    def inputs(self, t: float) -> dict[str, bool]:
        """The enabling device and the mark button at simulation time ``t`` [s]."""
        if self.script is None or self.t0 is None:
            return {"enable": False, "mark": False}
        s = t - self.t0
        enable = 0.0 <= s < self.script.duration_s
        mark = any(m.t <= s < m.t + MARK_S for m in self.script.marks)
        return {"enable": enable, "mark": mark}

    @property
    def finished_at(self) -> float | None:
        """Simulation time at which the script ends [s] (None before it started)."""
        if self.script is None or self.t0 is None:
            return None
        return self.t0 + self.script.duration_s
