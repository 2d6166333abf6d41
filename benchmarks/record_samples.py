"""How many of a recorded trajectory's controller cycles this machine keeps: ``record_trajectory``
(``leadthrough record --driver``) against each emulated controller in this process, on
loopback, as ``tests/test_record_driver.py`` runs it.

The test checks what the recording's logic guarantees (a sample per answered controller cycle,
on the controller's clock, at most ``max_stale_s`` of them lost in a row); the share of cycles
that brought a fresh sample, and the stale reads, depend on how fast and how loaded the
machine is: that figure is here. An idle 2-core machine kept every cycle in trial runs; a
loaded one loses a few per cent (the emulator is a thread of this process, stepped at 1 ms).

    python benchmarks/record_samples.py [--runs 3] [--duration 1.5]

Prints, per protocol and run: the samples, the trajectory's cycles, their share [%], the stale
reads and the longest run of lost cycles.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from leadthrough.drivers.controllers import connect
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.robot import load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.trajectory_recording import record_trajectory
from leadthrough.sim.emulators import EmulatorOptions, start

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
ROBOT = {"fanuc-j519": "er20", "ur-rtde": "ur5", "kuka-rsi": "er20"}


def _trajectory(pose: np.ndarray, duration: float, offset: float = 0.05) -> TrajectorySamples:
    """A smooth out-and-back motion of every joint, starting ``offset`` rad from ``pose``."""
    direction = np.where(np.arange(pose.size) % 2 == 0, 1.0, -1.0)
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    w = 2.0 * np.pi / duration
    s = 0.15 * (1.0 - np.cos(w * t))[:, None] * direction
    sd = 0.15 * w * np.sin(w * t)[:, None] * direction
    sdd = 0.15 * w * w * np.cos(w * t)[:, None] * direction
    return TrajectorySamples(time=t, q=pose + offset * direction + s, qd=sd, qdd=sdd)


def run_once(kind: str, duration: float) -> dict[str, float]:
    """One recording of ``duration`` [s]: its figures."""
    robot = load_robot(ROBOT[kind])
    pose = np.asarray(guide_start_pose(robot), dtype=float)
    opts = EmulatorOptions(q0=tuple(pose), watchdog=0.2)
    if kind == "kuka-rsi":
        driver = connect(kind, robot, "127.0.0.1", 0)
        emu = start(kind, robot, seed=2, port=driver.listen()[1],  # type: ignore[attr-defined]
                    options=opts)
    else:
        emu = start(kind, robot, seed=2, port=0, options=opts)
        driver = connect(kind, robot, "127.0.0.1", emu.port)
        if kind == "ur-rtde":
            driver.script_port = emu.emulator.script_port  # type: ignore[attr-defined]
    try:
        with driver:
            done = record_trajectory(driver, robot, _trajectory(pose, duration))
    finally:
        emu.stop()
    cycles = math.floor(duration / driver.dt + 1e-9) + 1
    apart = np.round(np.diff(done.recording.time) / driver.dt)
    return {"samples": done.recording.samples, "cycles": cycles,
            "share_pct": 100.0 * done.recording.samples / cycles, "stale": done.stale,
            "longest_loss": float(apart.max() - 1) if apart.size else 0.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=1.5, help="trajectory [s]")
    args = ap.parse_args()
    print(f"{'protocol':<11} {'run':>3} {'samples':>7} {'cycles':>6} {'share %':>7} "
          f"{'stale':>5} {'longest loss':>12}")
    for kind in KINDS:
        for k in range(args.runs):
            f = run_once(kind, args.duration)
            print(f"{kind:<11} {k:>3} {f['samples']:>7} {f['cycles']:>6} "
                  f"{f['share_pct']:>7.1f} {f['stale']:>5} {f['longest_loss']:>12.0f}")


if __name__ == "__main__":
    main()
