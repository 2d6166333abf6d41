"""The recording streamed to disk in chunks (session/session_file.py): the same rows, events
and settings as the recording kept in memory, read back by load_session; bounded chunks."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from leadthrough.errors import DataError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.session.recorder import RecordChunk, SessionRecorder
from leadthrough.session.session_file import SessionFileSink
from leadthrough.session_format import SessionEvent, SessionLog, load_session
from leadthrough.sim.driver import InputScript, SimDriver
from leadthrough.sim.robot import SimConfig, SimRobot


def _session(robot: Robot, params: ParamsFile, sink: SessionFileSink | None) -> SessionLog | None:
    sim = SimDriver(SimRobot(robot, SimConfig(seed=1), q0=guide_start_pose(robot)))
    sim.script_input(InputScript(0, ((1.2, math.inf),)))
    sim.script_input(InputScript(1, ((1.5, 1.52), (1.8, 1.82))))
    parts = build_loop(robot, params, LoopConfig(), sim.dt)
    return run_session(sim, *parts, 2.0, options=LoopOptions(enable_input=0, mark_input=1),
                       settings={"driver": "sim"}, sink=sink).log


def test_streamed_file_holds_what_memory_holds(er20: Robot, nominal_params: ParamsFile,
                                               tmp_path: Path) -> None:
    """Chunks of 300 rows (7 of them for 2 s at 1 kHz, the last partly filled; 8 in the pool):
    the file read back equals the in-memory recording of the same session, marks and
    transitions included; no row dropped; the writer process has ended."""
    memory = _session(er20, nominal_params, None)
    path = tmp_path / "s.parquet"
    with SessionFileSink(path, er20.n, chunk_rows=300, chunks=8) as sink:
        assert _session(er20, nominal_params, sink) is None
    assert memory is not None and path.exists() and not sink.partial.exists()
    disk = load_session(path)
    assert sink.rows_written == memory.time.size == disk.time.size
    for name in ("time", "q", "current", "tau_ext", "q_cmd", "qd_cmd", "tcp_cmd_base",
                 "tcp_cmd_quat", "twist_cmd_base", "state", "fault"):
        np.testing.assert_array_equal(getattr(disk, name), getattr(memory, name), err_msg=name)
    assert disk.events == memory.events and len(disk.marks) == 2
    assert disk.settings == {"driver": "sim"}
    assert sink.dropped_rows == 0
    assert not Path(f"/proc/{sink.writer_pid}").exists()


def test_sink_refuses_a_bad_path_or_pool(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="suffix"):
        SessionFileSink(tmp_path / "s.csv", 6)
    with pytest.raises(DataError, match="folder"):
        SessionFileSink(tmp_path / "nowhere" / "s.parquet", 6)
    with pytest.raises(DataError, match="chunks") as info:
        SessionFileSink(tmp_path / "s.parquet", 6, chunks=1)
    assert info.value.value == 1


def _fill(chunk: RecordChunk, value: float) -> None:
    chunk.time[:] = value
    chunk.q[:] = value
    chunk.rot[:] = np.eye(3)
    chunk.rows = chunk.size


def _drain(sink: SessionFileSink, timeout_s: float = 30.0) -> None:
    """Wait until the writer has returned every chunk handed to it."""
    end = time.monotonic() + timeout_s
    while sink.pending() and time.monotonic() < end:
        time.sleep(0.002)
    assert sink.pending() == 0, "the writer did not return its chunks"


def test_chunks_are_recycled_not_accumulated(tmp_path: Path) -> None:
    """100 chunks through a pool of 3, each written before the next is handed over: the loop
    only ever fills the pool's 3 chunks; a chunk not from the sink is copied into one of them
    (and one of another layout dropped and counted); every row reaches the file in order."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=50, chunks=3) as sink:
        chunk = sink.empty()
        seen = {id(chunk)}
        for k in range(100):
            _fill(chunk, k)
            chunk = sink.take(chunk)
            seen.add(id(chunk))
            _drain(sink)
        foreign = RecordChunk(50, 6, False)
        _fill(foreign, 100)
        assert sink.take(foreign) is not foreign and foreign.rows == 0
        other = RecordChunk(50, 7, False)
        _fill(other, 101)
        sink.take(other)
        assert sink.dropped_rows == 50
        sink.finish("er20", [], {})
    assert len(seen) == 3
    disk = load_session(tmp_path / "s.parquet")
    np.testing.assert_array_equal(disk.time, np.repeat(np.arange(101.0), 50))
    np.testing.assert_array_equal(disk.q[:, 3], disk.time)
    assert disk.settings == {"recording_rows_dropped": 50}


def test_the_loop_side_never_waits_for_the_writer(tmp_path: Path) -> None:
    """The writer process stopped (SIGSTOP) while the loop hands over 30 chunks: each hand-over
    returns at once; once the pool of 4 is out, the rows are dropped and counted (no memory
    mapped in the loop); the writer, running again, writes the 4 it holds and the file says
    how many rows were dropped."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100, chunks=4) as sink:
        os.kill(sink.writer_pid, signal.SIGSTOP)
        try:
            chunk = sink.empty()
            longest = 0.0
            for k in range(30):
                _fill(chunk, k)
                t = time.perf_counter()
                chunk = sink.take(chunk)
                longest = max(longest, time.perf_counter() - t)
        finally:
            os.kill(sink.writer_pid, signal.SIGCONT)
        assert longest < 0.5 and sink.dropped_rows == (30 - 4) * 100
        _drain(sink)             # the loop holds the scratch chunk: every pooled one comes back
        sink.finish("er20", [], {})
    disk = load_session(tmp_path / "s.parquet")
    np.testing.assert_array_equal(disk.time, np.repeat(np.arange(4.0), 100))
    assert disk.settings == {"recording_rows_dropped": 2600}


def test_the_writer_is_a_background_process_that_ignores_stop_signals(tmp_path: Path) -> None:
    """The writer runs in its own process and session at a lower priority (nice + 10 on ours),
    and ignores SIGINT, SIGTERM and SIGHUP (a Ctrl-C or a service manager's stop is the loop's
    stop request): it still finishes the file, and has exited afterwards."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        pid = sink.writer_pid
        assert pid != os.getpid() and os.getsid(pid) != os.getsid(0)
        nice = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16])
        assert nice == min(19, os.getpriority(os.PRIO_PROCESS, 0) + 10)
        for stop in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            os.kill(pid, stop)
        chunk = sink.empty()
        _fill(chunk, 1.0)
        sink.take(chunk)
        sink.finish("er20", [], {"k": 1})
    assert load_session(tmp_path / "s.parquet").settings == {"k": 1}
    assert not Path(f"/proc/{pid}").exists()


def test_a_writer_that_dies_stops_the_recording_not_the_loop(tmp_path: Path) -> None:
    """The writer killed mid-session: hand-overs go on without error, into one scratch chunk
    (emptied each time), and finish raises a DataError naming the partial file."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        chunk = sink.empty()
        _fill(chunk, 1.0)
        chunk = sink.take(chunk)
        os.kill(sink.writer_pid, signal.SIGKILL)
        time.sleep(0.2)
        returned = set()
        for _ in range(10):
            _fill(chunk, 2.0)
            chunk = sink.take(chunk)
            assert chunk.rows == 0
            returned.add(id(chunk))
        assert len(returned) == 1
        with pytest.raises(DataError, match="writer process ended") as info:
            sink.finish("er20", [], {})
    assert info.value.source == str(sink.partial)
    assert not (tmp_path / "s.parquet").exists()


def test_a_file_that_cannot_be_written_is_a_clear_error(tmp_path: Path) -> None:
    """The partial file's place taken by a folder: the writer cannot open it, the recording
    stops, and finish raises a DataError with the OS's or Arrow's reason."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        sink.partial.mkdir()
        chunk = sink.empty()
        _fill(chunk, 1.0)
        sink.take(chunk)
        with pytest.raises(DataError, match=r"not finished .*Error"):
            sink.finish("er20", [], {})


def test_settings_that_are_not_json_are_a_clear_error(tmp_path: Path) -> None:
    with (SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink,
          pytest.raises(DataError, match="not JSON") as info):
        sink.finish("er20", [], {"where": tmp_path})
    assert info.value.field == "settings"


def test_a_long_session_s_events_reach_the_file(tmp_path: Path) -> None:
    """8000 events (a shift of presses, marks and notes: a metadata message far larger than
    the socket's buffer) are finished into the file."""
    events = [SessionEvent(t=0.01 * k, kind="mark", label=f"P{k}") for k in range(8000)]
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        chunk = sink.empty()
        _fill(chunk, 1.0)
        sink.take(chunk)
        sink.finish("er20", events, {})
    assert load_session(tmp_path / "s.parquet").events == events


def test_leaving_without_finish_closes_what_was_written(tmp_path: Path) -> None:
    """The sink left before finish (an error while setting up or running the loop): the writer
    closes the rows it wrote into the partial file (Parquet, without the session's events),
    exits, and no session file appears."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        pid = sink.writer_pid
        chunk = sink.empty()
        _fill(chunk, 3.0)
        sink.take(chunk)
        _drain(sink)
    assert not Path(f"/proc/{pid}").exists()
    assert not (tmp_path / "s.parquet").exists()
    assert pq.read_table(sink.partial).column("t").to_pylist() == [3.0] * 100


def test_the_writer_ends_when_the_loop_s_process_dies(tmp_path: Path) -> None:
    """The loop's process killed outright after one chunk was written: its writer sees the
    link end, closes the rows into the partial file and exits (no orphan left running)."""
    script = (
        "import os, sys, time, numpy as np\n"
        "from leadthrough.session.session_file import SessionFileSink\n"
        f"sink = SessionFileSink({str(tmp_path / 's.parquet')!r}, 6, chunk_rows=100)\n"
        "c = sink.empty(); c.rot[:] = np.eye(3); c.time[:] = 4.0; c.rows = 100\n"
        "sink.take(c)\n"
        "end = time.monotonic() + 30\n"
        "while sink.pending() and time.monotonic() < end: time.sleep(0.01)\n"
        "print(sink.writer_pid, flush=True)\n"
        "os.kill(os.getpid(), 9)\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=120, check=False)
    assert out.returncode == -signal.SIGKILL, out.stderr
    pid = int(out.stdout.split()[0])
    end = time.monotonic() + 10.0
    while Path(f"/proc/{pid}").exists() and time.monotonic() < end:
        time.sleep(0.05)
    assert not Path(f"/proc/{pid}").exists()
    partial = tmp_path / "s.parquet.partial"
    assert pq.read_table(partial).column("t").to_pylist() == [4.0] * 100


def test_a_recorder_refuses_a_sink_of_another_layout(tmp_path: Path) -> None:
    with (SessionFileSink(tmp_path / "s.parquet", 7, chunk_rows=100) as sink,
          pytest.raises(DataError, match="another robot") as info):
        SessionRecorder(6, False, sink)
    assert info.value.value == 7
def test_chunk_arrays_are_views_of_one_memory_block() -> None:
    """A chunk over a given buffer: another chunk over the same bytes (the writer's side)
    sees every array the first one writes, at the same rows; the orientations convert as
    SciPy's in one call; an empty chunk has none."""
    rows = 37
    memory = bytearray(RecordChunk.nbytes(rows, 6, True))
    a, b = RecordChunk(rows, 6, True, memory), RecordChunk(rows, 6, True, memory)
    rng = np.random.default_rng(2)
    for name in ("time", "q", "current", "tau_ext", "wrench", "q_cmd", "qd_cmd", "tcp",
                 "twist", "applied"):
        getattr(a, name)[:] = rng.normal(size=getattr(a, name).shape)
    a.rot[:] = Rotation.random(rows, rng=3).as_matrix()
    a.state[:] = np.arange(rows)
    a.fault[:] = -np.arange(rows)
    for name in ("time", "q", "current", "tau_ext", "wrench", "q_cmd", "qd_cmd", "tcp", "rot",
                 "twist", "applied", "state", "fault"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    b.rows = rows
    np.testing.assert_array_equal(b.quaternions(), Rotation.from_matrix(a.rot).as_quat())
    assert RecordChunk(5, 6, False).quaternions().shape == (0, 4)
