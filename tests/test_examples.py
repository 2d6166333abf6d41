"""Every example script runs (the workflows in the README), chained as a user would."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(script: str, *args: str) -> str:
    proc = subprocess.run([sys.executable, str(EXAMPLES / script), *args],
                          capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    return proc.stdout


def test_examples_run(tmp_path: Path) -> None:
    params = tmp_path / "params.toml"
    out = _run("calibrate_sim.py", "--seconds", "20", "--out", str(params))
    assert "consistent" in out and params.is_file()
    out = _run("guide_and_teach.py", "--params", str(params), "--out-dir", str(tmp_path))
    assert (tmp_path / "seam.parquet").is_file() and (tmp_path / "seam_path.json").is_file()
    assert "welding line" in out


def test_real_ur10e_example(tmp_path: Path) -> None:
    if not (EXAMPLES.parents[1] / "shared" / "data" / "ur10e" / "identification").is_dir():
        pytest.skip("needs ../shared/data/ur10e beside the repository")
    out = _run("real_ur10e.py")
    assert "no UR10e data" not in out
    assert "payload" in out
