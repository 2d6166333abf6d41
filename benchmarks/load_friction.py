"""Load-dependent friction on the real robots: held-out error with and without the load term.

The Coulomb level f_c0 + f_cL·|τ_load| (Bittencourt et al., IROS 2010;
:mod:`leadthrough.identification.load_friction`), identified by iteration with ``consistent``
and ``ols-cv`` on the same runs as ``benchmarks/real_robots.py``:

* UR10e (Mamedov et al.): identified on ``30sec_12harm``, held out: ``ptp_10_points``,
  ``40sec_12harm``, ``50sec_12harm``;
* KUKA KR300 R2500 ultra (Weigand et al.): identified on run A, held out: B and C.

One table: J on the identification run, J on each held-out run, the RMS error per joint pooled
over the held-out runs, the identified f_cL per joint (0 on the joints whose load is too small to
tell it, :func:`leadthrough.identification.load_friction.load_excitation`), and the
identifications run (passes; each costs about one identification without the load term).

    python benchmarks/load_friction.py [--json out.json]

Needs ``../shared/data`` beside the repository.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from leadthrough.data.recording import Recording
from leadthrough.errors import DataWarning
from leadthrough.identification.api import IdentifyConfig, evaluate, identify
from leadthrough.robot import Robot

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_robots import DATA, kr300_logs, ur10e_logs

METHODS = ("consistent", "ols-cv")
ROBOTS = {"UR10e": ur10e_logs, "KR300": kr300_logs}


@dataclass(frozen=True)
class Row:
    """One identification and its held-out figures.

    Attributes:
        robot: Robot name.
        method: Identification method.
        load_term: Whether f_cL was identified.
        J_id: J on the identification run [N·m].
        J_held: J on each held-out run [N·m].
        rel_held: Relative torque error on each held-out run [%].
        rms_held: RMS error per joint, pooled over the held-out runs [N·m].
        load_friction: f_cL per joint [-] (zeros without the load term).
        passes: Identifications run for the load term (0 without it).
        runtime_s: Wall time of the identification [s].
    """

    robot: str
    method: str
    load_term: bool
    J_id: float
    J_held: dict[str, float]
    rel_held: dict[str, float]
    rms_held: list[float]
    load_friction: list[float]
    passes: int
    runtime_s: float

    @property
    def J_held_mean(self) -> float:  # noqa: N802 (the paper's symbol)
        """Mean J over the held-out runs [N·m]."""
        return float(np.mean(list(self.J_held.values())))


def measure(name: str, robot: Robot, ident: Recording, held: dict[str, Recording],
            method: str, load_term: bool) -> Row:
    """Identify with ``method`` (with or without the load term) and evaluate held out."""
    cfg = IdentifyConfig(load_friction=load_term)
    res = identify(ident, robot, method, cfg)
    stats = {k: evaluate(res.params, robot, v, cfg) for k, v in held.items()}
    count = sum(s.samples for s in stats.values())
    pooled = np.sqrt(sum(s.samples * s.rms**2 for s in stats.values()) / count)
    fl = res.params.load_friction if res.params.load_friction.size else np.zeros(robot.n)
    return Row(robot=name, method=method, load_term=load_term, J_id=res.J,
               J_held={k: s.J for k, s in stats.items()},
               rel_held={k: s.rel_error_pct for k, s in stats.items()},
               rms_held=pooled.tolist(), load_friction=fl.tolist(), passes=res.load_passes,
               runtime_s=res.runtime_s)


def rows_for(name: str, methods: tuple[str, ...] = METHODS) -> list[Row]:
    """Every method with and without the load term on one robot's logs."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        robot, _, ident, held = ROBOTS[name]()
    return [measure(name, robot, ident, held, m, load) for m in methods for load in (False, True)]


def table(rows: list[Row]) -> str:
    """The Markdown table."""
    lines = ["| robot | method | load term | J id [N·m] | J held out [N·m] | "
             "RMS per joint held out [N·m] | f_cL per joint [%] | passes |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        held = ", ".join(f"{k} {v:.2f}" for k, v in r.J_held.items())
        lines.append(
            f"| {r.robot} | {r.method} | {'yes' if r.load_term else 'no'} | {r.J_id:.2f} | "
            f"{held} (mean {r.J_held_mean:.2f}) | "
            + ", ".join(f"{v:.2f}" for v in r.rms_held) + " | "
            + (", ".join(f"{100 * v:.1f}" for v in r.load_friction) if r.load_term else "–")
            + f" | {r.passes} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    args = parser.parse_args()
    if not DATA.is_dir():
        print(f"{DATA} not found: the real-robot logs are not shipped with the package")
        return
    rows = [r for name in ROBOTS for r in rows_for(name)]
    print(table(rows))
    print()
    for with_, without in zip(rows[1::2], rows[::2], strict=True):
        print(f"{with_.robot} {with_.method}: held-out J with / without the load term "
              f"{with_.J_held_mean / without.J_held_mean:.3f}")
    if args.json is not None:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=2))


if __name__ == "__main__":
    main()
