"""Teach-in from a guiding session (paper Fig. 6): the welding line P1 → P2 fitted to the guided
TCP path, the simplified waypoint path (Ramer–Douglas–Peucker), a joint position and speed limit
check at a programmed speed, and JSON / CSV export.

Example::

    from leadthrough.robot import load_robot
    from leadthrough.session_format import load_session
    from leadthrough.teach import teach_session, write_program_json

    log = load_session("seam.parquet")
    program = teach_session(log, load_robot(log.robot), tolerance_mm=1.0, speed_m_s=0.1)
    print(program.welding_line.max_deviation_mm)
    write_program_json(program, "seam.json")
"""

from leadthrough.teach.export import program_to_dict, write_program_csv, write_program_json
from leadthrough.teach.limits_check import LimitReport, LimitViolation, check_limits, limit_report
from leadthrough.teach.line_fit import Line3, WeldingLine, fit_line, fit_welding_line
from leadthrough.teach.path import TcpPath, check_session_robot, find_mark, forward_tcp, tcp_path
from leadthrough.teach.program import TaughtProgram, Waypoints, teach_session
from leadthrough.teach.simplify import rdp_indices, segment_distances

__all__ = [
    "LimitReport",
    "LimitViolation",
    "Line3",
    "TaughtProgram",
    "TcpPath",
    "Waypoints",
    "WeldingLine",
    "check_limits",
    "check_session_robot",
    "find_mark",
    "fit_line",
    "fit_welding_line",
    "forward_tcp",
    "limit_report",
    "program_to_dict",
    "rdp_indices",
    "segment_distances",
    "tcp_path",
    "teach_session",
    "write_program_csv",
    "write_program_json",
]
