"""The three real-controller drivers against their emulated controllers over loopback sockets,
through the Driver protocol only (write, step, read): trajectories followed, limits kept,
controller state and inputs read, and every injected fault seen for what it is (sequence
gaps, stale feedback, controller-state flags, DriverError), with the emulator confirming that
nothing non-finite and no jump beyond its limits was executed."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import pytest

from leadthrough.drivers.fanuc_j519 import FanucJ519Driver
from leadthrough.drivers.kuka_rsi import KukaRsiDriver
from leadthrough.drivers.protocol import ControllerState
from leadthrough.drivers.streaming import StreamingDriver
from leadthrough.drivers.ur_rtde import UrRtdeDriver
from leadthrough.errors import DriverError
from leadthrough.robot import Robot, load_robot
from leadthrough.sim.emulators import (
    EmulatorOptions,
    EmulatorReport,
    FaultPlan,
    InputSchedule,
    RunningEmulator,
    Window,
    start,
)
from leadthrough.sim.emulators.arm import StopKind
from leadthrough.sim.emulators.kuka_rsi import IPOC_START
from wire_helpers import (
    DIRECTION,
    POSE,
    free_loopback_address,
    min_jerk,
    spawn_emulator,
    stop_process,
)

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
ROBOT = {"fanuc-j519": "er20", "ur-rtde": "ur5", "kuka-rsi": "er20"}
Target = Callable[[float, np.ndarray], np.ndarray]


@pytest.fixture(scope="module")
def robots() -> dict[str, Robot]:
    return {name: load_robot(name) for name in ("er20", "ur5")}


@dataclass
class Trace:
    """What the driver delivered, one entry per fresh sample (sim time [s] of the emulator)."""

    t: list[float] = field(default_factory=list)
    sequence: list[int] = field(default_factory=list)
    q: list[np.ndarray] = field(default_factory=list)
    state: list[int] = field(default_factory=list)
    inputs: list[int] = field(default_factory=list)
    stale: int = 0
    error: DriverError | None = None

    def flags(self, after: float = 0.0, before: float = math.inf) -> int:
        """Every state flag seen in ``after <= t < before`` [s]."""
        out = 0
        for t, s in zip(self.t, self.state, strict=True):
            out |= s if after <= t < before else 0
        return out


def _sim_time(kind: str, t: float) -> float:
    return t - IPOC_START * 1e-3 if kind == "kuka-rsi" else t


@contextmanager
def _session(kind: str, robot: Robot, watchdog: float | None = 0.2, **options: object
             ) -> Iterator[tuple[StreamingDriver, RunningEmulator]]:  # type: ignore[type-arg]
    """A driver opened on an emulator; the controller's watchdog 0.2 s (its own default with
    ``watchdog=None``), so that a loaded machine's hiccup does not stop a test of something
    else."""
    opts = EmulatorOptions(q0=POSE, watchdog=watchdog, **options)  # type: ignore[arg-type]
    driver: StreamingDriver  # type: ignore[type-arg]
    if kind == "kuka-rsi":
        driver = KukaRsiDriver(robot, "127.0.0.1", 0, connect_timeout=5.0)
        emu = start(kind, robot, seed=2, port=driver.listen()[1], options=opts)
    else:
        emu = start(kind, robot, seed=2, port=0, options=opts)
        driver = (FanucJ519Driver(robot, "127.0.0.1", emu.port) if kind == "fanuc-j519" else
                  UrRtdeDriver(robot, "127.0.0.1", emu.port,
                               script_port=emu.emulator.script_port))  # type: ignore[attr-defined]
    try:
        driver.open()
        yield driver, emu
    finally:
        driver.close()
        emu.stop()


def _stream(kind: str, driver: StreamingDriver, duration: float,  # type: ignore[type-arg]
            target: Target) -> Trace:
    """The loop every guiding session runs, until the controller's clock reaches ``duration``
    [s] (or 1.5 × that + 0.5 s of wall time pass: a silent controller, or an emulator slowed
    by a loaded machine); ``target(t, q0)`` [rad] on the controller's clock (sequence × cycle
    since the first sample)."""
    fb, cmd, trace = driver.make_feedback(), driver.make_command(), Trace()
    for _ in range(50):  # the first packet (a loaded machine may miss a step's timeout)
        driver.step()
        if driver.read(fb):
            break
    assert fb.sequence >= 0
    q0, seq0 = fb.q.copy(), fb.sequence
    cmd.q[:] = q0
    end = time.monotonic() + 1.5 * duration + 0.5
    while time.monotonic() < end and not (trace.t and trace.t[-1] >= duration):
        try:
            driver.write(cmd)
            driver.step()
        except DriverError as e:
            trace.error = e
            break
        if not driver.read(fb):
            trace.stale += 1
            continue
        trace.t.append(_sim_time(kind, fb.t))
        trace.sequence.append(fb.sequence)
        trace.q.append(fb.q.copy())
        trace.state.append(fb.state)
        trace.inputs.append(fb.inputs if fb.inputs_read else -1)
        if np.all(np.isfinite(fb.q)):
            cmd.q[:] = target((fb.sequence - seq0) * driver.dt, q0)
    return trace


def _hold(t: float, q0: np.ndarray) -> np.ndarray:
    return q0


def _report(emu: RunningEmulator) -> EmulatorReport:
    """The report before the driver's close adds its own stop."""
    return emu.emulator.report()


def _limit_refusals(emu: RunningEmulator) -> list[str]:
    """Commands the controller refused for what they asked (not because it had stopped)."""
    return [r.reason for r in emu.emulator.arm.refusals]


# --------------------------------------------------------------------------- normal work
@pytest.mark.parametrize("kind", KINDS)
def test_positions_follow_and_inputs_are_read(kind: str, robots: dict[str, Robot]) -> None:
    robot = robots[ROBOT[kind]]
    inputs = InputSchedule(enable=(Window(0.4),), mark=(Window(0.8, 1.0),))
    delta = 0.2 * DIRECTION
    with _session(kind, robot, inputs=inputs) as (driver, emu):
        if kind == "ur-rtde":
            time.sleep(0.2)  # the program idles until the first command: no watchdog stop
        trace = _stream(kind, driver, 2.0, lambda t, q0: min_jerk(q0, delta, t, 1.2))
        report = _report(emu)
    assert trace.error is None and report.violations == () and report.refused == 0
    assert report.stop_kind is None and report.accepted > 0.8 * len(trace.t)
    assert np.abs(trace.q[-1] - (np.array(POSE) + delta)).max() < 2e-4  # rad, settled
    # a feasible stream passes untouched, unless cycles went by without our target (a loaded
    # machine): the controller held the last one, and the catch-up is limited
    assert driver.limiter is not None
    assert driver.limiter.limited <= 20 * driver.skipped_cycles
    late = ControllerState.COMMAND_REJECTED  # answers a loaded machine sent too late
    assert driver.stats.missed == 0 and trace.flags(after=0.1) & ~late == 0
    t, bits = np.array(trace.t), np.array(trace.inputs)
    read = bits >= 0
    assert read.mean() > 0.9
    assert not np.any(bits[read & (t < 0.35)] & 1) and np.all(bits[read & (t > 0.45)] & 1)
    marked = t[read & (bits & 2 > 0)]
    assert marked.min() > 0.75 and marked.max() < 1.05


@pytest.mark.parametrize("kind", KINDS)
def test_a_jump_is_limited_and_never_refused(kind: str, robots: dict[str, Robot]) -> None:
    robot = robots[ROBOT[kind]]
    jump = 0.3 * DIRECTION
    with _session(kind, robot) as (driver, emu):
        trace = _stream(kind, driver, 2.0, lambda t, q0: q0 + (jump if t > 0.1 else 0.0))
        report = _report(emu)
        with pytest.raises(DriverError) as err:  # nothing non-finite reaches the wire
            cmd = driver.make_command()
            cmd.q[:] = np.nan
            driver.write(cmd)
    assert err.value.field == "cmd.q"
    assert trace.error is None and driver.limiter is not None and driver.limiter.limited > 5
    assert report.refused == 0 and report.violations == () and report.stop_kind is None
    assert np.abs(trace.q[-1] - (np.array(POSE) + jump)).max() < 2e-4


# --------------------------------------------------------------------------------- faults
# what each controller does about 1 % loss and a 100 ms burst of lost packets: J519 and the
# UR program stop on their watchdogs (no command can answer a packet that never came), RSI
# counts the 25 documents as late answers (below its Timeout of 100) and carries on; the
# driver knows those 25 were never received, so they are not answers of ours it rejected
LOSS_OUTCOME = {"fanuc-j519": ("watchdog", ControllerState.NOT_READY),
                "ur-rtde": ("watchdog", ControllerState.NOT_READY),
                "kuka-rsi": (None, ControllerState.NORMAL)}


@pytest.mark.parametrize("kind", KINDS)
def test_packet_loss_shows_as_gaps_and_the_controllers_own_stop(
        kind: str, robots: dict[str, Robot]) -> None:
    faults = FaultPlan(loss_rate=0.01, loss_bursts=(Window(0.5, 0.6),))
    with _session(kind, robots[ROBOT[kind]], None, faults=faults) as (driver, emu):
        trace = _stream(kind, driver, 1.2, _hold)
        report = _report(emu)
    stop, flag = LOSS_OUTCOME[kind]
    burst = round(0.1 / driver.dt)
    assert trace.error is None and trace.stale >= 2
    assert driver.stats.missed >= burst - 1 and driver.stats.gaps >= 1
    jumps = np.diff(trace.sequence)
    assert jumps.max() >= burst - 1 and jumps.min() >= 1
    assert report.stop_kind == stop and report.violations == () and not _limit_refusals(emu)
    late = ControllerState.COMMAND_REJECTED  # a loaded machine's late answers
    assert trace.flags(after=0.6) & flag == flag and not trace.flags() & ~(flag | late) & ~(
        ControllerState.NOT_READY if stop else 0)
    assert not trace.flags() & (ControllerState.ESTOP | ControllerState.PROTECTIVE_STOP)


@pytest.mark.parametrize("kind", KINDS)
def test_late_replies_leave_the_feedback_stale(kind: str, robots: dict[str, Robot]) -> None:
    faults = FaultPlan(late=(Window(0.5, 0.7),), late_by=0.1)
    with _session(kind, robots[ROBOT[kind]], None, faults=faults) as (driver, emu):
        trace = _stream(kind, driver, 1.2, _hold)
        report = _report(emu)
    assert trace.error is None and driver.stats.timeouts >= 3 and trace.stale >= 3
    assert report.violations == () and not _limit_refusals(emu)
    # never a step back in time: a late packet behind a newer one is dropped (UDP); a TCP
    # stream delivers in order (the emulator holds the packets after a late one behind it)
    assert np.all(np.diff(trace.sequence) > 0), trace.sequence
    assert (driver.out_of_order == 0) if kind == "ur-rtde" else (driver.out_of_order > 0)
    if kind == "kuka-rsi":  # answers to late documents carry stale IPOCs: counted as late
        assert trace.flags(after=0.5) & ControllerState.COMMAND_REJECTED
        assert report.stop_kind is None
    else:  # 100 ms without a packet to answer: the watchdog stops the arm
        assert trace.flags(after=0.5) & ControllerState.NOT_READY
        assert report.stop_kind == "watchdog"


STOP_FLAG = {("fanuc-j519", "estop"): ControllerState.NOT_READY,
             ("fanuc-j519", "protective"): ControllerState.NOT_READY,
             ("ur-rtde", "estop"): ControllerState.ESTOP,
             ("ur-rtde", "protective"): ControllerState.PROTECTIVE_STOP}


@pytest.mark.parametrize("stop", ["estop", "protective"])
@pytest.mark.parametrize("kind", KINDS)
def test_estop_and_protective_stop_reach_the_feedback(kind: str, stop: str,
                                                      robots: dict[str, Robot]) -> None:
    at = {"estop_at": 0.5} if stop == "estop" else {"protective_stop_at": 0.5}
    with _session(kind, robots[ROBOT[kind]], faults=FaultPlan(**at)) as (driver, emu):
        trace = _stream(kind, driver, 1.0, lambda t, q0: q0 + 0.05 * DIRECTION * t)
        report = _report(emu)
        refused = _limit_refusals(emu)
    # the rejections masked below are late answers only: no command refused for what it asked
    assert report.stop_kind == stop and report.violations == () and not refused, refused
    late = ControllerState.COMMAND_REJECTED  # a loaded machine's late answers (RSI)
    assert trace.error is None and trace.flags(after=0.1, before=0.5) & ~late == 0
    if kind == "kuka-rsi":  # RSI has no state to report: the robot goes silent
        assert max(trace.t) < 0.52 and trace.stale > 0.3 / driver.timeout
    else:
        assert trace.flags(after=0.52) & STOP_FLAG[(kind, stop)]
        assert all(s & STOP_FLAG[(kind, stop)] for t, s in zip(trace.t, trace.state,
                                                                strict=True) if t > 0.6)


@pytest.mark.parametrize("kind", KINDS)
def test_nan_and_a_closed_socket(kind: str, robots: dict[str, Robot]) -> None:
    faults = FaultPlan(nan_q=(Window(0.3, 0.34),), close_at=0.6)
    with _session(kind, robots[ROBOT[kind]], faults=faults) as (driver, emu):
        trace = _stream(kind, driver, 1.2, _hold)
        report = _report(emu)
    nan = [t for t, q in zip(trace.t, trace.q, strict=True) if not np.all(np.isfinite(q))]
    assert nan and min(nan) > 0.29 and max(nan) < 0.36  # delivered as is: the loop judges
    assert report.violations == () and not _limit_refusals(emu)
    if kind == "ur-rtde":  # TCP: the closed connection is an error naming the cause
        assert trace.error is not None and "link lost" in str(trace.error)
        assert trace.error.value == "closed"
    else:  # UDP: a closed socket is silence
        assert trace.error is None and max(trace.t) < 0.62 and trace.stale > 0.3 / driver.timeout


# ------------------------------------------------------------------- refusals at the start
def test_connection_refused_is_a_driver_error(robots: dict[str, Robot]) -> None:
    with pytest.raises(DriverError) as err:  # nobody on that TCP port
        UrRtdeDriver(robots["ur5"], "127.0.0.1", 9, connect_timeout=0.5).open()
    assert "cannot connect" in str(err.value) and err.value.value == "127.0.0.1:9"
    with pytest.raises(DriverError) as err:  # UDP: the port-unreachable answer
        FanucJ519Driver(robots["er20"], "127.0.0.1", 9, connect_timeout=0.5).open()
    assert err.value.field == "host:port" and err.value.value == "127.0.0.1:9"
    with pytest.raises(DriverError) as err:  # no robot sends
        KukaRsiDriver(robots["er20"], "127.0.0.1", 0, connect_timeout=0.3).open()
    assert err.value.field == "connect_timeout" and "leadthrough_rsi.src" in str(err.value)


def test_wrong_joint_count_or_units_is_a_driver_error(robots: dict[str, Robot]) -> None:
    panda = load_robot("panda")
    for make in (lambda: UrRtdeDriver(panda, "127.0.0.1"), lambda: KukaRsiDriver(panda)):
        with pytest.raises(DriverError) as err:
            make()
        assert err.value.field == "robot.n" and err.value.value == 7
    options = EmulatorOptions(q0=(0.3, 2.0, 0.4, 0.5, 0.8, 0.2))  # ur5 pose
    with start("fanuc-j519", robots["ur5"], seed=1, port=0, options=options) as emu:
        with pytest.raises(DriverError) as err:  # a 7-axis robot file on a 6-axis arm
            FanucJ519Driver(panda, "127.0.0.1", emu.port).open()
        assert "axis 7" in str(err.value)
        with pytest.raises(DriverError) as err:  # the ER20 file on the UR5 arm at 2 rad
            FanucJ519Driver(robots["er20"], "127.0.0.1", emu.port).open()
        assert err.value.field == "q[1]" and "unit" in str(err.value)


def test_the_ur_controller_refusing_the_stream(robots: dict[str, Robot]) -> None:
    ur5 = robots["ur5"]
    with _session("ur-rtde", ur5) as (driver, emu):
        second = UrRtdeDriver(ur5, "127.0.0.1", emu.port, script_port=None)
        with pytest.raises(DriverError) as err:  # another client writes the registers
            second.open()
        assert err.value.value == "IN_USE"
    faults = FaultPlan(protective_stop_at=0.0)  # a controller in protective stop runs no program
    with start("ur-rtde", ur5, seed=1, port=0, options=EmulatorOptions(q0=POSE, faults=faults)
               ) as emu:
        driver = UrRtdeDriver(ur5, "127.0.0.1", emu.port, connect_timeout=0.5,
                              script_port=emu.emulator.script_port)  # type: ignore[attr-defined]
        with pytest.raises(DriverError) as err:
            driver.open()
        assert "program is not running" in str(err.value) and "safety_mode 3" in str(err.value)
    assert not math.isnan(emu.emulator.t)


# ---------------------------------------------------------- the emulator in its own process
@pytest.mark.parametrize("kind", KINDS)
def test_leadthrough_emulate_in_its_own_process(kind: str, robots: dict[str, Robot]) -> None:
    """``leadthrough emulate`` on its default port (of a free 127.x address; RSI: sending to
    the port the driver listens on), our driver streaming to it for 2 s."""
    robot = robots[ROBOT[kind]]
    pose = ["--q0", *(str(q) for q in POSE), "--enable", "0.5:", "--watchdog", "0.2"]
    driver: StreamingDriver  # type: ignore[type-arg]
    if kind == "kuka-rsi":
        driver = KukaRsiDriver(robot, "127.0.0.1", 0, connect_timeout=60.0)
        host, port = "127.0.0.1", driver.listen()[1]
    else:
        port = {"fanuc-j519": 60015, "ur-rtde": 30004}[kind]
        host = free_loopback_address(port)
        driver = (FanucJ519Driver(robot, host) if kind == "fanuc-j519"
                  else UrRtdeDriver(robot, host))  # default ports: 60015, 30004 and 30002
    proc = spawn_emulator(kind, ROBOT[kind], host, port, "--seed", "3", *pose)
    try:
        with driver:
            delta = 0.2 * DIRECTION
            trace = _stream(kind, driver, 2.0, lambda t, q0: min_jerk(q0, delta, t, 1.0))
    finally:
        printed = stop_process(proc)
    flagged = [(t, s) for t, s in zip(trace.t, trace.state, strict=True) if s][:5]
    late = ControllerState.COMMAND_REJECTED  # answers a loaded machine sent too late
    assert trace.error is None and trace.flags() & ~late == 0, (flagged, printed)
    assert np.abs(trace.q[-1] - (np.array(POSE) + delta)).max() < 2e-4
    assert trace.inputs[-1] & 1  # the enabling device, held from 0.5 s
    assert "violations: ()" in printed and "refused: 0" in printed


@pytest.mark.parametrize("kind", KINDS)
def test_close_ends_the_stream_the_controllers_own_way(kind: str,
                                                       robots: dict[str, Robot]) -> None:
    """``close`` is the stream's clean end, seen by the controller as a requested stop:
    J519's stop packet, the UR program's stop mode, RSI's answer with Stop (not RSI's count
    of late answers running out, nor a watchdog)."""
    with _session(kind, robots[ROBOT[kind]], None) as (driver, emu):
        trace = _stream(kind, driver, 0.3, _hold)
        driver.close()
        arm = emu.emulator.arm
        deadline = time.monotonic() + 1.0
        while arm.stop_kind is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert trace.error is None and arm.stop_kind is StopKind.REQUEST, arm.stop_reason
        driver.close()                                     # again: nothing more
