"""The operator at an emulated robot: the script starts after the stream's first command, holds
the enabling device for its length, presses the mark button at its marks, and its push reaches
the client only through the reported currents."""

from __future__ import annotations

import numpy as np
import pytest

from leadthrough.drivers.controllers import connect
from leadthrough.errors import SimulationError
from leadthrough.robot import Robot
from leadthrough.sim.emulators import EmulatorOptions, start
from leadthrough.sim.emulators.operator import MARK_S, OperatorPlan
from wire_helpers import POSE


def _hold_and_log(robot: Robot, plan: OperatorPlan, seconds: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, object]:
    """Stream 'hold the start pose' to an emulated J519 with ``plan``'s operator; per fresh
    sample: controller time [s], enable and mark inputs, joint torque [N·m]."""
    emu = start("fanuc-j519", robot, seed=2, port=0,
                options=EmulatorOptions(q0=POSE, watchdog=0.5, operator=plan))
    driver = connect("fanuc-j519", robot, "127.0.0.1", emu.port)
    t, inputs, tau = [], [], []
    try:
        with driver:
            fb, cmd = driver.make_feedback(), driver.make_command()
            while not driver.read(fb):
                driver.step()
            cmd.q[:] = fb.q
            while not t or t[-1] < seconds:
                driver.write(cmd)
                driver.step()
                if driver.read(fb) and fb.inputs_read:
                    t.append(fb.t)
                    inputs.append(fb.inputs)
                    tau.append(robot.current_to_torque(fb.current))
            report = emu.emulator.report()
    finally:
        emu.stop()
    return np.array(t), np.array(inputs), np.array(tau), report


def test_the_operator_presses_pushes_and_marks(er20: Robot) -> None:
    plan = OperatorPlan("diagonal", delay_s=0.5)
    t, inputs, tau, report = _hold_and_log(er20, plan, 8.0)
    t0 = report.operator_start  # type: ignore[attr-defined]
    assert t0 is not None and 0.5 <= t0 - t[0] <= 0.6
    assert report.operator_end == pytest.approx(t0 + 6.5)  # type: ignore[attr-defined]
    enable, mark = (inputs & 1) > 0, (inputs & 2) > 0
    s = t - t0
    assert not enable[s < -0.01].any() and enable[(s > 0.01) & (s < 6.49)].all()
    assert not enable[s > 6.51].any()
    # the diagonal script marks P1 at 0.5 s and P2 at 5.5 s, each pressed for MARK_S
    pressed = s[mark]
    assert pressed.size > 0 and np.all(((pressed >= 0.5) & (pressed < 0.5 + MARK_S + 0.01))
                                       | ((pressed >= 5.5) & (pressed < 5.5 + MARK_S + 0.01)))
    # 40 N along (1, 1, 0)/√2 from 1 s to 4 s: the held robot's joint torques change by J^T F
    before = np.median(tau[(s > 0.2) & (s < 0.9)], axis=0)
    during = np.median(tau[(s > 2.0) & (s < 3.5)], axis=0)
    assert np.max(np.abs(during - before)) > 10.0  # N·m: 40 N at ~1 m


def test_a_bad_operator_plan_is_refused() -> None:
    with pytest.raises(SimulationError) as e:
        OperatorPlan("dance")
    assert e.value.field == "operator"
    with pytest.raises(SimulationError):
        OperatorPlan("push-x", delay_s=-1.0)
