"""Identified parameters for guiding the simulated robot, made once and shipped with the package.

Guiding the simulator takes what guiding a real robot takes: parameters identified from its
recordings, never the simulator's truth. The nominal (CAD) parameters are not enough: on the
simulated er20 a 40 N push with them is estimated at up to 290 N once the arm has moved, a
collision fault. The demo identifies the guiding parameters in its step 3 (``consistent`` with
the friction sweep, z₀ from a presliding test, ``params_guiding.toml``), which takes minutes
on a small machine. So that ``leadthrough pendant`` starts at once, the result of
:func:`calibrate_for_guiding` on the built-in er20, instance
:data:`~leadthrough.sim.session.DEFAULT_SIM_SEED`, is shipped (``sim/data/``);
``python -m leadthrough.sim.guiding_params`` makes it again (``tests/test_pendant_backend.py``
checks that it still guides the simulator: a push moves the arm, at rest it stays put).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

from leadthrough.errors import DataError
from leadthrough.excitation.design import ExcitationConfig, design_excitation
from leadthrough.identification.api import IdentifyConfig
from leadthrough.identification.calibration import Calibration, calibrate
from leadthrough.identification.params_file import ParamsFile, load_params
from leadthrough.robot.description import Robot, load_robot
from leadthrough.robot.poses import guide_start_pose
from leadthrough.sim.calibration_set import (
    record_excitation,
    record_friction_sweep,
    record_presliding_test,
)
from leadthrough.sim.plant import PlantPreset, plant_preset
from leadthrough.sim.robot import SimConfig
from leadthrough.sim.session import DEFAULT_SIM_SEED

__all__ = ["calibrate_for_guiding", "shipped_guiding_params", "shipped_params_path"]

_DATA = Path(__file__).parent / "data"


def shipped_params_path(robot: str, seed: int = DEFAULT_SIM_SEED) -> Path:
    """Where the shipped guiding parameters of simulated ``robot`` instance ``seed`` live."""
    return _DATA / f"{robot}_seed{seed}_guiding.toml"


def shipped_guiding_params(robot: Robot, seed: int = DEFAULT_SIM_SEED) -> ParamsFile:
    """The shipped guiding parameters of a simulated robot.

    Raises:
        DataError: None shipped for this robot and instance (identify them: ``leadthrough
            demo`` writes ``params_guiding.toml``).
    """
    path = shipped_params_path(robot.name, seed)
    if not path.is_file():
        raise DataError("no shipped guiding parameters for this simulated robot",
                        field="robot", value=f"{robot.name} instance {seed}",
                        expected=f"er20 instance {DEFAULT_SIM_SEED}, or --params from "
                                 "'leadthrough demo' (params_guiding.toml)")
    return load_params(path, robot)


def calibrate_for_guiding(robot: Robot, seed: int = DEFAULT_SIM_SEED, duration_s: float = 60.0,
                          progress: Callable[[str], None] | None = None,
                          plant: PlantPreset | str = PlantPreset.REALISTIC) -> Calibration:
    """The demo's guiding calibration: an optimised excitation, a friction sweep and a
    presliding test recorded on simulated instance ``seed``, calibrated with ``consistent``
    and the sweep's friction, each joint's z₀ from the presliding test and the command lag
    from the excitation (:func:`~leadthrough.identification.calibration.calibrate`, as
    ``leadthrough identify --friction-sweep S --presliding-test P`` does; the in-process
    simulator's lag is 0).

    Args:
        robot: The robot.
        seed: Simulated robot instance.
        duration_s: Length of the excitation recording [s].
        progress: Called with a line of text after each step.
        plant: Simulated plant (:mod:`leadthrough.sim.plant`).
    """
    say = progress if progress is not None else (lambda _: None)
    exc = design_excitation(robot, ExcitationConfig(starts=2, seed=0, max_iterations=100))
    say(f"excitation designed: cond = {exc.condition_number:.1f}")
    rec = record_excitation(robot, exc, duration_s,
                            SimConfig(seed=seed, run=0, plant=plant_preset(plant)))
    start = guide_start_pose(robot)
    sweep = record_friction_sweep(robot, seed=seed, run=2, q_start=start, plant=plant)
    pre = record_presliding_test(robot, seed=seed, run=3, q_start=start, plant=plant)
    say("recorded the excitation, the friction sweep and the presliding test")
    return calibrate(rec.measured, robot, "consistent", IdentifyConfig(),
                     friction_sweep=sweep.measured, presliding_test=pre.measured)


def main() -> None:
    """Make the shipped parameters again (``python -m leadthrough.sim.guiding_params``)."""
    robot = load_robot("er20")
    t0 = time.perf_counter()
    cal = calibrate_for_guiding(robot, progress=print)
    path = cal.save(shipped_params_path(robot.name), robot, DEFAULT_SIM_SEED)
    print(f"-> {path} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
