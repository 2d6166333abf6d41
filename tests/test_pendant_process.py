"""The loop's process and the pendant's: their lifetimes and the shared memory between them.

* the snapshot record (a sequence lock over shared memory): a writer in another process
  rewrites it as fast as it can while this one reads; every record read must be whole (its
  numbers' own checksum field, and its byte string, rewritten every fifth record, from the
  same write as its numbers);
* the pendant's process killed: the loop's process sees its pipe close, releases the enabling
  input (a commanded stop), comes to rest and exits, saying so;
* the pendant's process exiting without stopping the loop: the loop's process ends with it (no
  orphan).
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.pendant.shared_state import SeqlockRecord, SharedBlock

SRC = Path(__file__).resolve().parent.parent / "src"

#: Rewrites the record named argv[1] (argv[2] numbers, blob capacity argv[3]) for argv[4] s:
#: numbers[0] is the write's number, the last one the sum of the others; every fifth write
#: also writes the blob (the write's number and that sum, padded to a varying length).
WRITER = """
import pickle, sys, time
import numpy as np
from leadthrough.pendant.shared_state import SeqlockRecord, SharedBlock
block = SharedBlock(name=sys.argv[1])
n, cap, seconds = int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
record = SeqlockRecord(block, n, cap)
rng = np.random.default_rng(0)
values = np.zeros(n)
k, end = 0, time.monotonic() + seconds
while time.monotonic() < end:
    k += 1
    values[:-1] = rng.normal(size=n - 1)
    values[0] = k
    values[-1] = values[:-1].sum()
    blob = None
    if k % 5 == 0:
        blob = pickle.dumps((k, values[-1], b"x" * (k % (cap // 2))))
    record.write(values, blob)
print(k)
"""


@settings(max_examples=3, deadline=None)
@given(st.integers(4, 600), st.sampled_from([1024, 65536]))
def test_a_snapshot_read_while_written_is_never_torn(numbers: int, blob_bytes: int) -> None:
    block = SharedBlock(SeqlockRecord.size(numbers, blob_bytes))
    record = SeqlockRecord(block, numbers, blob_bytes)
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    writer = subprocess.Popen([sys.executable, "-c", WRITER, block.name, str(numbers),
                               str(blob_bytes), "3.0"], env=env, stdout=subprocess.PIPE,
                              text=True)
    try:
        whole, seen = 0, set()
        while writer.poll() is None:
            got = record.read()
            if got is None:
                continue
            seq, values, blob = got
            assert values[-1] == values[:-1].sum()            # the numbers' checksum field
            k = int(values[0])
            if k >= 5:
                blob_k, blob_sum, _ = pickle.loads(blob)
                assert blob_k == k - k % 5                    # the blob of the same write
                if blob_k == k:
                    assert blob_sum == values[-1]
            whole += 1
            seen.add(seq)
        written = int(writer.communicate(timeout=10)[0])
    finally:
        writer.kill()
        writer.wait()
        block.close()
    assert written > 10_000 and whole > 1000 and len(seen) > 100


def test_an_unwritten_record_reads_as_none() -> None:
    block = SharedBlock(SeqlockRecord.size(4, 16))
    try:
        record = SeqlockRecord(block, 4, 16)
        assert record.read() is None
        record.write(np.arange(4.0), b"abc")
        seq, values, blob = record.read() or (0, np.zeros(0), b"")
        assert seq == 2 and np.array_equal(values, np.arange(4.0)) and blob == b"abc"
        with pytest.raises(ValueError, match="capacity 16"):
            record.write(np.arange(4.0), b"y" * 17)
    finally:
        block.close()


#: The pendant's process: starts a guided session pushed along y, says so, then is killed
#: (``kill``) or, told to on its standard input, exits without stopping the loop (``exit``).
PARENT = """
import sys, time
from leadthrough.control.safety import State
from leadthrough.pendant.backend import SetEnable
from leadthrough.pendant.simulated import simulated_session
from leadthrough.robot import load_robot

if __name__ == "__main__":
    sim = simulated_session(load_robot("er20"), record_s=10.0)
    sim.live.start()
    from leadthrough.estimation.estimator import EstimatorStatus
    ready = time.monotonic() + 60.0                   # the estimator's warm-up and tare, on
    while sim.live.snapshot().estimator != EstimatorStatus.OK:   # the loop's clock: a press
        assert time.monotonic() < ready               # before it needs a fresh one
        time.sleep(0.02)
    sim.live.send(SetEnable(True))
    sim.hand.push([0.0, 40.0, 0.0])
    end = time.monotonic() + 60
    while time.monotonic() < end:
        snap = sim.live.snapshot()
        if snap.state == State.GUIDING and snap.speed > 0.05:
            break
        time.sleep(0.01)
    print(sim.live.pid, snap.state.name, flush=True)
    if sys.argv[1] == "exit":
        sys.stdin.readline()
        sys.exit(0)
    time.sleep(600)
"""


def _gone(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] == "Z"      # a zombie has ended


@pytest.mark.parametrize("how", ["kill", "exit"])
def test_the_loop_stops_when_the_pendant_goes(how: str, tmp_path: Path) -> None:
    script = tmp_path / "pendant_parent.py"
    script.write_text(textwrap.dedent(PARENT))
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    parent = subprocess.Popen([sys.executable, str(script), how], env=env,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    child = 0
    try:
        assert parent.stdout is not None
        line = parent.stdout.readline().split()
        assert len(line) == 2, parent.communicate(timeout=30)
        child, state = int(line[0]), line[1]
        assert state == "GUIDING" and not _gone(child)
        if how == "kill":
            parent.send_signal(signal.SIGKILL)
        _, err = parent.communicate("\n", timeout=60)       # the child shares the parent's stderr
        deadline = time.monotonic() + 10
        while not _gone(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _gone(child)
        if how == "kill":
            said = [line for line in err.splitlines() if line.startswith("leadthrough loop:")]
            assert len(said) == 1, err                # the pipe's end or the parent's exit
            assert said[0].split(": ", 1)[1].startswith((
                "the pendant's link closed: commanded stop; IDLE at rest",
                "the pendant's process ended: commanded stop; IDLE at rest")), err
        else:
            assert parent.returncode == 0, err
    finally:
        parent.kill()
        if child and not _gone(child):
            os.kill(child, signal.SIGKILL)
