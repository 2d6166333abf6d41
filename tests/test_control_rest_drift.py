"""The estimate's drift at rest (leadthrough.control.rest_drift): the controller on scripted
force estimates, the paper's law (no stop after letting go)."""

from __future__ import annotations

import numpy as np

from leadthrough.control import GuidingConfig, GuidingController, VirtualFrictionConfig
from leadthrough.control.safety_states import State
from leadthrough.robot import Robot
from test_control_guiding import DT, PAPER_LAW, Q_WORK, run

#: The estimator's 3 Hz low-pass time constant [s].
TAU = 1.0 / (2 * np.pi * 3.0)


def _config(drift_s: float = 1.5) -> GuidingConfig:
    return GuidingConfig(virtual_friction=VirtualFrictionConfig(mass=(100.0,) * 6),
                         drift_s=drift_s, hand_release=PAPER_LAW)


def _ramp(k_n: int, rate: float, start: int = 50) -> np.ndarray:
    """x: 0 N, then a ramp of ``rate`` [N/s] from cycle ``start`` (the drives' drift)."""
    w = np.zeros((k_n, 6))
    t = np.arange(k_n) * DT
    w[start:, 0] = rate * (t[start:] - t[start])
    return w


def test_a_drift_below_delta_per_drift_s_never_moves_the_tool(er20: Robot) -> None:
    """8 N/s for 10 s at rest (80 N, the issue-24 drift): the paper's law breaks away at δ =
    15 N, 1.9 s in; with the baseline the twist stays exactly 0, and a drift faster than
    δ/drift_s (20 N/s) still moves the tool."""
    w = _ramp(1050, 8.0)
    paper = run(GuidingController(er20, _config(drift_s=0.0)), Q_WORK, w, interpolate=False)
    first = int(np.argmax(paper.twist_base[:, 0] > 0.0))
    assert abs(first - (50 + 15.0 / 8.0 / DT)) <= 2
    tr = run(GuidingController(er20, _config()), Q_WORK, w, interpolate=False)
    assert np.all(tr.twist_base == 0.0) and np.all(tr.q == Q_WORK)
    fast = run(GuidingController(er20, _config()), Q_WORK, _ramp(1050, 20.0),
               interpolate=False)
    assert np.any(fast.twist_base[:, 0] > 0.0)


def test_a_grip_on_top_of_the_drift_moves_at_delta_over_it(er20: Robot) -> None:
    """After 5 s of 6 N/s drift (30 N, held), a hand grips with 20 N (a step through the 3 Hz
    filter): the tool moves, within the filter's time, though 20 N alone is far from 30 + 15."""
    w = _ramp(900, 6.0)
    w[550:, 0] = 30.0
    grip = 600
    w[grip:, 0] += 20.0 * (1.0 - np.exp(-np.arange(900 - grip) * DT / TAU))
    tr = run(GuidingController(er20, _config()), Q_WORK, w, interpolate=False)
    vx = tr.twist_base[:, 0]
    assert np.all(vx[:grip] == 0.0)
    assert 0 < int(np.argmax(vx[grip:] > 0.0)) * DT <= 4 * TAU


def test_letting_go_of_a_light_hold_moves_nothing(er20: Robot) -> None:
    """A hand rests with 12 N (< δ) for 3 s and lets go: the estimate returns to 0 quickly;
    whatever part of the hold the baseline took up, the tool stays exactly at rest (the
    baseline only ever holds it)."""
    w = np.zeros((600, 6))
    w[50:350, 0] = 12.0 * (1.0 - np.exp(-np.arange(300) * DT / TAU))
    w[350:, 0] = w[349, 0] * np.exp(-np.arange(250) * DT / TAU)
    tr = run(GuidingController(er20, _config()), Q_WORK, w, interpolate=False)
    assert np.all(tr.twist_base == 0.0)


def test_a_press_after_a_drift_while_released_moves_only_on_a_push(er20: Robot) -> None:
    """The enabling device released for 10 s while the estimate drifts at 8 N/s (to 80 N, the
    drives after a seam's release), then pressed with no hand: the tool stays exactly at rest
    (before, the baseline was 0 while not guiding and the law broke away at once). A hand that
    then grips with 30 N (a step through the 3 Hz filter) moves it within the filter's time.
    With the paper's law while guiding (no baseline), the drift that goes on after the press
    breaks away once it has added δ = 15 N, 15/8 s after the press, not at the press."""
    k_n, press, grip = 1600, 1050, 1300
    w = _ramp(k_n, 8.0)
    held = np.zeros(k_n, dtype=bool)
    held[1:50] = held[press:] = True
    w[grip:, 0] += 30.0 * (1.0 - np.exp(-np.arange(k_n - grip) * DT / TAU))
    tr = run(GuidingController(er20, _config()), Q_WORK, w, deadman=held, interpolate=False)
    vx = tr.twist_base[:, 0]
    assert tr.state[press] == State.GUIDING and tr.state[press - 1] == State.IDLE
    assert np.all(tr.twist_base[:grip] == 0.0) and np.all(tr.q[:grip] == Q_WORK)
    assert 0 < int(np.argmax(vx[grip:] > 0.0)) * DT <= 4 * TAU
    paper = run(GuidingController(er20, _config(drift_s=0.0)), Q_WORK, w, deadman=held,
                interpolate=False)
    first = int(np.argmax(paper.twist_base[:, 0] > 0.0))
    assert abs(first - (press + 15.0 / 8.0 / DT)) <= 6


def test_a_push_held_through_the_press_must_rise_by_delta(er20: Robot) -> None:
    """A hand that already pushes 40 N when the device is pressed (it gripped while
    released): no motion until it pushes δ = 15 N more; letting go then moves nothing (the law
    sees the smaller of w and w - b)."""
    k_n, press, more, off = 900, 300, 500, 700
    w = np.zeros((k_n, 6))
    w[50:, 0] = 40.0 * (1.0 - np.exp(-np.arange(k_n - 50) * DT / TAU))
    w[more:, 0] += 20.0 * (1.0 - np.exp(-np.arange(k_n - more) * DT / TAU))
    w[off:, 0] = w[off - 1, 0] * np.exp(-np.arange(k_n - off) * DT / TAU)
    held = np.zeros(k_n, dtype=bool)
    held[1:20] = held[press:] = True
    tr = run(GuidingController(er20, _config()), Q_WORK, w, deadman=held, interpolate=False)
    vx = tr.twist_base[:, 0]
    assert np.all(vx[:more] == 0.0)
    assert 0 < int(np.argmax(vx[more:] > 0.0)) * DT <= 4 * TAU
    stop = off + int(np.argmax(vx[off:] == 0.0))
    assert stop > off and np.all(tr.twist_base[stop:] == 0.0)
