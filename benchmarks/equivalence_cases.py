"""The guiding sessions of ``benchmarks/replay_equivalence.py``, in plain values: read by the
reference commit's code (``equivalence_reference.py``) and by today's, each building its own
configuration from them.

Per case: the operator script and its seed, the virtual mass of x, y, z [kg], the law, the
frame, the friction mode, translation-only axes with a zero-velocity update, the estimator's
method, a workspace box ``box_dx`` metres ahead of the start in x, and a feedback fault injected
by the simulated driver: (kind, t_start [s], t_end [s], joint or None, offset [rad]).
"""

from __future__ import annotations

#: The sessions: name -> the settings of SimSessionConfig, in plain values (the same table is
#: interpreted by today's code in replay_equivalence.py).
CASES: dict[str, dict[str, object]] = {
    "rest": {"operator": "rest"},
    "rest-velocity": {"operator": "rest", "controller": "velocity"},
    "push-x": {"operator": "push-x", "mass": 100.0},
    "push-x-velocity": {"operator": "push-x", "controller": "velocity", "mass": 100.0},
    "push-x-1000kg": {"operator": "push-x"},
    "diagonal": {"operator": "diagonal"},
    "seam": {"operator": "seam"},
    "random-0": {"operator": "random", "operator_seed": 0, "mass": 100.0},
    "random-8": {"operator": "random", "operator_seed": 8, "mass": 100.0},
    "random-18": {"operator": "random", "operator_seed": 18, "mass": 100.0},
    "tool-frame": {"operator": "push-x", "mass": 100.0, "frame": "tool"},
    "tool-frame-diagonal": {"operator": "diagonal", "frame": "tool"},
    "auto-friction": {"operator": "push-x", "mass": 100.0, "friction_mode": "auto"},
    "translation-rezero": {"operator": "random", "operator_seed": 3, "mass": 100.0,
                           "axes": "translation", "rezero_s": 0.3},
    "momentum": {"operator": "push-x", "mass": 100.0, "method": "momentum"},
    "workspace": {"operator": "push-x", "mass": 100.0, "box_dx": 0.15},
    "fault-stale": {"operator": "push-x", "mass": 100.0,
                    "fault": ["stale", 3.0, 1e9, None, 0.0]},
    "fault-nan-current": {"operator": "push-x", "mass": 100.0,
                          "fault": ["nan_current", 3.0035, 3.0045, 2, 0.0]},
    "fault-nan-q": {"operator": "push-x", "mass": 100.0,
                    "fault": ["nan_q", 2.5, 2.52, None, 0.0]},
    "fault-following": {"operator": "push-x", "mass": 100.0,
                        "fault": ["q_offset", 3.0, 1e9, 1, 0.2]},
}
