"""Workflow 2: hand-guide the simulated robot along a welding seam and teach the line.

With parameters from workflow 1 (``calibrate_sim.py``), run the ``seam`` operator (a hand
pulling the tool along a 0.3 m seam) through the estimator, the virtual-friction controller
and the safety layer, then fit the welding line P1 → P2 and export the waypoints.

    python examples/calibrate_sim.py --out params.toml
    python examples/guide_and_teach.py --params params.toml [--out-dir .]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from leadthrough.identification.params_file import load_params
from leadthrough.robot import load_robot
from leadthrough.session_format import save_session
from leadthrough.sim.session import SimSessionConfig, run_sim_session
from leadthrough.teach import teach_session, write_program_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--params", type=Path, default=Path("params.toml"))
    parser.add_argument("--out-dir", type=Path, default=Path("."))
    args = parser.parse_args()
    robot = load_robot("er20")
    params = load_params(args.params, robot)
    session = run_sim_session(robot, params, SimSessionConfig(operator="seam"))
    s = session.summary
    print(f"seam session: max speed {s.max_linear_speed:.3f} m/s, faults {s.faults or 'none'}, "
          f"cycle p99 {s.cycle_time_us.p99:.0f} µs")
    save_session(session.result.log, args.out_dir / "seam.parquet")
    program = teach_session(session.result.log, robot, tolerance_mm=1.0, speed_m_s=0.1)
    line = program.welding_line
    if line is not None and session.p1_base is not None and session.p2_base is not None:
        e1 = 1e3 * np.linalg.norm(line.p1_base - session.p1_base)
        e2 = 1e3 * np.linalg.norm(line.p2_base - session.p2_base)
        print(f"welding line {1e3 * line.length_m:.1f} mm, max deviation "
              f"{line.max_deviation_mm:.2f} mm, endpoints vs the hand's targets {e1:.1f} / "
              f"{e2:.1f} mm")
    print("->", write_program_json(program, args.out_dir / "seam_path.json"))


if __name__ == "__main__":
    main()
