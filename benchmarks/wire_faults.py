"""Faults on the wire, each injected by the emulated controller, during a guiding session:
how each ends (issue 25, "must show 3"). Prints a table per protocol × fault.

    python benchmarks/wire_faults.py [--protocols fanuc-j519 ur-rtde kuka-rsi] [--fault F ...]

Per case, ``leadthrough emulate P --robot er20 --seed 1`` runs in its own process (loopback,
a free 127.x address) with the enabling device pressed from 1.5 s (after the loop is ready: a
fresh press) and the fault from 3 s; the guiding loop (:func:`leadthrough.session.loop.
run_session`, the shipped er20 parameters, the controller cycle nearest 10 ms) runs in this
process through the protocol's driver until 6 s or the end of the link. Faults: 1 % of the
controller's packets lost plus a 100 ms burst, late replies (100 ms of packets 50 ms late), an
E-stop, a protective stop, the socket closed, an exception in the driver, a NaN in a reply.

Columns: the first fault the loop latched and when; how the session ended; the largest
commanded Cartesian acceleration from the fault on [m/s²] against the limit (a stop at the
acceleration limit, or no command at all once the link is gone: the controller's own stop);
whether the fault was latched at the end and logged with its cause; and from the emulator's
own record: commands refused, executed targets non-finite or beyond its limits
(``violations``, must be 0), and why its arm stopped.

The emulated arm has no operator pushing it: the robot is guided at rest, so the commanded
stops here start from rest (the stop from motion at the acceleration limit is shown on the
simulator, tests/test_loop_faults.py).
"""

from __future__ import annotations

import argparse
import math
import subprocess
import time
from dataclasses import dataclass, replace

import numpy as np

from leadthrough.control.guiding_types import GuidingConfig
from leadthrough.control.safety_states import Fault, State
from leadthrough.drivers.controllers import DEFAULT_PORTS, connect
from leadthrough.drivers.kuka_rsi import KukaRsiDriver
from leadthrough.drivers.protocol import Driver, WrappedDriver
from leadthrough.errors import DriverError
from leadthrough.identification.params_file import load_params
from leadthrough.robot import load_robot
from leadthrough.session.loop import LoopResult, run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.sim.emulators.process import (
    emulator_report,
    free_loopback_address,
    spawn_emulator,
    stop_emulator,
)
from leadthrough.sim.guiding_params import shipped_params_path

FAULT_AT = 3.0
END_AT = 6.0
FAULTS: dict[str, list[str]] = {
    "loss 1 % + 100 ms burst": ["--loss-rate", "0.01", "--loss-burst",
                                f"{FAULT_AT}:{FAULT_AT + 0.1}"],
    "late replies": ["--late", f"{FAULT_AT}:{FAULT_AT + 0.1}", "--late-by", "0.05"],
    "E-stop": ["--estop-at", str(FAULT_AT)],
    "protective stop": ["--protective-stop-at", str(FAULT_AT)],
    "socket closed": ["--close-at", str(FAULT_AT)],
    "driver exception": [],
    "NaN in a reply": ["--nan", f"{FAULT_AT}:{FAULT_AT + 0.01}"],
}


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
            self._t = fb.t - 1e6 if fb.t > 1e5 else fb.t   # RSI's IPOC starts at 1e6 s
        return fresh


@dataclass
class Case:
    protocol: str
    fault: str
    latched: str
    t_fault: float
    end: str
    max_acc: float
    logged: bool
    refused: str
    violations: str
    arm_stop: str


def _emulator(protocol: str, host: str, port: int, extra: list[str],
              wait: bool) -> subprocess.Popen[str]:
    args = ["--seed", "1", "--enable", "1.5:inf", *extra]
    if protocol == "kuka-rsi":
        args += ["--cycle-ms", "12"]
    return spawn_emulator(protocol, "er20", host, port, *args, wait=wait)


def run_case(protocol: str, fault: str) -> Case:
    robot = load_robot("er20")
    pf = load_params(shipped_params_path("er20"), robot)
    port = DEFAULT_PORTS[protocol]
    host = free_loopback_address(port)
    driver = (KukaRsiDriver(robot, host, port, cycle=0.012) if protocol == "kuka-rsi"
              else connect(protocol, robot, host, port))
    dt = driver.dt
    every = max(1, round(0.01 / dt))
    parts = build_loop(robot, pf, LoopConfig(guiding=replace(GuidingConfig(), dt=every * dt)), dt)
    for part in parts:                     # compiled before the link opens
        part.warm_up()
    options = LoopOptions(enable_input=0, watchdog_s=0.5, abort_s=1.0, stop_timeout_s=3.0)
    emu = None
    try:
        # RSI: the PC listens, the robot sends; the open waits for its first document
        emu = _emulator(protocol, host, port, FAULTS[fault], wait=protocol != "kuka-rsi")
        with driver:
            link: Driver = Raising(driver) if fault == "driver exception" else driver
            result = run_session(link, *parts, END_AT, options=options)
    finally:
        report = emulator_report(stop_emulator(emu)) if emu is not None else {}
    return _case(protocol, fault, result, report, parts.controller.config)


def _case(protocol: str, fault: str, r: LoopResult, report: dict[str, str],
          cfg: GuidingConfig) -> Case:
    log = r.log
    assert log is not None
    faulted = np.flatnonzero(log.state == int(State.FAULT))
    k = int(faulted[0]) if faulted.size else log.time.size - 1
    t = log.time - (1e6 if log.time[0] > 1e5 else 0.0)
    every = max(1, round(cfg.dt / (log.time[1] - log.time[0])))
    v = log.twist_cmd_base[k::every, :3]
    acc = (float(np.linalg.norm(np.diff(v, axis=0), axis=1).max() / cfg.dt) if len(v) > 1
           else 0.0)
    latched = Fault(int(log.fault[k])).name if faulted.size else Fault.NONE.name
    logged = any(e.kind == "transition" and e.label.endswith("FAULT") and latched in e.cause
                 for e in log.events)
    return Case(protocol, fault, latched, float(t[k]) if faulted.size else math.nan,
                f"{r.end.cause}", acc, logged, report.get("refused", "?"),
                report.get("violations", "?"), report.get("stop_kind", "?"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--protocols", nargs="+", default=list(DEFAULT_PORTS),
                        choices=list(DEFAULT_PORTS))
    parser.add_argument("--fault", nargs="+", default=list(FAULTS), choices=list(FAULTS))
    args = parser.parse_args()
    limit = GuidingConfig().limits.max_linear_acceleration
    for protocol in args.protocols:
        print(f"\n{protocol}: fault at {FAULT_AT} s, acceleration limit {limit} m/s²")
        print(f"{'fault':<26}{'latched':<18}{'t [s]':>7}  {'end':<16}{'max acc':>8}  "
              f"{'logged':<7}{'refused':>8}  {'violations':<11}{'arm stop'}")
        for fault in args.fault:
            c = run_case(protocol, fault)
            print(f"{c.fault:<26}{c.latched:<18}{c.t_fault:>7.3f}  {c.end:<16}"
                  f"{c.max_acc:>8.3f}  {'yes' if c.logged else 'NO':<7}{c.refused:>8}  "
                  f"{c.violations:<11}{c.arm_stop}", flush=True)
            time.sleep(0.5)


if __name__ == "__main__":
    main()
