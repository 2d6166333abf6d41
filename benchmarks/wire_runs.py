"""The wire benchmarks' processes: ``leadthrough`` commands and emulated controllers run as
subprocesses, as a user runs them (``wire_pipeline.py``, ``wire_guiding.py``).

Each emulator is ``leadthrough emulate`` in its own process (:func:`leadthrough.sim.emulators.
process.spawn_emulator`) on a loopback socket; ``--rt-priority`` puts every process of a run at
``SCHED_FIFO`` (:data:`RT_PRIORITY`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.sim.emulators.process import emulator_report, spawn_emulator

__all__ = ["HOST", "KINDS", "RSI_REACH_RAD", "RT_PRIORITY", "emulator_clean", "failure", "lt",
           "record_wire", "rsi_sized", "rt", "run_json", "stop", "tail", "verdict",
           "wait_line"]

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
HOST = "127.0.0.1"
#: RSI's reach from where it started [rad]: the shipped context's ±90° within the driver's
#: 0.95 margin.
RSI_REACH_RAD = 0.95 * 90.0 * 3.141592653589793 / 180.0
#: SCHED_FIFO priority of the runs' processes (``--rt-priority``), if given.
RT_PRIORITY: list[int] = []


def rt(proc: subprocess.Popen[str] | None) -> subprocess.Popen[str] | None:
    """Run ``proc`` with SCHED_FIFO at --rt-priority, if given (as long_session.py does)."""
    if proc is not None and RT_PRIORITY:
        os.sched_setscheduler(proc.pid, os.SCHED_FIFO, os.sched_param(RT_PRIORITY[0]))
    return proc


def lt(*args: str) -> list[str]:
    return [sys.executable, "-m", "leadthrough", *args]


def run_json(*args: str) -> dict[str, Any]:
    """A leadthrough command with --json; its JSON output."""
    done = subprocess.run(lt(*args, "--json"), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"leadthrough {' '.join(args)} failed:\n{done.stderr}")
    out: dict[str, Any] = json.loads(done.stdout)
    return out


def stop(proc: subprocess.Popen[str] | None) -> tuple[str, str]:
    """SIGTERM a spawned emulator; its (stdout: the report, stderr)."""
    if proc is None:
        return "", ""
    proc.terminate()
    try:
        out, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return out, err


def tail(text: str, n: int = 600) -> str:
    text = " ".join(text.split())
    return text if len(text) <= n else "..." + text[-n:]


def failure(what: str, stderr: str, emu: tuple[str, str]) -> RuntimeError:
    """A failed run, with the stderr of every process in it."""
    return RuntimeError(f"{what}: {tail(stderr) or '(no stderr)'}\n    emulator report: "
                        f"{tail(emu[0]) or '(none)'}\n    emulator stderr: "
                        f"{tail(emu[1]) or '(none)'}")


def wait_line(proc: subprocess.Popen[str], start: str, timeout: float) -> str | None:
    """Read ``proc``'s stderr until a line starts with ``start``; None if it ended or timed
    out first; the lines read are returned either way (as the error's text)."""
    assert proc.stderr is not None
    lines: list[str] = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        line = proc.stderr.readline()
        lines.append(line)
        if line.startswith(start):
            return None
        if not line and proc.poll() is not None:
            break
    return "".join(lines) + (proc.stderr.read() if proc.poll() is not None else "")


def record_wire(kind: str, robot: str, seed: int, traj: Path, out: Path,
                 q0: list[float] | None) -> dict[str, Any]:
    """``record --driver`` against ``emulate`` (``q0``: its start pose [rad], else its own)."""
    port = DEFAULT_PORTS[kind] + 100  # beside the interface's own port (a real one may be in use)
    args = ["record", "--driver", kind, "--host", HOST, "--port", str(port), "--robot", robot,
            "--trajectory", str(traj), "-o", str(out), "--json"]
    emu_args = ["--seed", str(seed)] + (["--q0", *map(str, q0)] if q0 is not None else [])
    emu: subprocess.Popen[str] | None = None
    if kind == "kuka-rsi":  # the PC listens, then the robot sends
        rec = subprocess.Popen(lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        rt(rec)
        time.sleep(3.0)  # record binds its port at once (no set-up before the open)
        if rec.poll() is None:
            emu = rt(spawn_emulator(kind, robot, HOST, port, *emu_args))
    else:  # the robot at the emulator's own start pose: record approaches
        emu = rt(spawn_emulator(kind, robot, HOST, port, *emu_args))
        rec = subprocess.Popen(lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        rt(rec)
    try:
        stdout, stderr = rec.communicate(timeout=600)
    finally:
        report = stop(emu)
    if rec.returncode != 0:
        raise failure(f"record --driver {kind} failed (exit {rec.returncode})", stderr, report)
    info: dict[str, Any] = json.loads(stdout)
    info["emulator"] = emulator_report(report[0])
    return info


def rsi_sized(traj: Path, out: Path, robot: str) -> list[float]:
    """The trajectory contracted, per axis, towards the middle of its range until it lies
    within RSI's correction range from there (positions, speeds and accelerations scaled by
    the same factor); written to ``out``. Returns the middle [rad]: RSI's start pose."""
    import numpy as np

    from leadthrough.excitation.fourier import TrajectorySamples
    from leadthrough.excitation.trajectory_file import load_trajectory, save_trajectory

    t, _ = load_trajectory(traj)
    mid = (t.q.min(axis=0) + t.q.max(axis=0)) / 2.0
    half = np.maximum(np.ptp(t.q, axis=0) / 2.0, 1e-9)
    k = np.minimum(1.0, 0.97 * RSI_REACH_RAD / half)
    save_trajectory(out, TrajectorySamples(time=t.time, q=mid + k * (t.q - mid), qd=k * t.qd,
                                           qdd=k * t.qdd), robot,
                    notes={"sized": "contracted to RSI's correction range (wire_pipeline.py)"})
    return [float(x) for x in mid]


def emulator_clean(emu: dict[str, str]) -> list[str]:
    """Why an emulator's report fails the wire tolerance ([] if it does not)."""
    bad = []
    if emu.get("refused") != "0":
        bad.append(f"emulator refused {emu.get('refused')} ({emu.get('stop_reason')})")
    if emu.get("violations") != "()":
        bad.append(f"limit violations {emu.get('violations')}")
    return bad


def verdict(bad: list[str]) -> str:
    return "PASS" if not bad else "FAIL: " + "; ".join(bad)
