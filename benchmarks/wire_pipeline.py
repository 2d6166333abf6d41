"""The calibration pipeline over the wire against the same pipeline on the in-process simulator
(issue 25, must show 2), for each controller interface.

Per interface: ``leadthrough emulate`` in its own process (the simulated robot of ``--seed``
behind the real protocol on a loopback socket), then exactly what a user runs:
``excite`` → ``record --driver`` → ``identify``; and the same trajectory through
``record --seed`` (in-process simulator, 1 kHz) → ``identify``. Both parameter sets are then
``validate``d on one held-out recording of the same robot (another excitation, in-process): the
relative torque error and J of each, and their difference. The wire recording is at the
controller's cycle (8 ms J519, 2 ms RTDE, 4 ms RSI), carries its transport delay and, for RSI,
joint torque instead of current.

    python benchmarks/wire_pipeline.py [--kinds fanuc-j519 ur-rtde kuka-rsi] [--seed 3]
        [--duration 20] [--method consistent]
"""

from __future__ import annotations

import argparse
import json
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

KINDS = ("fanuc-j519", "ur-rtde", "kuka-rsi")
PORTS = {"fanuc-j519": 60015, "ur-rtde": 30004, "kuka-rsi": 49152}
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


def _emulator(kind: str, robot: str, seed: int, port: int) -> subprocess.Popen[str]:
    """The emulated controller (its robot at its own start pose: record approaches)."""
    proc = subprocess.Popen(_lt("emulate", kind, "--robot", robot, "--seed", str(seed),
                                "--host", HOST, "--port", str(port)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], 60.0)
    if not ready or not proc.stdout.readline().startswith("leadthrough: emulating"):
        proc.kill()
        raise SystemExit(f"emulate {kind} did not start: {proc.communicate()}")
    return proc


def _record_wire(kind: str, robot: str, seed: int, traj: Path, out: Path) -> dict[str, Any]:
    port = PORTS[kind] + 100  # beside the interface's own port (a real one may be in use)
    args = ["record", "--driver", kind, "--host", HOST, "--port", str(port), "--robot", robot,
            "--trajectory", str(traj), "-o", str(out), "--json"]
    if kind == "kuka-rsi":  # the PC listens, then the robot sends
        rec = subprocess.Popen(_lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        time.sleep(3.0)
        emu = _emulator(kind, robot, seed, port)
    else:
        emu = _emulator(kind, robot, seed, port)
        rec = subprocess.Popen(_lt(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        stdout, stderr = rec.communicate(timeout=600)
    finally:
        emu.terminate()
        report, _ = emu.communicate(timeout=20)
    if rec.returncode != 0:
        raise RuntimeError(f"record --driver {kind} failed: {stderr.strip()}; emulator: "
                           f"{' '.join(report.split())}")
    info: dict[str, Any] = json.loads(stdout)
    info["emulator"] = {k.strip(): v.strip() for k, _, v in
                        (line.partition(":") for line in report.splitlines() if ":" in line)}
    return info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--robot", default="er20")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--method", default="consistent")
    ap.add_argument("--work", type=Path, default=None,
                    help="working folder (kept; its trajectories are reused)")
    args = ap.parse_args()
    work = args.work if args.work is not None else Path(tempfile.mkdtemp(prefix="lt-wire-"))
    work.mkdir(parents=True, exist_ok=True)
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
            except RuntimeError as e:
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


if __name__ == "__main__":
    main()
