"""CLI: robots listing, demo figures, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from leadthrough.cli import main


def test_robots_json_reports_base_counts(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["robots", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    counts = {r["name"]: r["base_parameters"] for r in out["robots"]}
    assert counts == {"er20": 36, "ur5": 36, "ur10": 36, "panda": 43}


def test_demo_quick_writes_summary(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--quick", "--out", str(tmp_path), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert printed["base_parameters"] == saved["base_parameters"] == 36
    assert saved["regressor_rel_error"]["rnea"] < 1e-9
    assert saved["hold"]["max_joint_error_rad"] < 1e-4
    assert max(saved["push_50N_x"]["current_error_sigma"]) < 0.5
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left


def test_no_command_and_bad_option_exit_2() -> None:
    assert main([]) == 2
    with pytest.raises(SystemExit) as e:
        main(["robots", "--nope"])
    assert e.value.code == 2


def test_console_script_runs() -> None:
    proc = subprocess.run([sys.executable, "-m", "leadthrough", "robots", "--robot", "x"],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "unknown robot" in proc.stderr
