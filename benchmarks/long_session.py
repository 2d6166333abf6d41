"""A long guiding session over the wire: timing (issue 25, must show 5) and memory (must show
6).

``leadthrough emulate`` (its own process; the enabling device pressed for 20 s every 30 s, the
mark button once per press) and ``leadthrough guide --driver`` (its own process, recording
streamed to disk by its writer process) for ``--minutes``; the resident memory (VmRSS) of the
guide process and of its writer is read from /proc every 10 s. At the end the guide stops by
its ``--duration``, then ``leadthrough teach`` loads the recording. It prints:

* timing: the servo periods the guide ran and those it ran late (its clock), the controller
  cycles the emulated controller ran without a fresh command (its count: RSI's ``Delay``, J519
  statuses left unanswered, the RTDE program's counter unchanged), the emulator's own largest
  lag behind the wall clock, and the first controller cycle's compute time against the
  median (the first is kept for sessions up to ten minutes);
* attribution (the emulator's ``timing.*``, :mod:`leadthrough.sim.emulators.answer_timing`):
  every answer timed by the kernel's receive stamp against the status packet's actual send:
  answers in time, late (after send + one cycle) and never answered, and of those the ones
  that coincide with the emulator's own lag; the statuses the emulator sent late (more than
  1 ms behind its schedule) and the cycle slots its resynchronisations skipped;
* the machine: the CPU time the hypervisor took from this virtual machine during the session
  (steal, ``benchmarks/machine_jitter.py``: 0 on bare metal), and its stalls: a probe per CPU
  (``machine_jitter.py --cpu C``, ``SCHED_FIFO`` ten above ``--rt-priority``, 60 without it)
  sleeps 1 ms at a time beside the session and logs each wake-up more than 1 ms late, a
  stretch in which nothing of ours could run on that CPU. Each late or missing answer that
  is not the emulator's lag is then matched against them: one that overlaps a stall may be
  the machine's; one that does not is the client's own (the loop, its process, the OS
  scheduling them). The probes wake 1000 times a second each and preempt the session for a few
  microseconds every time (``--no-probe``: without them);
* memory: RSS after the first minute (set-up done), at the end, the growth, of the guide and
  of its session writer process (the chunks they share count in both); the file's size;
  ``teach``'s answer; the emulator's report (all of it, with the client's windows, in
  ``emulator_report.txt`` under ``--out``).

``--rt-priority P`` runs both processes with ``SCHED_FIFO`` priority P (the guide by its own
option, the emulator set from here): the figures of a loaded machine. Default: ordinary
scheduling, the figures of an idle machine. ``--pin`` runs the guide on the last CPU (its own
``--cpus``; its session writer, started before the real-time set-up, is not pinned) and the
emulator on the first, so that the two never share a CPU (a real controller is another
computer).

    python benchmarks/long_session.py [--minutes 60] [--kind kuka-rsi] [--rt-priority P]
        [--out DIR] [--no-probe] [--pin] [--lock-memory]
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import select
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from leadthrough.drivers.controllers import DEFAULT_PORTS
from leadthrough.sim.emulators.process import (
    emulator_report,
    spawn_emulator,
    stop_emulator,
    timing_summary,
)
from machine_jitter import load_stalls, steal_seconds

#: A probe's wake-up later than this is a stall of the machine [ms].
PROBE_THRESHOLD_MS = 1.0


def _lt(*args: str) -> list[str]:
    return [sys.executable, "-m", "leadthrough", *args]


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _children(pid: int) -> list[int]:
    """The processes ``pid`` started (its session writer)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(c) for c in (task / "children").read_text().split()]
    return out


def _wait_for(proc: subprocess.Popen[str], text: str, timeout: float) -> str:
    """Read ``proc``'s stderr until a line holds ``text`` (or it ends, or ``timeout`` [s]);
    returns what was read."""
    assert proc.stderr is not None
    read, end = "", time.monotonic() + timeout
    while time.monotonic() < end:
        ready, _, _ = select.select([proc.stderr], [], [], max(0.0, end - time.monotonic()))
        line = proc.stderr.readline() if ready else ""
        read += line
        if not line or text in line:
            break
    return read


def _emulator(kind: str, port: int, minutes: float, rt_priority: int | None,
              cpu: int | None) -> subprocess.Popen[str]:
    presses: list[str] = []
    for k in range(int(minutes * 2) + 2):
        a = 5.0 + 30.0 * k
        presses += ["--enable", f"{a}:{a + 20}", "--mark", f"{a + 2}:{a + 2.2}"]
    emu = spawn_emulator(kind, "er20", "127.0.0.1", port, "--seed", "3", *presses,
                         timeout=120.0)
    if rt_priority is not None:
        os.sched_setscheduler(emu.pid, os.SCHED_FIFO, os.sched_param(rt_priority))
    if cpu is not None:
        os.sched_setaffinity(emu.pid, {cpu})
    return emu


def _probes(out: Path, seconds: float, rt_priority: int | None
            ) -> list[tuple[int, Path, subprocess.Popen[str]]]:
    """One ``machine_jitter.py`` probe per CPU, above the session's priority."""
    priority = min(99, (rt_priority or 50) + 10)
    script = Path(__file__).with_name("machine_jitter.py")
    probes = []
    for cpu in sorted(os.sched_getaffinity(0)):
        path = out / f"probe_cpu{cpu}.json"
        cmd = [sys.executable, str(script), "--seconds", f"{seconds:g}", "--cpu", str(cpu),
               "--rt-priority", str(priority), "--events", str(path), "--threshold-ms",
               f"{PROBE_THRESHOLD_MS:g}"]
        probes.append((cpu, path, subprocess.Popen(cmd, stdout=subprocess.PIPE,
                                                   stderr=subprocess.STDOUT, text=True)))
    return probes


def _stop_probes(probes: list[tuple[int, Path, subprocess.Popen[str]]]
                 ) -> tuple[dict[int, list[tuple[float, float]]], list[int]]:
    """End the probes (all signalled first); print what each measured. Returns their stalls per
    CPU (wall clock) and the CPUs whose probe failed (no file: its stalls are unknown)."""
    for _, _, proc in probes:
        if proc.poll() is None:
            proc.terminate()
    stalls: dict[int, list[tuple[float, float]]] = {}
    failed: list[int] = []
    for cpu, path, proc in probes:
        try:
            text, _ = proc.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            text, _ = proc.communicate()
        print(f"probe, CPU {cpu}: {' '.join(text.split())}")
        if proc.returncode == 0 and path.exists():
            stalls[cpu] = load_stalls(path)
        else:
            failed.append(cpu)
    return stalls, failed


def match_stalls(windows: list[tuple[float, float]],
                 stalls: dict[int, list[tuple[float, float]]]
                 ) -> tuple[list[tuple[float, float]], dict[int, int]]:
    """The client's late or missing answers (their wall-clock windows) against the machine's
    stalls per CPU (wall-clock stretches): the windows that overlap no stall, and per CPU how
    many windows overlap one of its stalls."""
    per_cpu = {cpu: 0 for cpu in stalls}
    own: list[tuple[float, float]] = []
    for start, end in windows:
        hit = [cpu for cpu, st in stalls.items() if any(a < end and b > start for a, b in st)]
        for cpu in hit:
            per_cpu[cpu] += 1
        if not hit:
            own.append((start, end))
    return own, per_cpu


def longest_stall(window: tuple[float, float], stalls: dict[int, list[tuple[float, float]]]
                  ) -> tuple[int, float] | None:
    """The longest stall (its CPU, its length [s]) that overlaps ``window`` (wall clock [s]),
    or None: how much of a late answer the machine's stall can explain."""
    start, end = window
    hits = [(b - a, cpu) for cpu, st in stalls.items() for a, b in st if a < end and b > start]
    if not hits:
        return None
    length, cpu = max(hits)
    return cpu, length


def _stall_line(windows: list[tuple[float, float]], total: int,
                stalls: dict[int, list[tuple[float, float]]], failed: list[int],
                wall0: float) -> str:
    """:func:`match_stalls` in a line (``total``: the client's late or missing answers, of
    which ``windows`` are the first; times from ``wall0``, the session's start)."""
    if not stalls:
        return "machine stalls: not measured (no probe)"
    own, per_cpu = match_stalls(windows, stalls)
    caveats = ""
    if failed:
        caveats += (f" INCOMPLETE: no probe on CPU {failed}, so some answers counted as the "
                    f"client's own may be the machine's;")
    if len(windows) < total:
        caveats += f" only the first {len(windows)} of {total} windows were kept;"
    counts = ", ".join(f"CPU {cpu}: {len(st)} (longest "
                       f"{max((b - a for a, b in st), default=0.0) * 1e3:.1f} ms)"
                       for cpu, st in stalls.items())
    shown = own if len(own) <= 20 else own[:15] + own[-5:]
    which = "" if len(own) <= 20 else ", the first 15 and the last 5"
    first = ", ".join(f"{(s - wall0):.3f} s +{(e - s) * 1e3:.1f} ms" for s, e in shown)
    machine = [(w, longest_stall(w, stalls)) for w in windows if w not in own][:20]
    theirs = ", ".join(f"{(w[0] - wall0):.3f} s +{(w[1] - w[0]) * 1e3:.1f} ms: CPU {hit[0]} "
                       f"stalled {hit[1] * 1e3:.1f} ms" for w, hit in machine if hit)
    return (f"machine stalls (a probe woke > {PROBE_THRESHOLD_MS:g} ms late): {counts};"
            f"{caveats} the client's late or missing answers (not the emulator's lag): {total}, "
            f"of the {len(windows)} matched "
            f"overlapping a stall {len(windows) - len(own)} (per CPU "
            f"{', '.join(f'{c}: {n}' for c, n in per_cpu.items())}"
            + (f"; the longest stall each overlaps: {theirs}" if theirs else "")
            + "), **not overlapping any: "
            f"{len(own)}**" + (f" (from the session's start{which}: {first})" if own else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--kind", default="kuka-rsi", choices=sorted(DEFAULT_PORTS))
    ap.add_argument("--params", type=Path, default=None,
                    help="params file (default: the shipped er20 parameters)")
    ap.add_argument("--rt-priority", type=int, default=None, metavar="P",
                    help="SCHED_FIFO priority of the guide and the emulator")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--no-probe", action="store_true",
                    help="no machine probes beside the session")
    ap.add_argument("--pin", action="store_true",
                    help="the guide on the last CPU, the emulator on the first")
    ap.add_argument("--lock-memory", action="store_true",
                    help="the guide with --lock-memory (mlockall: no page faults in the loop)")
    args = ap.parse_args()
    cpus = sorted(os.sched_getaffinity(0))
    if args.pin and len(cpus) < 2:
        ap.error(f"--pin needs two CPUs, this process may use {cpus}")
    guide_cpu, emu_cpu = (cpus[-1], cpus[0]) if args.pin else (None, None)
    from leadthrough.sim.guiding_params import shipped_params_path

    params = args.params or shipped_params_path("er20")
    out = args.out or Path(tempfile.mkdtemp(prefix="lt-long-"))
    out.mkdir(parents=True, exist_ok=True)
    session = out / "long.parquet"
    port = DEFAULT_PORTS[args.kind] + 200
    guide_cmd = _lt("guide", "--driver", args.kind, "--host", "127.0.0.1", "--port", str(port),
                    "--robot", "er20", "--params", str(params), "--enable-input", "0",
                    "--mark-input", "1", "--watchdog", "0.5", "--duration",
                    str(60.0 * args.minutes), "-o", str(session), "--json")
    if args.rt_priority is not None:
        guide_cmd += ["--rt-priority", str(args.rt_priority)]
    if guide_cpu is not None:
        guide_cmd += ["--cpus", str(guide_cpu)]
    if args.lock_memory:
        guide_cmd += ["--lock-memory"]
    probes = [] if args.no_probe else _probes(out, 60.0 * args.minutes + 900.0,
                                              args.rt_priority)
    try:
        run = _session(args, guide_cmd, port, emu_cpu)
    finally:
        stalls, failed = _stop_probes(probes)
    _report(args, out, session, run, stalls, failed)


@dataclass
class _Run:
    """What a session left: the emulator's report, the guide's output (its stderr with what it
    printed before the emulator started), memory samples (s, MB) of the guide and its writer,
    the machine's steal [s] and the session's start on the wall clock [s]."""

    report: str
    stdout: str
    stderr: str
    samples: list[tuple[float, float]]
    writer: list[tuple[float, float]]
    steal: float
    wall0: float


def _session(args: argparse.Namespace, guide_cmd: list[str], port: int,
             emu_cpu: int | None) -> _Run:
    """Run the emulator and the guide until the guide ends; sample their memory."""
    emu = None
    if args.kind != "kuka-rsi":
        emu = _emulator(args.kind, port, args.minutes, args.rt_priority, emu_cpu)
    guide = subprocess.Popen(guide_cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    early_stderr = ""
    if emu is None:  # RSI: the PC listens (after compiling), then the robot sends
        early_stderr = _wait_for(guide, "compiling the loop done", timeout=300.0)
        emu = _emulator(args.kind, port, args.minutes, args.rt_priority, emu_cpu)
    t0, steal0, wall0 = time.monotonic(), steal_seconds(), time.time()
    samples: list[tuple[float, float]] = []
    writer: list[tuple[float, float]] = []
    while guide.poll() is None:
        try:
            t = time.monotonic() - t0
            samples.append((t, _rss_mb(guide.pid)))
            kids = _children(guide.pid)
            if kids:
                writer.append((t, sum(_rss_mb(k) for k in kids)))
        except (FileNotFoundError, ProcessLookupError):
            break
        time.sleep(10.0)
    stdout, stderr = guide.communicate()
    steal = steal_seconds() - steal0
    report = stop_emulator(emu, timeout=30.0)
    return _Run(report, stdout, early_stderr + stderr, samples, writer, steal, wall0)


def _report(args: argparse.Namespace, out: Path, session: Path, run: _Run,
            stalls: dict[int, list[tuple[float, float]]], failed: list[int]) -> None:
    """Print the figures; write the memory samples and the emulator's report under ``out``."""
    report, stdout, samples, writer = run.report, run.stdout, run.samples, run.writer
    result = (json.loads(stdout) if stdout.strip().startswith("{")
              else {"stderr": run.stderr})
    after = [m for s, m in samples if s >= 60.0]
    first = after[0] if after else float("nan")
    teach = subprocess.run(_lt("teach", str(session), "--robot", "er20", "--no-line", "-o",
                               str(out / "taught.json")), capture_output=True, text=True,
                           check=False)
    print(f"{args.kind}, {args.minutes:g} min: RSS after 1 min {first:.1f} MB, max "
          f"{max(after, default=float('nan')):.1f} MB, at the end "
          f"{after[-1] if after else float('nan'):.1f} MB: growth "
          f"{(after[-1] - first) if after else float('nan'):+.1f} MB (goal <= 50 MB)")
    w_after = [m for s, m in writer if s >= 60.0]
    if w_after:
        print(f"session writer process: RSS after 1 min {w_after[0]:.1f} MB, at the end "
              f"{w_after[-1]:.1f} MB: growth {w_after[-1] - w_after[0]:+.1f} MB (the chunks "
              f"it shares with the guide count in both)")
    print(f"recording {session}: {session.stat().st_size / 1e6:.1f} MB" if session.exists()
          else "no recording")
    if "periods" in result:
        emu_fields = emulator_report(report)
        print(f"timing: {result['periods']} periods, {result['late_periods']} late (guide); "
              f"{emu_fields.get('missed_cycles', '?')} controller cycles without a fresh "
              f"command (emulator; its largest lag {emu_fields.get('max_lag', '?')} s); "
              f"first controller cycle {result['cycle_us_first']:.0f} µs, median "
              f"{result['cycle_us_median']:.0f} µs: ratio "
              f"{result['cycle_us_first'] / result['cycle_us_median']:.2f} (goal <= 2), "
              f"p99 {result['cycle_us_p99']:.0f} µs, max {result['cycle_us_max']:.0f} µs")
        print(timing_summary(emu_fields))
        print(f"machine: steal {run.steal:.2f} s over the session (CPU time the hypervisor took "
              f"from this virtual machine: a late answer may be the machine's; "
              f"benchmarks/machine_jitter.py measures it alone)")
        windows = ast.literal_eval(emu_fields.get("timing.client_windows", "()"))
        def count(name: str) -> int:
            return int(emu_fields.get(f"timing.{name}", "0"))

        total = (count("late") - count("late_with_lag")) + (count("never")
                                                             - count("never_with_lag"))
        print(_stall_line([(float(a), float(b)) for a, b in windows], total, stalls, failed,
                          run.wall0))
    print(f"guide: {json.dumps(result)}")
    print(f"teach: exit {teach.returncode}: {(teach.stdout + teach.stderr).strip()[:400]}")
    print("emulator: " + " ".join(" ".join(line.split()) for line in report.splitlines()
                                  if not line.startswith("timing.client_windows")))
    (out / "rss.json").write_text(json.dumps({"guide": samples, "writer": writer}))
    (out / "emulator_report.txt").write_text(report)


if __name__ == "__main__":
    main()
