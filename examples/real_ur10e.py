"""Workflow 3: your own robot and logs, shown on the real UR10e recordings.

A robot is a URDF plus a drive TOML (``real/ur10e/robot.toml``); a controller log is read
through a column map (``real/ur10e/columns.toml``). Calibrate on the no-load run, check on the
load run's payload (2.805 kg). Needs ``../shared/data/ur10e`` beside the repository.

    python examples/real_ur10e.py
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from leadthrough.data.io import load_recording
from leadthrough.errors import DataWarning
from leadthrough.estimation.payload import estimate_payload
from leadthrough.identification.api import identify
from leadthrough.robot import load_robot

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[1] / "shared" / "data" / "ur10e" / "identification"


def main() -> int:
    if not DATA.is_dir():
        print(f"no UR10e data at {DATA}; nothing to do")
        return 0
    robot = load_robot(HERE / "real" / "ur10e" / "robot.toml")
    columns = HERE / "real" / "ur10e" / "columns.toml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        unloaded = load_recording(DATA / "ur-20_02_19_14harm50sec.csv", columns)
        loaded = load_recording(DATA / "ur-20_02_19_14harm50secLoad.csv", columns)
    res = identify(unloaded, robot, "consistent")
    print(f"consistent: J {res.J:.2f} N·m on the no-load run")
    est = estimate_payload(loaded, robot, res.params, "motion")
    print(f"payload {est.mass_kg:.3f} kg (true 2.805 kg, {100 * (est.mass_kg / 2.805 - 1):+.1f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
