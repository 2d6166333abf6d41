"""Cost of the real-controller wire codecs and round trips over loopback.

Per packet: encode / decode time of each codec (median of repeated runs), and for each
protocol a short session of our driver against the emulated controller (a thread of the same
process, so both share one interpreter lock: the figures are pessimistic): the time of a
driver ``write`` (limiter, encoding, send), the stale steps (no packet within 3 cycles),
packets superseded before they were read, lost and unanswered packets, the emulator's largest
lag behind the wall clock, and what it refused.

    python benchmarks/wire_protocols.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from leadthrough.drivers.fanuc_j519 import CommandPacket, FanucJ519Driver, StatusPacket
from leadthrough.drivers.kuka_rsi import KukaRsiDriver, RobotMessage, SensorMessage
from leadthrough.drivers.streaming import StreamingDriver
from leadthrough.drivers.ur_rtde import Recipe, UrRtdeDriver
from leadthrough.robot import load_robot
from leadthrough.sim.emulators import EmulatorOptions, start

POSE = (0.3, -0.6, 0.4, 0.5, 0.8, 0.2)


def per_call(fn: Callable[[], object], repeat: int = 2000) -> float:
    """Median time of ``fn`` [µs] over 5 batches."""
    batches = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        batches.append((time.perf_counter() - t0) / repeat * 1e6)
    return statistics.median(batches)


def codecs() -> None:
    status = StatusPacket(sequence=1, status=5, joints=(1.0,) * 6, current=(0.5,) * 6)
    s_bytes = status.encode()
    cmd = CommandPacket(sequence=1, positions=(1.0,) * 6)
    c_bytes = cmd.encode()
    names = ("timestamp", "actual_q", "actual_current", "actual_digital_input_bits",
             "robot_mode", "safety_mode", "safety_status_bits", "runtime_state",
             "output_int_register_0")
    recipe = Recipe(1, names, ("DOUBLE", "VECTOR6D", "VECTOR6D", "UINT64", "INT32", "INT32",
                               "UINT32", "UINT32", "INT32"))
    values = {"timestamp": 1.0, "actual_q": (0.1,) * 6, "actual_current": (0.2,) * 6,
              "actual_digital_input_bits": 1, "robot_mode": 7, "safety_mode": 1,
              "safety_status_bits": 1, "runtime_state": 2, "output_int_register_0": 1}
    r_bytes = recipe.encode(values)
    rob = RobotMessage(ipoc=1, axis_actual=(1.0,) * 6, axis_setpoint=(1.0,) * 6,
                       cart_actual=(1.0,) * 6, cart_setpoint=(1.0,) * 6, delay=0,
                       gear_torque=(1.0,) * 6, digital_inputs=0)
    rob_bytes = rob.encode(6)
    sen = SensorMessage(1, (0.1,) * 6)
    sen_bytes = sen.encode(6)
    rows = [
        ("J519 status decode", lambda: StatusPacket.decode(s_bytes)),
        ("J519 command encode", cmd.encode),
        ("J519 command decode", lambda: CommandPacket.decode(c_bytes)),
        ("RTDE data decode (9 outputs)", lambda: recipe.decode(r_bytes)),
        ("RTDE data encode (9 outputs)", lambda: recipe.encode(values)),
        ("RSI <Rob> decode", lambda: RobotMessage.decode(rob_bytes)),
        ("RSI <Rob> encode", lambda: rob.encode(6)),
        ("RSI <Sen> encode", lambda: sen.encode(6)),
        ("RSI <Sen> decode", lambda: SensorMessage.decode(sen_bytes)),
    ]
    print("codec (median of 5 x 2000 calls)       µs")
    for name, fn in rows:
        print(f"  {name:36s} {per_call(fn):7.1f}")


def session(kind: str, seconds: float) -> None:
    """Our driver against the emulator (a thread of this process) for ``seconds``: the loop's
    write + step + read; the write (limiter, encoding, send) timed."""
    robot = load_robot("ur5" if kind == "ur-rtde" else "er20")
    options = EmulatorOptions(q0=POSE)
    driver: StreamingDriver  # type: ignore[type-arg]
    if kind == "kuka-rsi":
        driver = KukaRsiDriver(robot, "127.0.0.1", 0)
        emu = start(kind, robot, 1, driver.listen()[1], options)
    else:
        emu = start(kind, robot, 1, 0, options)
        driver = (FanucJ519Driver(robot, "127.0.0.1", emu.port) if kind == "fanuc-j519" else
                  UrRtdeDriver(robot, "127.0.0.1", emu.port,
                               script_port=emu.emulator.script_port))  # type: ignore[attr-defined]
    write_us: list[float] = []
    with driver:
        fb, cmd = driver.make_feedback(), driver.make_command()
        driver.step()
        driver.read(fb)
        cmd.q[:] = fb.q
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            t0 = time.perf_counter()
            driver.write(cmd)
            write_us.append((time.perf_counter() - t0) * 1e6)
            driver.step()
            driver.read(fb)
        report = emu.emulator.report()
        stats = driver.stats
    emu.stop()
    us = np.array(write_us)
    print(f"  {kind:11s} cycle {driver.dt * 1e3:3.0f} ms  packets {stats.received:5d}  write "
          f"p50 {np.median(us):5.1f} µs p99 {np.percentile(us, 99):6.1f} µs  stale "
          f"{stats.timeouts:3d}  superseded {stats.skipped:3d}  lost {stats.missed:3d}  "
          f"unanswered {driver.unanswered:3d}  emulator max lag {report.max_lag * 1e3:5.2f} ms"
          f"  refused {report.refused}  violations {len(report.violations)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    codecs()
    print(f"loopback sessions ({args.seconds:g} s each, driver and emulator in one process)")
    for kind in ("fanuc-j519", "ur-rtde", "kuka-rsi"):
        session(kind, args.seconds)


if __name__ == "__main__":
    main()
