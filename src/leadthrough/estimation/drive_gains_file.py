"""The drive-gains file: a TOML file of the gains and load friction measured with a known mass
(:mod:`leadthrough.estimation.drive_gains`), written by ``leadthrough drive-gains`` and read by
``leadthrough payload --drive-gains``.

Layout::

    [meta]
    robot = "er20"
    known_mass_kg = 20.0
    known_com_m = [0.05, 0.0, 0.15]       # in the TCP frame
    known_inertia_kgm2 = [0.02, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.02]  # about the CoM
    reference_shift_s = 0.0
    samples = 123456
    sim_seed = 1                          # only for a simulated robot

    [joints.<name>]                       # one per joint, in the robot's order
    gain = 0.9917                         # true torque per drive-file torque
    gain_std = 0.0021                     # inf where the mass did not load the joint
    load_friction = 0.062                 # f_cL [-]
    applied = true
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from leadthrough.data.recording import is_sim_seed
from leadthrough.dynamics.model import MAX_LOAD_FRICTION
from leadthrough.errors import DataError
from leadthrough.estimation.drive_gains import DriveGains, KnownPayload
from leadthrough.fileio import atomic_write_text, read_toml, toml_number, toml_table
from leadthrough.robot.description import Robot

__all__ = ["MAX_GAIN_ERROR", "load_drive_gains", "save_drive_gains"]

#: A gain further than this from 1 is refused on reading: a drive off its datasheet by more
#: than half is a wrong drive file, not a tolerance.
MAX_GAIN_ERROR = 0.5


def save_drive_gains(path: str | Path, robot: Robot, gains: DriveGains,
                     sim_seed: int | None = None) -> Path:
    """Write a drive-gains file atomically.

    Args:
        path: Output TOML file.
        robot: The robot the gains belong to.
        gains: The gains.
        sim_seed: The simulated robot instance the runs came from (None: a real robot).

    Returns:
        The path written.
    """
    known = gains.known
    lines = ["# leadthrough drive gains, measured with a known mass", "[meta]",
             f'robot = "{robot.name}"', f"known_mass_kg = {float(known.mass_kg)!r}",
             "known_com_m = [" + ", ".join(repr(float(v)) for v in known.com_tcp) + "]",
             "known_inertia_kgm2 = [" + ", ".join(repr(float(v))
                                                  for v in known.inertia().ravel()) + "]",
             f"reference_shift_s = {float(gains.reference_shift_s)!r}",
             f"samples = {int(gains.samples)}",
             *([] if sim_seed is None else [f"sim_seed = {int(sim_seed)}"])]
    for k, name in enumerate(robot.joint_names):
        lines += ["", f"[joints.{name}]", f"gain = {float(gains.gain[k])!r}",
                  f"gain_std = {float(gains.gain_std[k])!r}",
                  f"load_friction = {float(gains.load_friction[k])!r}",
                  f"applied = {'true' if gains.applied[k] else 'false'}"]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def load_drive_gains(path: str | Path, robot: Robot) -> tuple[DriveGains, int | None]:
    """Read a drive-gains file and check it belongs to ``robot``.

    Returns:
        The gains and the simulated robot instance they were measured on (None: a real one).

    Raises:
        DataError: Missing, malformed, out of range, or written for another robot.
    """
    path = Path(path)
    doc = read_toml(path, "drive-gains file")
    meta = toml_table(path, doc, "meta")
    if meta.get("robot") != robot.name:
        raise DataError("drive gains of another robot", source=path, field="meta.robot",
                        value=meta.get("robot"), expected=f"'{robot.name}'")
    seed = meta.get("sim_seed")
    if seed is not None and not is_sim_seed(seed):
        raise DataError("malformed", source=path, field="meta.sim_seed", value=seed,
                        expected="an integer >= 0 (the simulated robot instance)")
    com = meta.get("known_com_m")
    if not isinstance(com, list) or len(com) != 3:
        raise DataError("malformed", source=path, field="meta.known_com_m", value=com,
                        expected="3 numbers [m]")
    c = [toml_number(path, "meta.known_com_m", v) for v in com]
    mass = toml_number(path, "meta.known_mass_kg", meta.get("known_mass_kg"))
    if mass <= 0.0:
        raise DataError("out of range", source=path, field="meta.known_mass_kg", value=mass,
                        expected="> 0 kg")
    inertia = meta.get("known_inertia_kgm2", [0.0] * 9)
    if not isinstance(inertia, list) or len(inertia) != 9:
        raise DataError("malformed", source=path, field="meta.known_inertia_kgm2",
                        value=inertia, expected="9 numbers [kg·m²], row by row")
    i = [toml_number(path, "meta.known_inertia_kgm2", v) for v in inertia]
    try:
        known = KnownPayload(mass, (c[0], c[1], c[2]),
                             ((i[0], i[1], i[2]), (i[3], i[4], i[5]), (i[6], i[7], i[8])))
    except DataError as e:
        raise DataError(e.message, source=path, field="meta.known_inertia_kgm2",
                        value=inertia, expected=e.expected) from e
    joints = toml_table(path, doc, "joints")
    columns: dict[str, list[Any]] = {"gain": [], "gain_std": [], "load_friction": [],
                                     "applied": []}
    for name in robot.joint_names:
        table = toml_table(path, joints, name, f"joints.{name}")
        for key, values in columns.items():
            values.append(_joint_value(path, f"joints.{name}.{key}", key, table.get(key)))
    return DriveGains(robot=robot.name, gain=np.array(columns["gain"]),
                      gain_std=np.array(columns["gain_std"]),
                      load_friction=np.array(columns["load_friction"]),
                      applied=np.array(columns["applied"], dtype=bool), known=known,
                      reference_shift_s=toml_number(path, "meta.reference_shift_s",
                                                meta.get("reference_shift_s", 0.0)),
                      samples=int(toml_number(path, "meta.samples", meta.get("samples", 0)))), seed


def _joint_value(path: Path, field: str, key: str, value: Any) -> float | bool:
    """One joint's entry, checked against its range."""
    if key == "applied":
        if not isinstance(value, bool):
            raise DataError("malformed", source=path, field=field, value=value,
                            expected="true or false")
        return value
    if key == "gain_std" and value == math.inf:
        return math.inf
    v = toml_number(path, field, value)
    ranges = {"gain": (1.0 - MAX_GAIN_ERROR < v < 1.0 + MAX_GAIN_ERROR,
                       f"between {1 - MAX_GAIN_ERROR:g} and {1 + MAX_GAIN_ERROR:g}"),
              "gain_std": (v >= 0.0, ">= 0, or inf"),
              "load_friction": (0.0 <= v < MAX_LOAD_FRICTION,
                                f"in [0, {MAX_LOAD_FRICTION:g})")}
    ok, expected = ranges[key]
    if not ok:
        raise DataError("out of range", source=path, field=field, value=v, expected=expected)
    return v
