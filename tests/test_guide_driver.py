"""``leadthrough guide --driver D --host H --enable-input 0 --mark-input 1`` end to end against
``leadthrough emulate D`` in its own process, for each of the three protocols over loopback.

The emulator presses the enabling device (its input 0) for 1 s every 2 s and the mark button
once in each press, from 1 s after its start: whenever the guide command's loop becomes ready,
presses begin after it. Checked: guiding starts only inside a press (a fresh press) and ends
after each release; the marks are in the recording streamed to disk; SIGINT (Ctrl-C) ends the
session with a commanded stop at rest, then the driver's clean stop of the stream (logged in the
file, so made before it was finished; the emulator saw a requested stop); the emulator's own record
has no refused command and nothing non-finite or beyond its limits; ``teach`` reads the marks.
The watchdog is 0.5 s, the loop's and (FANUC, UR) the emulated controller's: a machine as
loaded as a shared runner stalls a process for a few hundred ms now and then (CI on 8b4261c:
the guide process of the J519 case missed the emulator's default 4 cycles, 32 ms, before the
first press, a correct fault that left nothing of this test to check). A 50 ms loop watchdog's
fault is tested in tests/test_loop_faults.py, the controllers' own watchdogs in
tests/test_wire_drivers.py; RSI keeps its context's Timeout (late packets, not seconds).
The emulated arm has no operator pushing it, so the guided robot holds still: the taught line
is too short for ``teach``, which says so naming the two marks (a line needs a push, covered on
the simulator by tests/test_teach.py).
"""

from __future__ import annotations

import ast
import dataclasses
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from leadthrough.control.safety_states import State
from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.session_format import SessionLog, load_session
from leadthrough.sim.emulators import EMULATORS
from leadthrough.sim.emulators.kuka_rsi import IPOC_START
from leadthrough.sim.emulators.process import emulator_report
from leadthrough.sim.guiding_params import shipped_params_path
from wire_helpers import (
    POSE,
    free_loopback_address,
    spawn_emulator,
    stop_process,
    wait_for_line,
)

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
PRESSES = [(1.0 + 2 * k, 2.0 + 2 * k) for k in range(60)]


def _emulator_args(kind: str) -> list[str]:
    args = ["--seed", "1", "--q0", *map(str, POSE)]
    if kind != "kuka-rsi":
        args += ["--watchdog", "0.5"]
    for a, b in PRESSES:
        args += ["--enable", f"{a}:{b}", "--mark", f"{a + 0.4}:{a + 0.5}"]
    return args


def _guide(kind: str, host: str, out: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "leadthrough", "guide", "--driver", kind, "--host", host,
         "--robot", "er20", "--params", str(shipped_params_path("er20")), "--enable-input", "0",
         "--mark-input", "1", "-o", str(out), "--watchdog", "0.5", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _guiding_starts_and_ends(log: SessionLog) -> tuple[list[float], list[float]]:
    guiding = log.state == int(State.GUIDING)
    edges = np.diff(guiding.astype(int))
    return (list(log.time[1:][edges == 1]), list(log.time[1:][edges == -1]))


#: RSI runs in its 12 ms (IPO) mode here: at 4 ms a machine as loaded as a shared CI runner
#: answers late now and then, which is a refused command and a latched fault (correctly).
RSI_CYCLE_MS = 12
#: The emulators' status periods in these tests [s] (the others at their default cycle).
PERIODS = {kind: 1e-3 * (RSI_CYCLE_MS if kind == "kuka-rsi" else EMULATORS[kind].default_cycle_ms)
           for kind in KINDS}


def _emulator_stalled(log: SessionLog, report: str, period: float) -> bool:
    """Whether each of the session's stale-feedback faults is the emulator's own stall.

    The emulator is a Python process stepped at 1 ms; on a loaded machine it stalls now and
    then, and a stall longer than the loop's stale limit is a STALE_FEEDBACK fault, as on a
    real controller whose packets stop. Two of its statuses are its lag plus a period apart,
    so a fault is the emulator's only if its report lists a stall of at least the limit the
    loop logged ("stale feedback: no sample for … (limit L ms)") less one period, at that
    time. The emulator's clock stands still during a stall, so the stall's time is when it
    went silent; the loop logs the fault on that clock some cycles later (its own clock goes
    on a period per receive timeout meanwhile, and may stay ahead after): the fault comes from
    two periods before the stall's time to its length plus 0.1 s after it.
    """
    events = [e for e in log.events if e.kind == "loop" and e.label == "stale feedback"]
    limits = [re.search(r"limit (\d+) ms", e.cause) for e in events]
    if not events or not all(limits):
        return False
    stalls = ast.literal_eval(emulator_report(report)["stalls"])
    for event, match in zip(events, limits, strict=True):
        assert match is not None
        limit = float(match[1]) * 1e-3
        if not any(lag >= limit - period and -2 * period <= event.t - t <= lag + 0.1
                   for t, lag in stalls):
            return False
    return True


def _emulator_answered_late(log: SessionLog, report: str, period: float) -> bool:
    """Whether each of the session's refused commands on J519 is the emulator's own lag.

    J519 refuses each late answer: a CONTROLLER_STATE fault noted "controller state
    COMMAND_REJECTED", the status after the late answer reporting it not taken (RSI's
    refusal is a run of late answers, UR's program holds a cycle: neither is judged here).
    The emulator's answer timing (:mod:`~leadthrough.sim.emulators.answer_timing`) lists its
    first late or missing answers as ``t=<send> #<status> +<ms>`` or ``never``, marked
    `` lag`` where the emulator's own lag coincides (the answer is then not shown to be the
    client's). A fault is the emulator's only if such a marked answer is to a status sent
    within three periods before the fault.
    """
    notes = [e for e in log.events if e.kind == "loop" and e.label == "controller state"]
    if not notes or any(e.cause != "COMMAND_REJECTED" for e in notes):
        return False
    late = [re.match(r"t=([\d.]+) #\d+ (?:\S+ ms|never) lag$", entry) for entry in
            ast.literal_eval(emulator_report(report)["timing.events"])]
    sent = [float(m[1]) for m in late if m is not None]
    return all(any(t <= e.t <= t + 3 * period + 1e-6 for t in sent) for e in notes)


def _guide_until_ctrl_c(kind: str, folder: Path) -> tuple[SessionLog, str, Path]:
    """``guide --driver kind`` against the emulator for three presses, then Ctrl-C; the
    session (on the emulator's clock), the emulator's report and the session file."""
    folder.mkdir()
    port = DEFAULT_PORTS[kind]
    host = free_loopback_address(port)
    out = folder / "session.parquet"
    if kind == "kuka-rsi":      # the PC listens: start it first, then the robot sends to it
        guide = _guide(kind, host, out)
        wait_for_line(guide, "compiling the loop done", 120)
        emu = spawn_emulator(kind, "er20", host, port, "--cycle-ms", str(RSI_CYCLE_MS),
                             *_emulator_args(kind))
    else:
        emu = spawn_emulator(kind, "er20", host, port, *_emulator_args(kind))
        guide = _guide(kind, host, out)
    try:
        wait_for_line(guide, "leadthrough: guiding", 120)
        time.sleep(6.0)                          # three presses
        guide.send_signal(signal.SIGINT)
        stdout, stderr = guide.communicate(timeout=60)
    finally:
        if guide.poll() is None:
            guide.kill()
        report = stop_process(emu)
    assert "session ended: stop requested" in stdout and "Traceback" not in stderr
    assert out.exists() and not out.with_name(out.name + ".partial").exists()
    log = load_session(out)
    # exit 0 for a clean session, 3 when a fault was latched (the machine's load can cause
    # one: judged by the caller)
    latched = any(e.kind == "transition" and ":" in e.cause for e in log.events)
    assert guide.returncode == (3 if latched else 0), (guide.returncode, stderr)
    if kind == "kuka-rsi":        # the RSI clock is the IPOC [ms]; the emulator's starts here
        log = dataclasses.replace(log, time=log.time - IPOC_START * 1e-3, events=[
            dataclasses.replace(e, t=e.t - IPOC_START * 1e-3) for e in log.events])
    return log, report, out


@pytest.mark.parametrize("kind", KINDS)
def test_guide_against_the_emulator_until_ctrl_c(kind: str, tmp_path: Path) -> None:
    log, report, out = _guide_until_ctrl_c(kind, tmp_path / "first")
    latched = [e for e in log.events if e.kind == "transition" and e.label.endswith("FAULT")]
    if (any(f.cause.endswith("STALE_FEEDBACK") for f in latched)
            and _emulator_stalled(log, report, PERIODS[kind])) or (
            kind == "fanuc-j519" and any(f.cause.endswith("CONTROLLER_STATE") for f in latched)
            and _emulator_answered_late(log, report, PERIODS[kind])):
        # the emulator stalled or lagged (its report says so at that time), which a real
        # controller does not: the latched fault says nothing of the guiding, so the session
        # is run once more
        log, report, out = _guide_until_ctrl_c(kind, tmp_path / "again")
    # a fault the machine's load can cause (a stale sample, a late answer refused) may end a
    # phase; any other (a COLLISION at rest, a limit) is the loop's own and fails the test
    own = [(round(e.t, 3), e.cause) for e in log.events if e.kind == "transition"
           and e.label.endswith("FAULT")
           and not e.cause.endswith(("STALE_FEEDBACK", "CONTROLLER_STATE"))]
    assert not own, (own, report)
    # fresh presses: each guiding phase starts in a press and ends at its release, at Ctrl-C's
    # stop or at a fault (on a loaded machine a late answer is a refused command: RSI, J519)
    starts, ends = _guiding_starts_and_ends(log)
    if not starts:  # (pytest.fail prints all of it; an assertion's message is cut)
        events = "\n".join(f"  {e.t:.3f} {e.kind} {e.label} {e.cause}" for e in log.events)
        pytest.fail(f"no press guided; session {log.time[0]:.3f}-{log.time[-1]:.3f} s, "
                    f"events:\n{events}\nemulator report:\n{report}")
    # the recording's time is the loop's clock, on the controller's (the emulator's windows'):
    # an input change reaches the next packet (the emulator samples its inputs once per
    # cycle), is read in the sample after it and acted on at the next controller cycle (8,
    # 10, 12 ms here): within three cycles of the slowest
    slack = 0.037
    for t in starts:
        assert any(a - slack <= t <= a + slack for a, _ in PRESSES), (t, starts)
    stops = [e for e in log.events if e.kind == "loop" and e.label == "stop"]
    assert stops and stops[-1].cause == "stop requested"
    faults = [e.t for e in log.events if e.kind == "transition" and e.label.endswith("FAULT")]
    for t in ends:
        assert (any(b - slack <= t <= b + slack for _, b in PRESSES)
                or stops[-1].t <= t <= stops[-1].t + slack
                or any(f <= t <= f + slack for f in faults)), (t, ends, log.events)
    # every press after the first guided one, before a fault or the stop, guides again
    last = min([stops[-1].t, *faults])
    for a, b in PRESSES:
        if starts[0] <= a and b < last:
            assert any(a - slack <= t <= a + slack for t in starts), (a, starts, log.events)
    t0 = float(log.time[0])
    held_at_start = [w for w in PRESSES if w[0] < t0 < w[1]]
    for _, b in held_at_start:        # held when the loop started: no guiding in that press
        inside = (log.time > t0) & (log.time < b)
        assert not np.any(log.state[inside] == int(State.GUIDING))
    # marks from the mark input, in the file
    marks = [e for e in log.events if e.kind == "mark"]
    assert len(marks) >= 2 and [m.label for m in marks[:2]] == ["P1", "P2"]
    for m in marks:
        assert any(a + 0.4 - slack <= m.t <= a + 0.5 + slack for a, _ in PRESSES), m
    # Ctrl-C: a stop request, the commanded motion at rest at the end, then the stream's own
    # clean stop (J519's stop packet, the UR program's stop mode, RSI's Stop), logged in the
    # file: made before the file was finished; the controller saw a requested stop
    assert log.state[-1] != int(State.GUIDING) and not log.qd_cmd[-1].any()
    label, cause = [(e.label, e.cause) for e in log.events if e.kind == "loop"][-1]
    assert label == "driver stopped" and cause.startswith("after stop requested"), cause
    assert "stop_kind: request" in report, report
    assert "violations: ()" in report and "refused: 0" in report, report
    taught = subprocess.run([sys.executable, "-m", "leadthrough", "teach", str(out), "-o",
                             str(tmp_path / "path.json")], capture_output=True, text=True,
                            timeout=120)
    # the robot never moved: teach refuses the line between the two marks, naming both
    assert taught.returncode == 2 and "Traceback" not in taught.stderr, taught
    assert "P1 and P2 are only" in taught.stderr and "mm apart" in taught.stderr, taught


def test_guide_on_a_robot_needs_an_enabling_input_and_a_live_controller(tmp_path: Path) -> None:
    """No --enable-input, a simulator setting with --driver, the reset button on the enabling
    input: each a one-line error, exit 2, before any command; a controller that does not
    answer: one line, exit 1 (the link)."""
    out = tmp_path / "s.parquet"
    params = str(shipped_params_path("er20"))
    base = [sys.executable, "-m", "leadthrough", "guide", "--robot", "er20", "--params", params,
            "-o", str(out), "--driver", "fanuc-j519", "--host", "127.0.0.1"]
    no_enable = subprocess.run(base, capture_output=True, text=True, timeout=120)
    assert no_enable.returncode == 2 and "--enable-input" in no_enable.stderr
    operator = subprocess.run([*base, "--enable-input", "0", "--operator", "push-x"],
                              capture_output=True, text=True, timeout=120)
    assert operator.returncode == 2 and "--operator" in operator.stderr
    clash = subprocess.run([*base, "--enable-input", "0", "--reset-input", "0"],
                           capture_output=True, text=True, timeout=120)
    assert clash.returncode == 2 and "reset_input" in clash.stderr, clash.stderr
    assert "compiling" not in clash.stderr            # refused before anything is built
    dead = subprocess.run([*base, "--enable-input", "0", "--port", "9"], capture_output=True,
                          text=True, timeout=120)
    # the controller's link, not the input: exit 1
    assert dead.returncode == 1 and "Traceback" not in dead.stderr, dead.stderr
    assert not out.exists()


# a fault in each press and a reset press after it: enabling device [a, a + 1.5), a NaN in a
# reply at a + 0.8, the reset button [a + 2.2, a + 2.4), the next press at a + 6 (the
# estimator's warm-up and tare after the reset, 1 s of its samples, take 3 s here: guide
# --driver kuka-rsi runs RSI's 4 ms cycle, the emulator sends every 12 ms)
RESET_PERIODS = [1.0 + 6 * k for k in range(30)]


def _reset_emulator_args() -> list[str]:
    args = ["--seed", "1", "--q0", *map(str, POSE)]
    for a in RESET_PERIODS:
        args += ["--enable", f"{a}:{a + 1.5}", "--nan", f"{a + 0.8}:{a + 0.81}",
                 "--reset", f"{a + 2.2}:{a + 2.4}"]
    return args


def test_a_fault_is_reset_from_its_input_and_guiding_needs_a_fresh_press(
        tmp_path: Path) -> None:
    """``guide --driver kuka-rsi --reset-input 2`` against the emulator: each press ends in
    a latched fault (a NaN in a reply), the reset button resets it once the NaN has gone and
    the stop is at rest, guiding starts again only at the next press of the enabling device
    (none while it is still held or released after the reset), all without restarting; the
    session file records the faults and the resets, and the exit code is 3 (a fault was
    latched in the session, reset or not). RSI at 12 ms, whose isolated late answers
    are no fault (J519 refuses each late answer: on a machine as loaded as a shared runner its
    sessions latch a fault of their own now and then, which says nothing of the reset)."""
    kind = "kuka-rsi"
    host = free_loopback_address(DEFAULT_PORTS[kind])
    out = tmp_path / "session.parquet"
    guide = _guide(kind, host, out, "--reset-input", "2")   # the PC listens first
    emu = None
    try:
        wait_for_line(guide, "compiling the loop done", 120)
        emu = spawn_emulator(kind, "er20", host, DEFAULT_PORTS[kind], "--cycle-ms",
                             str(RSI_CYCLE_MS), *_reset_emulator_args())
        wait_for_line(guide, "leadthrough: guiding", 120)
        time.sleep(10.5)                         # past the second period's press (7 s)
        guide.send_signal(signal.SIGINT)
        stdout, stderr = guide.communicate(timeout=60)
    finally:
        if guide.poll() is None:
            guide.kill()
        report = stop_process(emu) if emu is not None else ""
    # the faults were reset, but the session latched them: not a clean session, exit 3
    assert guide.returncode == 3 and "session ended: stop requested" in stdout, stderr
    assert "a fault was latched in the session" in stderr, stderr
    log = load_session(out)   # on the emulator's clock (RSI's IPOC counts from IPOC_START)
    log = dataclasses.replace(log, time=log.time - IPOC_START * 1e-3, events=[
        dataclasses.replace(e, t=e.t - IPOC_START * 1e-3) for e in log.events])
    slack = 0.04      # three 12 ms cycles: the input's packet, its sample, the next cycle
    faults = [e for e in log.events if e.kind == "transition" and e.label.endswith("FAULT")]
    resets = [e for e in log.events if e.kind == "loop" and e.label == "fault reset"]
    starts, _ = _guiding_starts_and_ends(log)
    trace = [(round(e.t, 3), e.label, e.cause) for e in log.events]
    assert faults and resets, trace
    # a STALE_FEEDBACK fault only from the emulator's own stall; any other fault is a NaN's
    nan_faults = []
    for f in faults:
        if f.cause.endswith("STALE_FEEDBACK"):
            assert _emulator_stalled(log, report, PERIODS[kind]), (f, report, trace)
        else:
            nan_faults.append(f)
    assert nan_faults, trace
    for f in nan_faults:  # each at a NaN, caused by it, logged with its cause
        assert f.cause.endswith("NONFINITE_INPUT") or f.cause.endswith("ESTIMATOR"), (f, trace)
        assert any(a + 0.8 <= f.t <= a + 0.81 + slack for a in RESET_PERIODS), (f, trace)
    for r in resets:      # each from a press of the reset button, after a fault
        assert any(a + 2.2 <= r.t <= a + 2.2 + slack for a in RESET_PERIODS), (r, trace)
        assert any(f.t < r.t for f in faults)
    # faulted from each fault to its reset: no guiding in between
    for f in faults:
        after = [r.t for r in resets if r.t > f.t]
        until = after[0] if after else log.time[-1]
        inside = (log.time > f.t + slack) & (log.time < until)
        assert np.all(log.state[inside] == int(State.FAULT)), (f, trace)
    # guiding again after a reset, only at the next fresh press of the enabling device
    again = [t for t in starts if any(r.t < t for r in resets)]
    assert again, (starts, trace)
    for t in again:
        assert any(a - slack <= t <= a + slack for a in RESET_PERIODS), (t, starts)
    assert "violations: ()" in report and "refused: 0" in report, report
