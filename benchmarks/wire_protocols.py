"""Cost of the real-controller wire codecs and round trips over loopback.

Per packet: encode / decode time of each codec (median of repeated runs), and for each
protocol a short session of our client against the emulated controller: the time from a
status packet's arrival to the command leaving (client side), the emulator's largest lag
behind the wall clock, and lost / late counts.

    python benchmarks/wire_protocols.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from leadthrough.drivers.fanuc_j519 import CommandPacket, StatusPacket, StreamMotionClient
from leadthrough.drivers.kuka_rsi import RobotMessage, RsiClient, SensorMessage
from leadthrough.drivers.ur_rtde import Recipe, RtdeClient, ServoCommand
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
    robot = load_robot("ur5" if kind == "ur-rtde" else "er20")
    turnaround: list[float] = []
    if kind == "kuka-rsi":
        rsi = RsiClient("127.0.0.1", 0)
        rsi.open()
        emu = start(kind, robot, 1, rsi.address[1], EmulatorOptions(q0=POSE))
        stats = rsi.stats
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if (msg := rsi.receive(0.1)) is not None:
                t0 = time.perf_counter()
                rsi.send(rsi.correction_for(msg.axis_setpoint or msg.axis_actual))
                turnaround.append(time.perf_counter() - t0)
        report = emu.stop()
        rsi.close()
    else:
        emu = start(kind, robot, 1, 0, EmulatorOptions(q0=POSE, watchdog=0.5))
        if kind == "fanuc-j519":
            j519 = StreamMotionClient("127.0.0.1", emu.port)
            j519.open()
            stats = j519.stats
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline:
                if (status := j519.receive(0.1)) is not None:
                    t0 = time.perf_counter()
                    j519.send(j519.make_command(list(status.joints[:6])))
                    turnaround.append(time.perf_counter() - t0)
            j519.close()
        else:
            rtde = RtdeClient("127.0.0.1", emu.port)
            rtde.open()
            stats = rtde.stats
            deadline, k = time.monotonic() + seconds, 0
            while time.monotonic() < deadline:
                if (state := rtde.receive(0.1)) is not None:
                    t0 = time.perf_counter()
                    k += 1
                    rtde.send(ServoCommand(tuple(state.q), k))
                    turnaround.append(time.perf_counter() - t0)
            rtde.close()
        report = emu.stop()
    us = np.array(turnaround) * 1e6
    print(f"  {kind:11s} packets {stats.received:5d}  send p50 {np.median(us):5.1f} µs "
          f"p99 {np.percentile(us, 99):6.1f} µs  lost {stats.missed:3d}  emulator max lag "
          f"{report.max_lag * 1e3:5.2f} ms  refused {report.refused}  violations "
          f"{len(report.violations)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    codecs()
    print(f"loopback sessions ({args.seconds:g} s each, client and emulator in one process)")
    for kind in ("fanuc-j519", "ur-rtde", "kuka-rsi"):
        session(kind, args.seconds)


if __name__ == "__main__":
    main()
