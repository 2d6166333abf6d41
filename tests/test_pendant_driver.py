"""The pendant's live session on a real controller's wire protocol: a
:class:`~leadthrough.pendant.backend.LiveSession` on a
:class:`~leadthrough.pendant.loop_process.DriverRecipe` (the loop ``leadthrough pendant --driver``
runs), against ``leadthrough emulate D --operator diagonal`` in its own process, for each of the
three protocols over loopback; no browser (the page is ``test_pendant_browser.py``'s).

The emulated operator presses the controller's enabling input (input 0) from
``--operator-delay`` after the stream's first command for the script's 6.5 s, pushes the tool
with 40 N along (1, 1, 0)/√2 from 1 s to 4 s into it, and presses the mark button (input 1) at
0.5 s and 5.5 s. Checked through the snapshots: the loop starts IDLE; GUIDING only once the
input is pressed, within a few cycles of the operator's press (a fresh press: none before it);
the tool moves along the push; the marks arrive as P1, P2 at the button's presses. Then a fault
of the protocol's own (J519: NaN joint positions in a status, UR: an emergency stop, RSI: the
robot gone, its process killed) shows as FAULT with the fault in the snapshot's cause and a
notice naming it, the commanded motion comes to rest, and stopping the session is the
commanded stop and the driver's stop of the stream, said in the last snapshot's notices.

The emulator's injected faults are timed on its own clock from its start; the loop starts
after its process has loaded its compiled code, which on a loaded machine takes seconds more
or less: an attempt whose fault came before the operator's press and push is run once more.
"""

from __future__ import annotations

import math
import subprocess
import time
from dataclasses import dataclass, field

import numpy as np
import pytest

from leadthrough.control.safety import Fault, State
from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.identification.params_file import load_params
from leadthrough.pendant.backend import LiveSession, LoopSnapshot
from leadthrough.pendant.loop_process import DriverRecipe
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop_config import LoopOptions
from leadthrough.session_format import SessionLog
from leadthrough.sim.emulators.kuka_rsi import IPOC_START
from leadthrough.sim.emulators.process import emulator_report
from leadthrough.sim.guiding_params import shipped_params_path
from wire_helpers import free_loopback_address, spawn_emulator, stop_process

#: The emulator's fault [s of its clock since its start]: after the press and the push on any
#: start the machine's load allows (the loop starts 2-10 s after the emulator).
AT = 15.0
#: The operator's start after the stream's first command [s]: the estimator warms up and
#: tares on 1 s of samples first (RSI: 1 s of its 4 ms cycle's samples takes 3 s of the
#: emulator's 12 ms one: see tests/test_guide_driver.py).
DELAY = {"fanuc-j519": 1.5, "ur-rtde": 1.5, "kuka-rsi": 4.0}
#: The diagonal script's push direction (base frame), its marks [s into the script].
PUSH = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
MARKS_AT = (0.5, 5.5)
#: An input change reaches the next packet, is read with the sample after it and acted on at
#: the next controller cycle (8, 10, 12 ms): within a few of the slowest cycles [s].
SLACK = 0.05

#: Each protocol's fault: the emulator's options (None: its process killed after P2), the
#: faults it may latch, and the text a notice or the cause names it by.
FAULTS: dict[str, tuple[list[str] | None, tuple[Fault, ...], tuple[str, ...]]] = {
    "fanuc-j519": (["--nan", f"{AT}:{AT + 0.01}"], (Fault.NONFINITE_INPUT,),
                   ("NONFINITE_INPUT",)),
    "ur-rtde": (["--estop-at", str(AT)], (Fault.CONTROLLER_STATE,),
                ("controller state: ESTOP",)),
    # UDP: a robot gone is silence (stale feedback) or the kernel's "port unreachable" on
    # the next read (a driver error)
    "kuka-rsi": (None, (Fault.STALE_FEEDBACK, Fault.DRIVER_ERROR),
                 ("stale feedback", "driver error", "link lost")),
}


@dataclass
class Watched:
    """What the snapshots showed during one session, on the emulator's clock [s]."""

    first: LoopSnapshot
    trace: list[tuple[float, State, bool, int]] = field(default_factory=list)
    faulted: LoopSnapshot | None = None
    at_rest: LoopSnapshot | None = None
    last: LoopSnapshot | None = None
    report: dict[str, str] = field(default_factory=dict)
    killed: str | None = None
    log: SessionLog | None = None
    #: When the fault was injected (the emulator's clock; the robot's process killed: then).
    injected: float = AT
    #: The loop's clock less the emulator's [s] (RSI's IPOC counts from IPOC_START ms).
    offset: float = 0.0

    def clock(self, t: float) -> float:
        """Loop time ``t`` on the emulator's clock [s]."""
        return t - self.offset


def _session(kind: str, robot: Robot) -> Watched:
    """One session against a fresh emulator, watched until the fault's stop is at rest, then
    stopped."""
    port = DEFAULT_PORTS[kind]
    host = free_loopback_address(port)
    emu_faults = FAULTS[kind][0]
    args = ["--seed", "1", "--q0", *map(str, guide_start_pose(robot)), "--operator",
            "diagonal", "--operator-delay", str(DELAY[kind]), *(emu_faults or [])]
    args += ["--cycle-ms", "12"] if kind == "kuka-rsi" else ["--watchdog", "0.5"]
    recipe = DriverRecipe(robot, load_params(shipped_params_path("er20"), robot), kind, host,
                          options=LoopOptions(enable_input=0, mark_input=1, watchdog_s=0.5,
                                              abort_s=1.0))
    live = LiveSession(recipe, robot, record_s=30.0)
    procs: list[subprocess.Popen[str]] = []
    watched: Watched | None = None

    def progress(step: str) -> None:     # RSI: the PC listens, the robot sends to it
        if kind == "kuka-rsi" and not procs and step.startswith("building"):
            procs.append(spawn_emulator(kind, "er20", host, port, *args, wait=False))

    if kind != "kuka-rsi":
        procs.append(spawn_emulator(kind, "er20", host, port, *args))
    try:
        live.start(timeout_s=120.0, progress=progress)
        first = live.snapshot()
        assert first is not None
        watched = Watched(first, offset=IPOC_START * 1e-3 if kind == "kuka-rsi" else 0.0)
        _watch(live, watched, procs[0] if emu_faults is None else None)
        live.stop(timeout_s=20.0)
        watched.last = live.snapshot()
        watched.log = live.session_log(())   # every controller cycle (the snapshots: polled)
    finally:
        live.close()
        text = (watched.killed if watched is not None and watched.killed is not None
                else stop_process(procs[0]) if procs else "")
    watched.report = emulator_report(text)
    return watched


def _watch(live: LiveSession, w: Watched, kill: subprocess.Popen[str] | None) -> None:
    """Poll the snapshots (wall-clock deadline 90 s) until the fault's stop is at rest;
    ``kill``: the emulator's process, killed once P2 is marked."""
    deadline = time.monotonic() + 90.0
    seen = -1.0
    while time.monotonic() < deadline:
        snap = live.snapshot()
        assert snap is not None
        if snap.error is not None:
            pytest.fail(f"the loop stopped: {snap.error}; {[n.text for n in snap.notices]}")
        if snap.time != seen:
            seen = snap.time
            t = w.clock(snap.time)
            w.trace.append((t, snap.state, snap.enabled, len(snap.marks)))
            if snap.state == State.FAULT and w.faulted is None:
                w.faulted = snap
            if w.faulted is not None and snap.speed == 0.0 and snap.state == State.FAULT:
                w.at_rest = snap
                return
            if kill is not None and len(snap.marks) >= 2:
                w.injected = t
                w.killed, kill = stop_process(kill), None
        time.sleep(0.02)       # (the machine's two cores are the loop's and the emulator's)
    pytest.fail(f"no fault at rest within 90 s: last {w.trace[-1:]}")


#: Faults a loaded machine causes on its own (a stalled emulator or loop: no sample in time,
#: a late answer refused, a slow exchange), as a real controller's link can.
LOAD_FAULTS = (Fault.STALE_FEEDBACK, Fault.CONTROLLER_STATE, Fault.DRIVER_TIMEOUT)


def _spoilt(w: Watched) -> str | None:
    """Why the machine's load spoilt this attempt, if it did: a fault of the load's
    (:data:`LOAD_FAULTS`) before the injected one, or the loop started so late that the
    injected fault came before the press and the push. None: the attempt counts (any other
    early fault fails the test)."""
    if w.faulted is None:
        return None
    t_fault = w.clock(w.faulted.time)
    if t_fault < w.injected - SLACK:
        return (f"{w.faulted.fault.name} at {t_fault:.3f} s, before the injection" if
                w.faulted.fault in LOAD_FAULTS else None)
    guided = [t for t, state, _, _ in w.trace if state == State.GUIDING and t < t_fault]
    if not guided or guided[-1] - guided[0] < 3.5:
        return f"the injected fault at {t_fault:.3f} s came before the press and the push"
    return None


@pytest.mark.parametrize("kind", list(FAULTS))
def test_the_pendant_guides_a_controller_and_stops_on_its_fault(kind: str, er20: Robot
                                                                ) -> None:
    spoilt = []
    for _ in range(3):       # up to three attempts for one not spoilt by the machine's load
        w = _session(kind, er20)
        why = _spoilt(w)
        if why is None:
            break
        spoilt.append(why)
    trace = [(round(t, 3), s.name, e, m) for t, s, e, m in w.trace]
    assert why is None, (spoilt, trace[:2], trace[-2:], None if w.faulted is None else (
        w.faulted.cause, [n.text for n in w.faulted.notices]))
    # the loop starts IDLE, the enabling input released
    assert w.first.state == State.IDLE and not w.first.enabled, w.first
    # GUIDING only while the controller's input is pressed (each snapshot), and first at the
    # operator's press (every controller cycle of the recording): a fresh press, the script
    # presses once the loop has started; not before it
    assert all(e for _, s, e, _ in w.trace if s == State.GUIDING), trace
    t_press = float(w.report["operator_start"])
    log = w.log
    assert log is not None
    t_log = log.time - w.offset
    guiding = log.state == int(State.GUIDING)
    assert guiding.any() and not guiding[t_log < t_press].any(), t_press
    first_guiding = float(t_log[np.argmax(guiding)])
    assert t_press <= first_guiding <= t_press + SLACK, (t_press, first_guiding)
    assert next(t for t, _, e, _ in w.trace if e) >= t_press - SLACK, (t_press, trace)
    # the tool follows the push (along it, not across), before the fault
    t_fault = w.clock(w.faulted.time) if w.faulted is not None else math.inf
    before = (t_log >= first_guiding) & (t_log < t_fault)
    moved = log.tcp_cmd_base[before] - log.tcp_cmd_base[before][0]
    far = moved[np.argmax(moved @ PUSH)]
    along = float(far @ PUSH)
    assert along > 0.005 and abs(far[2]) < 0.3 * along, far
    # the mark button: P1 and P2 at its presses
    assert w.last is not None
    marks = w.last.marks
    assert [m.label for m in marks[:2]] == ["P1", "P2"], marks
    for m, at in zip(marks, MARKS_AT, strict=False):
        assert t_press + at - SLACK <= w.clock(m.t) <= t_press + at + 0.1 + SLACK, (m, t_press)
    # the fault: FAULT with its cause, a notice naming it, the commanded motion at rest
    _, faults, names = FAULTS[kind]
    faulted, at_rest = w.faulted, w.at_rest
    assert faulted is not None and at_rest is not None
    assert at_rest.fault in faults and at_rest.fault.name in at_rest.cause, at_rest.cause
    said = [n.text for n in at_rest.notices] + [at_rest.cause]
    assert any(name in text for name in names for text in said), said
    if kind != "kuka-rsi":       # the injection's time, on the emulator's clock
        assert AT - SLACK <= w.clock(faulted.time) <= AT + 0.5, faulted.time
    # stopped: the commanded stop, then the driver's stop of the stream, in the notices
    last = w.last
    assert last.error == "stopped" and last.state != State.GUIDING and last.speed == 0.0
    texts = [n.text for n in last.notices]
    assert "stop: stop requested" in texts, texts
    assert any(t.startswith("driver stopped: after stop requested") for t in texts), texts
    if kind != "kuka-rsi":       # the robot there to see it: the emulator's own record
        assert w.report["violations"] == "()", w.report
