"""Exit codes of ``guide`` and ``record`` through :func:`leadthrough.cli.main`: 0 only for a
clean session, 3 for a fault latched during it (a non-finite sample, an E-stop), 1 for a lost
link or a controller that cannot be reached, 2 for bad input; the codes are in the help.

Before, ``guide --driver`` exited 0 after a latched NONFINITE_INPUT fault (a script could not
tell a faulted session from a clean one), the simulator's ``guide`` too, and ``record``
exited 2 (bad input) for an E-stop mid-run and for a lost link alike.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from leadthrough.cli import guide_cmd, main
from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.excitation.trajectory_file import save_trajectory
from leadthrough.robot.description import load_robot
from leadthrough.session_format import load_session
from leadthrough.sim.driver import InjectedFault, InjectedFaultKind
from leadthrough.sim.emulators import EmulatorOptions, FaultPlan, Window, start
from leadthrough.sim.guiding_params import shipped_params_path
from wire_helpers import POSE, free_loopback_address, spawn_emulator, stop_process, wait_for_line

PARAMS = str(shipped_params_path("er20"))


def _out(capsys: pytest.CaptureFixture[str]) -> tuple[str, str]:
    got = capsys.readouterr()
    return got.out, got.err


# ------------------------------------------------------------------------- the simulator
def test_guide_on_the_simulator_exits_0_clean_and_3_after_a_latched_fault(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    base = ["guide", "--robot", "er20", "--params", PARAMS, "--operator", "rest",
            "--duration", "1.5", "--json"]
    assert main([*base, "-o", str(tmp_path / "clean.parquet")]) == 0
    out, _ = _out(capsys)
    assert json.loads(out)["faults"] == []
    # the same session with a NaN in the measured positions at 0.8 s (the simulated driver's
    # feedback fault): the loop latches NONFINITE_INPUT and goes on to the end
    run = guide_cmd.run_sim_session

    def with_nan(robot: Any, pf: Any, cfg: Any) -> Any:
        nan = InjectedFault(InjectedFaultKind.NAN_Q, 0.8, 0.81)
        return run(robot, pf, dataclasses.replace(cfg, faults=(nan,)))

    monkeypatch.setattr(guide_cmd, "run_sim_session", with_nan)
    faulted = tmp_path / "faulted.parquet"
    assert main([*base, "-o", str(faulted)]) == 3
    out, err = _out(capsys)
    assert "NONFINITE_INPUT" in json.loads(out)["faults"]
    assert "a fault was latched" in err and "exit code 3" in err
    assert any(e.cause.endswith("NONFINITE_INPUT") for e in load_session(faulted).events)


def test_the_exit_codes_are_in_the_help(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["--help"], ["guide", "--help"], ["record", "--help"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 0
        text = " ".join(_out(capsys)[0].split())
        assert "exit codes: 0" in text and "3 " in text and "fault" in text, argv
        assert "1 " in text and "link" in text and "2 bad input" in text, argv


# ---------------------------------------------------------------- guide on a controller
def _nan_every_second() -> list[str]:
    args: list[str] = []
    for k in range(1, 120):
        args += ["--nan", f"{k}:{k + 0.02}"]
    return args


@contextmanager
def _ur_emulator(*extra: str) -> Iterator[str]:
    """``leadthrough emulate ur-rtde`` in its own process on a free loopback address."""
    port = DEFAULT_PORTS["ur-rtde"]
    host = free_loopback_address(port)
    emu = spawn_emulator("ur-rtde", "er20", host, port, "--seed", "1", "--q0", *map(str, POSE),
                         "--watchdog", "0.5", *extra)
    try:
        yield host
    finally:
        stop_process(emu)


def _guide_driver(host: str, out: Path, duration: float) -> list[str]:
    return ["guide", "--driver", "ur-rtde", "--host", host, "--robot", "er20", "--params",
            PARAMS, "--enable-input", "0", "--watchdog", "0.5", "--duration", str(duration),
            "-o", str(out), "--json"]


def test_guide_on_a_controller_exits_3_after_a_nan(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A NaN in the controller's joint positions (once a second, whenever the session runs):
    NONFINITE_INPUT is latched, the session runs to its end and the file is written: exit 3,
    the faults in the summary and on stderr (it was 0)."""
    out = tmp_path / "nan.parquet"
    with _ur_emulator(*_nan_every_second()) as host:
        code = main(_guide_driver(host, out, 2.5))
    stdout, stderr = _out(capsys)
    assert code == 3, stderr
    summary = json.loads(stdout)
    assert summary["end"] == "duration" and "NONFINITE_INPUT" in summary["faults"], summary
    assert "exit code 3" in stderr and "Traceback" not in stderr
    log = load_session(out)
    assert any(e.cause.endswith("NONFINITE_INPUT") for e in log.events)
    assert not out.with_name(out.name + ".partial").exists()


def test_guide_on_a_controller_exits_1_on_a_lost_link_and_a_dead_controller(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The controller's process killed mid-session (its sockets reset): the loop ends on a
    lost link, the recording written, exit 1 (a fault latched with it does not make it 3).
    Nobody at the address: exit 1 (the link, not the input; it was 2), one line, nothing
    written. Bad input stays 2."""
    out = tmp_path / "lost.parquet"
    port = DEFAULT_PORTS["ur-rtde"]
    host = free_loopback_address(port)
    emu = spawn_emulator("ur-rtde", "er20", host, port, "--seed", "1", "--q0", *map(str, POSE),
                         "--watchdog", "0.5")
    guide = subprocess.Popen([sys.executable, "-m", "leadthrough",
                              *_guide_driver(host, out, 120.0)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_line(guide, "leadthrough: guiding", 120)
        time.sleep(1.0)
        emu.kill()
        stdout, stderr = guide.communicate(timeout=60)
    finally:
        if guide.poll() is None:
            guide.kill()
        stop_process(emu)
    assert guide.returncode == 1, stderr
    assert json.loads(stdout)["end"] == "link lost" and "Traceback" not in stderr
    assert load_session(out).time.size > 0
    dead = tmp_path / "dead.parquet"
    assert main(["guide", "--driver", "fanuc-j519", "--host", "127.0.0.1", "--port", "9",
                 "--robot", "er20", "--params", PARAMS, "--enable-input", "0", "-o",
                 str(dead)]) == 1
    _, stderr = _out(capsys)
    assert "leadthrough: error:" in stderr and "Traceback" not in stderr
    assert not dead.exists() and not dead.with_name(dead.name + ".partial").exists()
    assert main(["guide", "--driver", "fanuc-j519", "--host", "127.0.0.1", "--robot", "er20",
                 "--params", PARAMS, "-o", str(dead)]) == 2


# ------------------------------------------------------------------------------- record
def _trajectory(path: Path, duration: float = 1.5) -> Path:
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    w = 2.0 * np.pi / duration
    direction = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    s = 0.05 * (1.0 - np.cos(w * t))[:, None] * direction
    sd = 0.05 * w * np.sin(w * t)[:, None] * direction
    sdd = 0.05 * w * w * np.cos(w * t)[:, None] * direction
    save_trajectory(path, TrajectorySamples(time=t, q=np.asarray(POSE) + s, qd=sd, qdd=sdd),
                    robot="er20")
    return path


@contextmanager
def _j519(**faults: Any) -> Iterator[int]:
    """An emulated J519 controller in this process, starting at POSE; its port."""
    opts = EmulatorOptions(q0=POSE, watchdog=0.5, faults=FaultPlan(**faults))
    emu = start("fanuc-j519", load_robot("er20"), seed=2, port=0, options=opts)
    try:
        yield emu.port
    finally:
        emu.stop()


@pytest.mark.parametrize(("faults", "code", "words"), [
    ({}, 0, "recorded"),
    ({"estop_at": 1.2}, 3, "controller state"),
])
def test_record_on_a_controller_exits_0_clean_and_3_after_an_estop(
        faults: dict[str, Any], code: int, words: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    traj = _trajectory(tmp_path / "traj.csv")
    out = tmp_path / "rec.parquet"
    with _j519(**faults) as port:
        got = main(["record", "--driver", "fanuc-j519", "--host", "127.0.0.1", "--port",
                    str(port), "--robot", "er20", "--trajectory", str(traj), "-o", str(out)])
    stdout, stderr = _out(capsys)
    assert got == code, stderr
    assert words in stdout + stderr and "Traceback" not in stderr
    assert out.exists() == (code == 0)


def test_record_exits_3_on_a_nan_and_1_on_a_lost_link(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    traj = _trajectory(tmp_path / "traj.csv")
    out = tmp_path / "rec.parquet"
    base = ["record", "--driver", "fanuc-j519", "--host", "127.0.0.1", "--robot", "er20",
            "--trajectory", str(traj), "-o", str(out)]
    with _j519(nan_q=(Window(1.2, 1.25),)) as port:
        assert main([*base, "--port", str(port)]) == 3
    _, stderr = _out(capsys)
    assert "non-finite" in stderr and not out.exists()
    with _j519(close_at=1.2) as port:    # UDP: the controller falls silent
        assert main([*base, "--port", str(port)]) == 1
    _, stderr = _out(capsys)
    # silence seen first (no fresh sample), or our next command answered by the kernel's
    # "port unreachable" once the emulator closed its socket (the link lost): both the link
    assert "leadthrough: error:" in stderr and (
        "no fresh sample" in stderr or "link lost" in stderr), stderr
    assert "Traceback" not in stderr and not out.exists()
    # nobody there: the link, exit 1
    assert main([*base, "--port", "9"]) == 1
    # the simulator's run: clean, 0
    sim = tmp_path / "sim.parquet"
    assert main(["record", "--robot", "er20", "--trajectory", str(traj), "-o", str(sim)]) == 0
    assert sim.exists()
