"""Which simulated plant plays the robot: the realistic one (default) or the ideal one.

* ``realistic``: the robot as a calibration meets it on the shop floor. Beyond the ideal plant
  it has what the identification model does not: true links outside the identifier's box and
  an unmodelled dress pack, a friction shape other than eq. 15's, load- and
  temperature-dependent friction, torque-constant errors and cogging in the drives, and
  currents sampled late (see :class:`~leadthrough.sim.robot.SimRobot`).
* ``ideal``: the plant of the project before issue 24, kept bit for bit so that old and new
  figures can be shown side by side. Its links stay inside the ±30 % box the identifier
  enforces and its friction has eq. 15's shape.

The preset selects which phenomena the plant has; their parameters live in the simulator's
configuration (:class:`~leadthrough.sim.robot.SimConfig`). Both presets are drawn from the
robot instance's seed, so a seed and a preset name one robot.
"""

from __future__ import annotations

from dataclasses import fields
from enum import StrEnum
from typing import Any

import numpy as np

from leadthrough.errors import SimulationError

__all__ = ["PLANT_NAMES", "PlantPreset", "check_draw_ranges", "plant_preset"]


class PlantPreset(StrEnum):
    """The simulated plant (see the module doc)."""

    REALISTIC = "realistic"
    IDEAL = "ideal"


#: Preset names, default first (for command-line choices).
PLANT_NAMES: tuple[str, ...] = tuple(p.value for p in PlantPreset)


def plant_preset(value: PlantPreset | str, field: str = "plant") -> PlantPreset:
    """The preset named by ``value``.

    Args:
        value: A preset or its name (``"realistic"``, ``"ideal"``).
        field: Name of the setting, for the error message.

    Raises:
        SimulationError: An unknown name.
    """
    try:
        return PlantPreset(value)
    except ValueError as e:
        raise SimulationError("unknown plant", field=field, value=value,
                              expected="one of " + ", ".join(PLANT_NAMES)) from e


def check_draw_ranges(prefix: str, settings: Any, skip: tuple[str, ...] = ()) -> None:
    """Check the fields of a realistic plant's settings: each a number or a (low, high) range
    to draw from, finite and 0 <= low <= high.

    Args:
        prefix: Prefix of the field names in messages (e.g. ``"thermal"``).
        settings: A dataclass of such fields.
        skip: Fields checked elsewhere.

    Raises:
        SimulationError: Naming the first bad field and its value.
    """
    for f in fields(settings):
        if f.name in skip:
            continue
        value = getattr(settings, f.name)
        lo, hi = value if isinstance(value, tuple) else (value, value)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo <= hi):
            raise SimulationError("bad range", field=f"{prefix}.{f.name}", value=value,
                                  expected="finite numbers 0 <= low <= high")
