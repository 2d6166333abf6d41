"""The pipeline over the wire against the same pipeline on the in-process simulator (issue 25,
must show 2), for each controller interface.

Per interface: ``leadthrough emulate`` in its own process (the simulated robot of ``--seed``
behind the real protocol on a loopback socket), then exactly what a user runs:
``excite`` → ``record --driver`` → ``identify``; and the same trajectory through
``record --seed`` (in-process simulator, 1 kHz) → ``identify``. Both parameter sets are then
``validate``d on one held-out recording of the same robot (another excitation, in-process): the
relative torque error and J of each, and their difference. The wire recording is at the
controller's cycle (8 ms J519, 2 ms RTDE, 4 ms RSI), carries its transport delay and, for RSI,
joint torque instead of current.

Then guiding (``--guide``, with the shipped guiding parameters of the simulated er20 and its
robot instance): ``leadthrough emulate --operator S`` (the scripted operator at the emulated
robot, from its start pose) and ``leadthrough guide --driver`` until the script's end, for the
scripts ``rest`` (no motion), ``push-x`` (40 N for 3 s, virtual mass 100 kg: to the 0.2 m/s
cap) and ``seam`` (P1 -> P2, then ``teach``); the same with ``leadthrough guide --operator S``
on the in-process simulator. Per run: the largest commanded TCP speed, the TCP's drift at rest,
the faults, the release overrun and, for the seam, the taught line's end points against the
operator's targets.

    python benchmarks/wire_pipeline.py [--kinds fanuc-j519 ur-rtde kuka-rsi] [--seed 3]
        [--duration 20] [--method consistent] [--guide] [--no-identify]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.errors import SimulationError
from leadthrough.sim.emulators.process import emulator_report, spawn_emulator, stop_emulator

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
HOST = "127.0.0.1"


def _lt(*args: str) -> list[str]:
    return [sys.executable, "-m", "leadthrough", *args]


def _run(*args: str) -> dict[str, Any]:
    """A leadthrough command with --json; its JSON output."""
    done = subprocess.run(_lt(*args, "--json"), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"leadthrough {' '.join(args)} failed:\n{done.stderr}")
    out: dict[str, Any] = json.loads(done.stdout)
    return out


def _record_wire(kind: str, robot: str, seed: int, traj: Path, out: Path) -> dict[str, Any]:
    port = DEFAULT_PORTS[kind] + 100  # beside the interface's own port (a real one may be in use)
    args = ["record", "--driver", kind, "--host", HOST, "--port", str(port), "--robot", robot,
            "--trajectory", str(traj), "-o", str(out), "--json"]
    if kind == "kuka-rsi":  # the PC listens, then the robot sends
        rec = subprocess.Popen(_lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        time.sleep(3.0)
        emu = spawn_emulator(kind, robot, HOST, port, "--seed", str(seed))
    else:  # the robot at the emulator's own start pose: record approaches
        emu = spawn_emulator(kind, robot, HOST, port, "--seed", str(seed))
        rec = subprocess.Popen(_lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        stdout, stderr = rec.communicate(timeout=600)
    finally:
        report = stop_emulator(emu)
    if rec.returncode != 0:
        raise RuntimeError(f"record --driver {kind} failed: {stderr.strip()}; emulator: "
                           f"{' '.join(report.split())}")
    info: dict[str, Any] = json.loads(stdout)
    info["emulator"] = emulator_report(report)
    return info


OPERATOR_DELAY_S = 3.0
SCRIPT_S = {"rest": 5.0, "push-x": 6.0, "seam": 30.0}


def _session_figures(path: Path) -> dict[str, Any]:
    """Figures of a recorded session (the same for the wire and the in-process runs)."""
    import numpy as np

    from leadthrough.session.metrics import release_overruns
    from leadthrough.session.record import load_session

    log = load_session(path)
    speed = np.linalg.norm(log.twist_cmd_base[:, :3], axis=1)
    tcp = log.tcp_cmd_base
    faults = sorted({e.cause.split(":", 1)[1] for e in log.events
                     if e.kind == "transition" and ":" in e.cause})
    over = release_overruns(log, 0.4)  # None over the wire: the hand is the emulator's
    return {"max_speed": float(speed.max()), "drift_mm": 1e3 * float(
        np.max(np.linalg.norm(tcp - tcp[0], axis=1))), "faults": faults,
        "overrun_mm": float("nan") if over is None else 1e3 * float(max(over, default=0.0))}


def _teach(path: Path, work: Path) -> str:
    done = subprocess.run(_lt("teach", str(path), "--robot", "er20", "-o",
                              str(work / f"{path.stem}.json"), "--json"),
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        return f"teach failed: {done.stderr.strip()[-200:]}"
    line = json.loads(done.stdout).get("welding_line") or {}
    return (f"line {1e3 * line.get('length_m', float('nan')):.0f} mm (0.3 m asked), max "
            f"deviation {line.get('max_deviation_mm', float('nan')):.1f} mm")


def _guide_wire(kind: str, script: str, seed: int, params: Path, q0: list[float],
                out: Path) -> str:
    """One guided session over the wire; returns the emulator's report line."""
    port = DEFAULT_PORTS[kind] + 300
    duration = OPERATOR_DELAY_S + SCRIPT_S[script] + 1.0
    guide = _lt("guide", "--driver", kind, "--host", HOST, "--port", str(port), "--robot",
                "er20", "--params", str(params), "--enable-input", "0", "--mark-input", "1",
                "--mass", "100", "--watchdog", "0.5", "--duration", str(duration), "-o",
                str(out), "--json")
    emu_args = ("--seed", str(seed), "--q0", *map(str, q0), "--operator", script,
                "--operator-delay", str(OPERATOR_DELAY_S))

    emu = None if kind == "kuka-rsi" else spawn_emulator(kind, "er20", HOST, port, *emu_args)
    g = subprocess.Popen(guide, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if emu is None:  # RSI: the PC listens first (after its set-up), then the robot sends
        assert g.stderr is not None
        while not g.stderr.readline().startswith("leadthrough: guiding"):
            if g.poll() is not None:
                raise RuntimeError(f"guide --driver {kind} ended: {g.communicate()}")
        emu = spawn_emulator(kind, "er20", HOST, port, *emu_args)
    try:
        _, err = g.communicate(timeout=600)
    finally:
        report = stop_emulator(emu)
    if not out.exists():
        raise RuntimeError(f"guide --driver {kind} wrote nothing: {err.strip()[-300:]}")
    fields = emulator_report(report)
    return f"refused {fields.get('refused')}, violations {fields.get('violations')}"


def guide_section(kinds: list[str], seed: int, work: Path) -> None:
    """The guiding comparison (see the module doc)."""
    from leadthrough.robot import load_robot
    from leadthrough.robot.poses import guide_start_pose
    from leadthrough.sim.guiding_params import shipped_params_path

    params = shipped_params_path("er20")
    q0 = [float(x) for x in guide_start_pose(load_robot("er20"))]
    print(f"\nguiding, shipped er20 parameters, robot instance {seed}, virtual mass 100 kg")
    print(f"{'script':<7} {'pipeline':<21} {'max speed':>10} {'drift':>9} {'overrun':>9} "
          f"faults / teach / emulator")
    for script in SCRIPT_S:
        sim = work / f"guide_{script}_sim.parquet"
        done = subprocess.run(_lt("guide", "--robot", "er20", "--params", str(params),
                                  "--operator", script, "--mass", "100", "--seed", str(seed),
                                  "-o", str(sim), "--json"),
                              capture_output=True, text=True, check=False)
        runs: list[tuple[str, Path, str]] = []
        if done.returncode in (0, 1) and sim.exists():
            runs.append(("in-process simulator", sim, ""))
        for kind in kinds:
            out = work / f"guide_{script}_{kind}.parquet"
            try:
                runs.append((kind, out, _guide_wire(kind, script, seed, params, q0, out)))
            except (RuntimeError, SimulationError) as e:
                print(f"{script:<7} {kind:<21} {e}")
        for name, path, note in runs:
            f = _session_figures(path)
            extra = _teach(path, work) if script == "seam" else ""
            print(f"{script:<7} {name:<21} {f['max_speed']:>8.3f} m/s {f['drift_mm']:>6.1f} mm "
                  f"{f['overrun_mm']:>6.1f} mm {f['faults'] or 'no fault'} {extra} {note}",
                  flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--robot", default="er20")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--method", default="consistent")
    ap.add_argument("--guide", action="store_true", help="also the guiding comparison")
    ap.add_argument("--no-identify", action="store_true", help="skip the calibration part")
    ap.add_argument("--work", type=Path, default=None,
                    help="working folder (kept; its trajectories are reused)")
    args = ap.parse_args()
    work = args.work if args.work is not None else Path(tempfile.mkdtemp(prefix="lt-wire-"))
    work.mkdir(parents=True, exist_ok=True)
    if args.no_identify:
        guide_section(args.kinds, 1, work)
        return
    robot, seed = args.robot, str(args.seed)
    traj, held = work / "traj.csv", work / "held.csv"
    for path, exc_seed in ((traj, "0"), (held, "2")):
        if not path.exists():
            _run("excite", "--robot", robot, "--duration", str(args.duration), "--starts", "1",
                 "--seed", exc_seed, "-o", str(path))
    _run("record", "--robot", robot, "--seed", seed, "--run", "1", "--trajectory", str(held),
         "-o", str(work / "held.parquet"))
    sim_rec = work / "sim.parquet"
    _run("record", "--robot", robot, "--seed", seed, "--trajectory", str(traj),
         "-o", str(sim_rec))
    rows: list[tuple[str, str, float, float, float]] = []
    for name, rec, info in [("in-process simulator", sim_rec, {"cycle_s": 1e-3})] + [
            (kind, work / f"{kind}.parquet", {}) for kind in args.kinds]:
        if name in KINDS:
            t0 = time.perf_counter()
            try:
                info = _record_wire(name, robot, args.seed, traj, rec)
            except (RuntimeError, SimulationError) as e:
                print(e, flush=True)
                continue
            info["wall_s"] = time.perf_counter() - t0
        params = work / f"{name.replace(' ', '_')}.toml"
        _run("identify", str(rec), "--robot", robot, "--method", args.method, "-o", str(params))
        val = _run("validate", str(params), str(work / "held.parquet"), "--robot", robot)
        rows.append((name, f"{1e3 * info['cycle_s']:g} ms", val["rel_error_pct"], val["J"],
                     float(info.get("max_following_error_rad", float("nan")))))
        if name in KINDS:
            emu = info["emulator"]
            print(f"{name}: {info['samples']} samples, {info['stale_cycles']} stale, approach "
                  f"{info['approach_s']:.1f} s, {info['wall_s']:.0f} s wall; emulator: "
                  f"commands {emu.get('commands')}, refused {emu.get('refused')}, violations "
                  f"{emu.get('violations')}", flush=True)
    base = rows[0][2]
    print(f"\n{args.method} on seed {seed}, held-out validation (another excitation, in-process)")
    print(f"{'pipeline':<22} {'cycle':>7} {'rel. torque error':>18} {'J [N·m]':>9} "
          f"{'vs in-process':>14}")
    for name, cycle, rel, J, _ in rows:
        print(f"{name:<22} {cycle:>7} {rel:>16.2f} % {J:>9.2f} {rel - base:>+12.2f} pp")
    if args.guide:
        guide_section(args.kinds, 1, work)


if __name__ == "__main__":
    main()
