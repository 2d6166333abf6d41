"""The recording streamed to disk in chunks (session/session_file.py): the same rows, events
and settings as the recording kept in memory, read back by load_session; bounded chunks."""

from __future__ import annotations

import math
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
from leadthrough.session.recorder import QUATERNION_SLICE_ROWS, RecordChunk
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


def test_sink_refuses_a_bad_path(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="suffix"):
        SessionFileSink(tmp_path / "s.csv", 6)
    with pytest.raises(DataError, match="folder"):
        SessionFileSink(tmp_path / "nowhere" / "s.parquet", 6)


def test_chunks_are_recycled_not_accumulated(tmp_path: Path) -> None:
    """Many chunks through the sink: the chunk objects handed back to the loop are the few
    recycled ones, whatever the number of chunks written."""
    sink = SessionFileSink(tmp_path / "s.parquet", 6, chunk_rows=50)
    chunk = RecordChunk(50, 6, False)
    seen = set()
    for _ in range(200):
        chunk.time[:] = 1.0
        chunk.rot[:] = np.eye(3)
        chunk.rows = 50
        chunk = sink.take(chunk)
        seen.add(id(chunk))
    sink.finish("er20", [], {})
    assert len(seen) <= 5 + sink.extra_chunks
    assert load_session(tmp_path / "s.parquet").time.size == 200 * 50


def test_chunk_orientations_convert_slice_by_slice_as_in_one_call() -> None:
    """The writer converts a chunk's orientations a slice at a time (the interpreter lock is
    offered between slices): the same quaternions as SciPy in one call, over a partial last
    slice and an empty chunk."""
    rows = 2 * QUATERNION_SLICE_ROWS + 117
    chunk = RecordChunk(rows + 10, 6, False)
    chunk.rot[:rows] = Rotation.random(rows, rng=3).as_matrix()
    chunk.rows = rows
    np.testing.assert_array_equal(chunk.quaternions(),
                                  Rotation.from_matrix(chunk.rot[:rows]).as_quat())
    assert RecordChunk(5, 6, False).quaternions().shape == (0, 4)
