"""Faults on the wire, each injected by the emulated controller while the robot moves at speed
under a hand: how each ends (issue 25, "must show 3"). Prints a table per protocol × fault.

    python benchmarks/wire_faults.py [--protocols fanuc-j519 ur-rtde kuka-rsi] [--fault F ...]

Per case, ``leadthrough emulate P --robot er20 --seed 1 --operator push-x`` runs in its own
process (loopback, a free 127.x address): 3 s after the stream's first command the emulated
operator presses the enabling device (a fresh press: the loop is ready by then) and from 1 s
later pushes the tool along +x with 40 N for 3 s (into the simulated plant; the loop sees the
push only through the currents or RSI's joint torques). The fault comes at ``FAULT_AT`` = 5.5 s
of the emulator's clock: 2.2-2.5 s into the operator's script (the stream starts within 0.3 s
of the emulator), 1.2-1.5 s into the push, when the guided TCP runs at the speed limit
(0.2 m/s; the table shows it). The guiding loop (:func:`leadthrough.session.loop.run_session`,
the shipped er20 parameters, the controller cycle nearest 10 ms) runs in this process through
the protocol's driver until ``END_AT`` or the end of the link. RSI runs at its 12 ms (IPO)
cycle: at 4 ms a process of this loaded 2-core machine answers late in runs now and then.

Faults: 1 % of the controller's packets lost plus a 100 ms burst; late replies (100 ms of the
controller's packets 50 ms late); an E-stop; a protective stop; the socket closed; an
exception in the driver; a NaN in a reply; and two of our side: isolated missing answers (one
every 0.5 s, four) and a run of five missing answers in a row (the loop's process skips its
answer: the controller counts a late answer).

Columns: the first fault latched; its time on the script's clock [s]; the commanded TCP speed
when it latched (no fault: at the injection) [m/s]; the largest commanded Cartesian
acceleration from one cycle before it on, of the controller's cycles (acc), of the interpolated
joint command averaged over a cycle (cmd) and at the servo period (peak: inside a cycle) [m/s²]
(:mod:`leadthrough.session.stop_figures`), against the limit; the commanded stop distance [mm]
and time [s]; how the session ended; whether the fault was latched to the end and logged with
its cause; the answers the controller counted late (the driver's count); from the emulator's
own record: commands refused, executed targets non-finite or beyond its limits (``viol``, must
be 0), and why its arm stopped (``watchdog``, ``estop``, ``protective``: the controller's own
stop; ``request``: the driver's stop at the session's end, the stream's clean end); the
attempts: on this loaded machine a late answer of ours (J519 refuses it) or a
scheduling stall sometimes latches a fault before the injected one, or the push has not reached
0.1 m/s; such an attempt says nothing of the case and is run again, up to three times (the
count is shown; each spoilt attempt's fault and time are printed above its row).
"""

from __future__ import annotations

import argparse
import math
import subprocess
import time
from dataclasses import dataclass, replace

import numpy as np

from leadthrough.control.guiding_types import GuidingConfig
from leadthrough.drivers.controllers import DEFAULT_PORTS, connect
from leadthrough.drivers.kuka_rsi import KukaRsiDriver
from leadthrough.drivers.protocol import Driver, JointCommand, WrappedDriver
from leadthrough.errors import DriverError
from leadthrough.identification.params_file import load_params
from leadthrough.robot import load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import LoopResult, run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.session.stop_figures import StopFigures, stop_figures
from leadthrough.sim.emulators.process import (
    emulator_report,
    free_loopback_address,
    spawn_emulator,
    stop_emulator,
)
from leadthrough.sim.guiding_params import shipped_params_path
from leadthrough.sim.session import light_guiding

FAULT_AT = 5.5
END_AT = 9.5
MASS_KG = 100.0    # the translational virtual mass (as wire_pipeline.py's push-x)
ATTEMPTS = 3
RSI_CLOCK0 = 1e6   # RSI's IPOC starts at 1e9 ms
FAULTS: dict[str, list[str]] = {
    "loss 1 % + 100 ms burst": ["--loss-rate", "0.01", "--loss-burst",
                                f"{FAULT_AT}:{FAULT_AT + 0.1}"],
    "late replies": ["--late", f"{FAULT_AT}:{FAULT_AT + 0.1}", "--late-by", "0.05"],
    "E-stop": ["--estop-at", str(FAULT_AT)],
    "protective stop": ["--protective-stop-at", str(FAULT_AT)],
    "socket closed": ["--close-at", str(FAULT_AT)],
    "driver exception": [],
    "NaN in a reply": ["--nan", f"{FAULT_AT}:{FAULT_AT + 0.01}"],
    "4 isolated missing answers": [],
    "5 missing answers in a row": [],
}
#: Our side's faults: cycles (from the first at or after FAULT_AT + offset [s]) not answered.
UNANSWERED = {"4 isolated missing answers": ((0.0, 1), (0.5, 1), (1.0, 1), (1.5, 1)),
              "5 missing answers in a row": ((0.0, 5),)}


def clock(t: float) -> float:
    """The emulator's clock from a feedback time [s] (RSI's IPOC starts at 1e6 s)."""
    return t - RSI_CLOCK0 if t > RSI_CLOCK0 / 10 else t


class Raising(WrappedDriver):
    """Raises once from ``step`` at the first sample at or after ``FAULT_AT`` of the
    emulator's clock (an exception inside the driver)."""

    def __init__(self, driver: Driver) -> None:
        super().__init__(driver)
        self._t = math.nan
        self._raised = False

    def step(self) -> None:
        if not self._raised and self._t >= FAULT_AT:
            self._raised = True
            raise DriverError("injected: the driver raised", field="step", value=self._t)
        self._driver.step()

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        if fresh:
            self._t = clock(fb.t)
        return fresh


class Unanswering(WrappedDriver):
    """Skips the answer (``write``) of ``count`` cycles from the first sample at or after each
    ``FAULT_AT + offset`` of the emulator's clock: the controller counts late answers."""

    def __init__(self, driver: Driver, plan: tuple[tuple[float, int], ...]) -> None:
        super().__init__(driver)
        self._plan = [(FAULT_AT + offset, count) for offset, count in plan]
        self._t = math.nan
        self._skip = 0
        self.skipped = 0

    def write(self, cmd: JointCommand) -> None:
        if self._plan and self._t >= self._plan[0][0]:
            self._skip += self._plan.pop(0)[1]
        if self._skip > 0:
            self._skip -= 1
            self.skipped += 1
            return
        self._driver.write(cmd)

    def read(self, fb):  # type: ignore[no-untyped-def]
        fresh = self._driver.read(fb)
        if fresh:
            self._t = clock(fb.t)
        return fresh


@dataclass
class Case:
    protocol: str
    fault: str
    figures: StopFigures
    script_t: float
    end: str
    late_answers: int
    report: dict[str, str]
    speed_at_injection: float
    attempts: int = 1

    @property
    def spoilt(self) -> bool:
        """A fault latched before the injected one (the machine's load: a late answer),
        or no guiding at the fault: the attempt says nothing of the case."""
        t = clock(self.figures.t_fault)
        return t < FAULT_AT - 0.02 or not (self.speed_at_injection > 0.1
                                           or self.figures.speed_at_fault > 0.1)


def _emulator(protocol: str, host: str, port: int, extra: list[str],
              wait: bool) -> subprocess.Popen[str]:
    q0 = guide_start_pose(load_robot("er20"))
    args = ["--seed", "1", "--q0", *map(str, q0), "--operator", "push-x", *extra]
    if protocol == "kuka-rsi":
        args += ["--cycle-ms", "12"]
    return spawn_emulator(protocol, "er20", host, port, *args, wait=wait)


def _link(driver: Driver, fault: str) -> Driver:
    if fault == "driver exception":
        return Raising(driver)
    if fault in UNANSWERED:
        return Unanswering(driver, UNANSWERED[fault])
    return driver


def run_case(protocol: str, fault: str) -> Case:
    robot = load_robot("er20")
    pf = load_params(shipped_params_path("er20"), robot)
    port = DEFAULT_PORTS[protocol]
    host = free_loopback_address(port)
    driver = (KukaRsiDriver(robot, host, port, cycle=0.012) if protocol == "kuka-rsi"
              else connect(protocol, robot, host, port))
    dt = driver.dt
    every = max(1, round(0.01 / dt))
    parts = build_loop(robot, pf, LoopConfig(guiding=replace(light_guiding(MASS_KG),
                                                             dt=every * dt)), dt)
    for part in parts:                     # compiled before the link opens
        part.warm_up()
    options = LoopOptions(enable_input=0, watchdog_s=0.5, abort_s=1.0, stop_timeout_s=3.0)
    emu = None
    try:
        # RSI: the PC listens, the robot sends; the open waits for its first document
        emu = _emulator(protocol, host, port, FAULTS[fault], wait=protocol != "kuka-rsi")
        with driver:
            result: LoopResult = run_session(_link(driver, fault), *parts, END_AT,
                                             options=options)
    finally:
        if emu is not None:   # the driver's stop taken at the controller's next cycle
            time.sleep(0.05)
        report = emulator_report(stop_emulator(emu)) if emu is not None else {}
    assert result.log is not None
    figures = stop_figures(result.log, robot, parts.controller.config.dt)
    start = report.get("operator_start", "None")
    script_t = (clock(figures.t_fault) - float(start) if start != "None" else math.nan)
    log = result.log
    at = min(int(np.searchsorted(log.time - (log.time[0] - clock(log.time[0])), FAULT_AT)),
             log.time.size - 1)
    return Case(protocol, fault, figures, script_t, str(result.end.cause),
                getattr(driver, "late_answers", 0), report,
                float(np.linalg.norm(log.twist_cmd_base[at, :3])))


def _row(c: Case) -> str:
    f, r = c.figures, c.report
    logged = "yes" if f.logged and f.latched_to_end else ("no fault" if math.isnan(f.t_fault)
                                                          else "NO")
    viol = "0" if r.get("violations") == "()" else r.get("violations", "?")
    v = c.speed_at_injection if math.isnan(f.t_fault) else f.speed_at_fault
    return (f"{c.fault:<27}{f.fault.name:<18}{c.script_t:>6.2f}{v:>7.3f}"
            f"{f.cycle_acc:>7.3f}{f.command_acc:>7.3f}{f.command_peak:>7.3f}"
            f"{f.distance * 1e3:>7.1f}{f.stop_time:>6.2f}  "
            f"{c.end:<11}{logged:<9}{c.late_answers:>5}{r.get('refused', '?'):>5}  {viol:<5}"
            f"{r.get('stop_kind', '?'):<11}{c.attempts}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--protocols", nargs="+", default=list(DEFAULT_PORTS),
                        choices=list(DEFAULT_PORTS))
    parser.add_argument("--fault", nargs="+", default=list(FAULTS), choices=list(FAULTS))
    args = parser.parse_args()
    limit = GuidingConfig().limits.max_linear_acceleration
    for protocol in args.protocols:
        print(f"\n{protocol}: fault at {FAULT_AT} s of the emulator's clock, push-x, "
              f"acceleration limit {limit} m/s²")
        print(f"{'fault':<27}{'latched':<18}{'t':>6}{'v':>7}{'acc':>7}{'cmd':>7}{'peak':>7}"
              f"{'dist':>7}{'stop':>6}  {'end':<11}{'logged':<9}{'late':>5}{'ref':>5}  "
              f"{'viol':<5}{'arm stop':<11}tries")
        for fault in args.fault:
            for attempt in range(1, ATTEMPTS + 1):
                case = run_case(protocol, fault)
                case.attempts = attempt
                time.sleep(0.5)
                if not case.spoilt:
                    break
                f = case.figures     # what spoilt it, for the record
                print(f"  (attempt {attempt} spoilt: {f.fault.name} at "
                      f"{clock(f.t_fault):.3f} s, {case.speed_at_injection:.3f} m/s at the "
                      "injection)", flush=True)
            print(_row(case), flush=True)


if __name__ == "__main__":
    main()
