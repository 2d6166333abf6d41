"""The recording streamed to disk in chunks (session/session_file.py): the same rows, events
and settings as the recording kept in memory, read back by load_session; bounded chunks."""

from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from leadthrough.errors import DataError
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot import Robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.session.loop import run_session
from leadthrough.session.loop_config import LoopConfig, LoopOptions, build_loop
from leadthrough.session.record import SessionLog, load_session
from leadthrough.session.recorder import RecordChunk
from leadthrough.session.session_file import SessionFileSink
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
    """Chunks of 300 rows (7 of them for 2 s at 1 kHz, the last partly filled): the file read
    back equals the in-memory recording of the same session, marks and transitions
    included; the loop recycled its chunks (none allocated beyond the spares)."""
    memory = _session(er20, nominal_params, None)
    path = tmp_path / "s.parquet"
    sink = SessionFileSink(path, er20.n, chunk_rows=300)
    assert _session(er20, nominal_params, sink) is None
    assert memory is not None and path.exists() and not sink.partial.exists()
    disk = load_session(path)
    assert sink.rows_written == memory.time.size == disk.time.size
    for name in ("time", "q", "current", "tau_ext", "q_cmd", "qd_cmd", "tcp_cmd_base",
                 "tcp_cmd_quat", "twist_cmd_base", "state", "fault"):
        np.testing.assert_array_equal(getattr(disk, name), getattr(memory, name), err_msg=name)
    assert disk.events == memory.events and len(disk.marks) == 2
    assert disk.settings == {"driver": "sim"}
    assert sink.extra_chunks == 0
    assert not Path(f"/proc/{sink.writer_pid}").exists()   # the writer process has ended


def test_sink_refuses_a_bad_path(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="suffix"):
        SessionFileSink(tmp_path / "s.csv", 6)
    with pytest.raises(DataError, match="folder"):
        SessionFileSink(tmp_path / "nowhere" / "s.parquet", 6)


def _fill(chunk: RecordChunk, value: float) -> None:
    chunk.time[:] = value
    chunk.q[:] = value
    chunk.rot[:] = np.eye(3)
    chunk.rows = chunk.size


def test_chunks_are_recycled_not_accumulated(tmp_path: Path) -> None:
    """Many chunks through the sink: the chunks handed back to the loop are the few the writer
    returns (100 hand-overs 10 ms apart: fewer than half of them need a new chunk, even with
    the writer process starved on a loaded machine for a while); a chunk not from the sink is
    copied; every row reaches the file in order."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=50)
    chunk = sink.empty()
    seen = set()
    for k in range(100):
        _fill(chunk, k)
        chunk = sink.take(chunk)
        seen.add(id(chunk))
        time.sleep(0.01)
    foreign = RecordChunk(50, 6, False)
    _fill(foreign, 100)
    assert sink.take(foreign) is foreign and foreign.rows == 0
    sink.finish("er20", [], {})
    assert len(seen) <= 4 + sink.extra_chunks < 4 + 50
    disk = load_session(tmp_path / "s.parquet")
    np.testing.assert_array_equal(disk.time, np.repeat(np.arange(101.0), 50))
    np.testing.assert_array_equal(disk.q[:, 3], disk.time)


def test_the_loop_side_never_waits_for_the_writer(tmp_path: Path) -> None:
    """The writer process stopped (SIGSTOP) while the loop hands over 30 chunks: each hand-over
    returns at once with a new chunk (mapped and counted), and once the writer runs again the
    file holds every row."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100)
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
    assert sink.extra_chunks == 30 - 4 + 1 and longest < 0.05
    sink.finish("er20", [], {})
    assert load_session(tmp_path / "s.parquet").time.size == 30 * 100


def test_the_writer_is_a_background_process_that_ignores_ctrl_c(tmp_path: Path) -> None:
    """The writer runs in its own process at a lower priority (nice + 10 on ours) and ignores
    SIGINT (a Ctrl-C reaches the terminal's whole process group; it is the loop's stop
    request): it still finishes the file, and has exited afterwards."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100)
    pid = sink.writer_pid
    assert pid != os.getpid()
    nice = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16])
    assert nice == min(19, os.getpriority(os.PRIO_PROCESS, 0) + 10)
    os.kill(pid, signal.SIGINT)
    chunk = sink.empty()
    _fill(chunk, 1.0)
    sink.take(chunk)
    sink.finish("er20", [], {"k": 1})
    assert load_session(tmp_path / "s.parquet").settings == {"k": 1}
    assert not Path(f"/proc/{pid}").exists()


def test_a_writer_that_dies_stops_the_recording_not_the_loop(tmp_path: Path) -> None:
    """The writer killed mid-session: hand-overs go on without error (the loop's chunk comes
    back emptied), and finish raises a DataError naming the partial file."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100)
    chunk = sink.empty()
    _fill(chunk, 1.0)
    chunk = sink.take(chunk)
    os.kill(sink.writer_pid, signal.SIGKILL)
    time.sleep(0.2)
    for _ in range(10):
        _fill(chunk, 2.0)
        chunk = sink.take(chunk)
        assert chunk.rows == 0
    with pytest.raises(DataError, match="writer process ended") as info:
        sink.finish("er20", [], {})
    assert info.value.source == str(sink.partial)
    assert not (tmp_path / "s.parquet").exists()


def test_a_file_that_cannot_be_written_is_a_clear_error(tmp_path: Path) -> None:
    """The partial file's place taken by a folder: the writer cannot open it, the recording
    stops, and finish raises a DataError with Arrow's or the OS's reason."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100)
    sink.partial.mkdir()
    chunk = sink.empty()
    _fill(chunk, 1.0)
    sink.take(chunk)
    with pytest.raises(DataError, match="could not be written"):
        sink.finish("er20", [], {})


def test_leaving_without_finish_stops_the_writer(tmp_path: Path) -> None:
    """The sink as a context manager left before finish (an error while setting up the
    loop): the writer process is stopped and no session file appears."""
    with SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=100) as sink:
        pid = sink.writer_pid
    assert not Path(f"/proc/{pid}").exists()
    assert not (tmp_path / "s.parquet").exists()


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
