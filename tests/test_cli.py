"""CLI: robots listing, demo figures, exit codes."""

from __future__ import annotations

import contextlib
import io
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


@pytest.fixture(scope="module")
def quick_demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, dict]:
    """``leadthrough demo --quick`` on the default (realistic) plant, run once: its folder,
    the printed and the saved summary."""
    out = tmp_path_factory.mktemp("demo")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["demo", "--quick", "--out", str(out), "--json"]) == 0
    return out, json.loads(printed.getvalue()), json.loads((out / "summary.json").read_text())


@pytest.mark.xfail(strict=True, reason=(
    "issue 24: on the realistic plant the payload weight from motion reads 4-7 % high with "
    "either parameter set (quick demo; README Limitations); goal 1 % kept"))
def test_demo_quick_table3_meets_its_goal(quick_demo: tuple[Path, dict, dict]) -> None:
    # Table III's goal, 1 %, by the guiding method (ideal plant: measured <= 0.8 % in the quick
    # demo)
    saved = quick_demo[2]
    assert all(abs(r["error_pct"]) < 1.0 for r in saved["table3"]["consistent"])


def test_demo_quick_writes_summary(quick_demo: tuple[Path, dict, dict]) -> None:
    tmp_path, printed, saved = quick_demo
    checks = saved["checks"]
    assert printed["checks"]["base_parameters"] == checks["base_parameters"] == 36
    assert checks["regressor_rel_error"]["rnea"] < 1e-9
    assert checks["hold"]["max_joint_error_rad"] < 1e-4
    assert max(checks["push_50N_x"]["current_error_sigma"]) < 0.5
    # every step left its result: Table II/III, sessions, the taught path, the report
    held_out = saved["table2"]["held-out"]
    assert {"ols-cv", "proposed", "consistent"} <= set(held_out)
    # Table II's order holds on the held-out run too (test_identification's docstring)
    assert (held_out["floor"] < held_out["consistent"] < held_out["proposed"]
            < held_out["ols-cbrt"] < held_out["ols-cv"]), held_out
    assert len(saved["table3"]["consistent"]) == 4
    rest = saved["guiding"]["rest/virtual-friction"]
    assert rest["max_linear_speed"] == 0.0 and rest["rest_drift_m"] == 0.0
    assert saved["guiding"]["rest/velocity"]["rest_drift_m"] > 0.0  # the baseline drifts
    for name in ("report.html", "report.md", "path.json", "path.csv", "fig3.png", "fig4.png",
                 "fig5.png", "fig6.png", "params_consistent.toml",
                 "session_seam_virtual-friction.parquet",
                 # the taught seam as robot programs, each solved back before it was written
                 "seam.script", "seam.src", "seam.dat", "seam.ls", "seam.mod"):
        assert (tmp_path / name).is_file(), name
    assert saved["teach"]["waypoints"] >= 2
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
