"""Does the pendant touch the real-time loop? The guiding loop's timing with and without the
pendant and a browser, in one run (issue 26, must show 2).

One live session on the simulated er20 runs in real time (1 ms servo period, 10 ms controller
cycle) for the whole run, guided throughout: a hand pushes the tool ±40 N along y in a 6 s
pattern (push, let go, push back, let go), so that every phase sees the same motion. The phases,
each a whole number of patterns long:

1. ``alone``: the loop only;
2. ``pendant``: the pendant's web server running, no browser;
3. ``reader``: a client in another process that reads every message the page would get and
   draws nothing: the pendant's whole work for a browser, without the browser's own CPU;
4. ``browser``: Debian's Chromium (headless, software WebGL) showing the page, updated 20 times
   a second, on this machine;
5. ``frozen``: that Chromium stopped (SIGSTOP to its process group): a browser that no longer
   reads its websocket while the server keeps sending;
6. ``alone again``: the browser and the server closed: the run's own drift and noise.

Per phase it prints, for every servo period and for the controller-cycle periods: the loop's
period **work** (estimator + controller cycle + interpolation, as ``run_session`` measures it)
median / p99 / p99.9 / max [µs], and **done**: from the period's scheduled start to the end of its
work (waking up, the simulated robot's step, the work: where a held interpreter lock or a busy
CPU would show) median / p99 / max [µs], with periods later than one period. Noise: the two
loop-only phases are cut into 1 s blocks; a phase differs "beyond noise" when its work median,
work p99, done p99 or share of late periods lies outside the range of that figure over those
blocks.
The machine's load and the process's memory are printed too (a frozen browser must not make the
server hoard messages without bound).

    python benchmarks/pendant_isolation.py [--phase-s 18] [--port 8097]
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from leadthrough.pendant.app import Pendant, wait_for_clients
from leadthrough.pendant.backend import LiveSession, PeriodTimes, SetEnable
from leadthrough.pendant.simulated import simulated_session
from leadthrough.robot import load_robot
from leadthrough.sim.operator import HandPush

PATTERN_S = 6.0
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--remote-debugging-port=0",
                 "--window-size=1280,800"]


@dataclass(frozen=True)
class Phase:
    """One phase's periods and what the machine did meanwhile."""

    name: str
    times: PeriodTimes
    load: float
    rss_mb: float


def hand_pattern(t: float) -> np.ndarray:
    """The hand's force at time ``t`` into the pattern [N]: +40 N, 0, −40 N, 0 along y."""
    k = int(t // (PATTERN_S / 4)) % 4
    return np.array([0.0, (40.0, 0.0, -40.0, 0.0)[k], 0.0])


def run_phase(name: str, live: LiveSession, hand: HandPush, seconds: float) -> Phase:
    """Push the pattern for ``seconds`` and collect the periods run meanwhile."""
    start = live.periods_run
    t0 = time.monotonic()
    while (elapsed := time.monotonic() - t0) < seconds:
        hand.push(hand_pattern(elapsed))
        time.sleep(0.05)
    hand.release()
    count = live.periods_run - start
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return Phase(name, live.period_times(count), os.getloadavg()[0], rss)


def _stats(values: np.ndarray) -> tuple[float, float, float, float]:
    return (float(np.median(values)), float(np.percentile(values, 99)),
            float(np.percentile(values, 99.9)), float(values.max()))


def _figures(times: PeriodTimes) -> np.ndarray:
    """Work median, work p99, done p99 [µs] and late periods [%] of some periods."""
    w, d = times.work_us, times.done_us
    return np.array([np.median(w), np.percentile(w, 99), np.percentile(d, 99),
                     100.0 * np.mean(d > 1000.0)])


def _block_figures(times: PeriodTimes, per_block: int = 1000) -> np.ndarray:
    """:func:`_figures` of each whole block of ``per_block`` periods, shape (k, 4)."""
    return np.array([_figures(PeriodTimes(times.work_us[k:k + per_block],
                                          times.done_us[k:k + per_block],
                                          times.controller_cycle[k:k + per_block]))
                     for k in range(0, times.work_us.size - per_block + 1, per_block)])


def report(phases: list[Phase]) -> None:
    """Print the table and the verdict."""
    print(f"\n{'phase':<12} {'periods':>8} {'work µs: median':>16} {'p99':>6} {'p99.9':>6} "
          f"{'max':>7} | {'cycle work: median':>18} {'p99':>6} | {'done µs: median':>15} "
          f"{'p99':>6} {'max':>7} {'late':>5} | load  RSS MB")
    for ph in phases:
        w, c, d = ph.times.work_us, ph.times.work_us[ph.times.controller_cycle], ph.times.done_us
        sw, sc, sd = _stats(w), _stats(c), _stats(d)
        late = int(np.sum(d > 1000.0))
        print(f"{ph.name:<12} {w.size:>8} {sw[0]:>16.1f} {sw[1]:>6.1f} {sw[2]:>6.1f} "
              f"{sw[3]:>7.0f} | {sc[0]:>18.1f} {sc[1]:>6.1f} | {sd[0]:>15.1f} {sd[1]:>6.1f} "
              f"{sd[3]:>7.0f} {late:>5} | {ph.load:4.2f}  {ph.rss_mb:6.0f}")
    _verdict(phases)


def _verdict(phases: list[Phase]) -> None:
    """A phase is within noise when each figure lies within the range of the same figure
    over the 1 s blocks of both loop-only phases."""
    ref = np.concatenate([_block_figures(ph.times) for ph in phases
                          if ph.name.startswith("alone")])
    lo, hi = ref.min(axis=0), ref.max(axis=0)
    names = ("work median", "work p99", "done p99", "late %")
    print("\nloop-only 1 s blocks: " + ", ".join(
        f"{n} {a:.1f}–{b:.1f}" for n, a, b in zip(names, lo, hi, strict=True)))
    for ph in phases:
        fig = _figures(ph.times)
        out = [n for n, v, a, b in zip(names, fig, lo, hi, strict=True) if not a <= v <= b]
        print(f"  {ph.name:<12} " + ", ".join(
            f"{n} {v:.1f}" for n, v in zip(names, fig, strict=True))
            + ("  -> beyond noise: " + ", ".join(out) if out else "  -> within noise"))


#: The ``reader`` client: connects as viser's page does (its first message, the camera, makes
#: it a client) and reads until killed.
READER = """
import sys
import msgspec
import viser
from websockets.sync.client import connect
camera = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
          "position": [2.0, -0.6, 1.3], "fov": 1.3, "near": 0.01, "far": 100.0,
          "image_height": 800, "image_width": 1280, "look_at": [0.5, 0.1, 0.6],
          "up_direction": [0.0, 0.0, 1.0]}
with connect(sys.argv[1], subprotocols=[f"viser-v{viser.__version__}"], max_size=None) as ws:
    ws.send(msgspec.msgpack.encode(camera))
    while True:
        ws.recv()
"""


def _reader(url: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-c", READER, url.replace("http", "ws", 1)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _chromium(url: str, profile: Path) -> subprocess.Popen[bytes]:
    binary = shutil.which("chromium") or "/usr/bin/chromium"
    return subprocess.Popen([binary, *CHROMIUM_ARGS, f"--user-data-dir={profile}", url],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--phase-s", type=float, default=18.0,
                        help="length of each phase [s] (rounded to whole 6 s patterns)")
    parser.add_argument("--port", type=int, default=8097)
    parser.add_argument("--rt-priority", type=int, default=None,
                        help="run the loop's thread under SCHED_FIFO at this priority")
    parser.add_argument("--switch-interval-ms", type=float, default=None,
                        help="Python's thread switch interval [ms] (default: as set)")
    args = parser.parse_args()
    if args.switch_interval_ms is not None:
        sys.setswitchinterval(args.switch_interval_ms * 1e-3)
    logging.getLogger("websockets").setLevel(logging.CRITICAL)   # the killed browser's socket
    seconds = max(1, round(args.phase_s / PATTERN_S)) * PATTERN_S
    robot = load_robot("er20")
    sim = simulated_session(robot, record_s=60.0, timing_window=round(seconds * 1000) + 2000,
                            rt_priority=args.rt_priority)
    live, hand = sim.live, sim.hand
    policy = "SCHED_OTHER" if args.rt_priority is None else f"SCHED_FIFO {args.rt_priority}"
    print(f"er20 on the simulator, real time; {seconds:g} s per phase; python "
          f"{sys.version.split()[0]}, switch interval {sys.getswitchinterval() * 1e3:g} ms; "
          f"loop thread {policy}")
    live.start()
    live.send(SetEnable(True))
    time.sleep(2.0)                                   # tare, then guiding
    phases = [run_phase("alone", live, hand, seconds)]
    with tempfile.TemporaryDirectory() as tmp:
        pendant = Pendant(live, Path(tmp) / "out", hand=hand, port=args.port)
        pendant.start()
        phases.append(run_phase("pendant", live, hand, seconds))
        reader = _reader(pendant.url)
        try:
            if not wait_for_clients(pendant, 1, 30.0):
                raise SystemExit("the reading client did not connect to the pendant")
            phases.append(run_phase("reader", live, hand, seconds))
        finally:
            reader.kill()
            reader.wait(10)
        time.sleep(1.0)
        browser = _chromium(pendant.url, Path(tmp) / "profile")
        try:
            if not wait_for_clients(pendant, 1, 60.0):
                raise SystemExit("Chromium did not connect to the pendant")
            time.sleep(3.0)                           # the page loads its scene
            phases.append(run_phase("browser", live, hand, seconds))
            os.killpg(browser.pid, signal.SIGSTOP)
            phases.append(run_phase("frozen", live, hand, seconds))
        finally:
            os.killpg(browser.pid, signal.SIGCONT)
            os.killpg(browser.pid, signal.SIGTERM)
            browser.wait(10)
        pendant.stop()
    phases.append(run_phase("alone again", live, hand, seconds))
    live.stop()
    report(phases)


if __name__ == "__main__":
    main()
