"""Params files: identified model parameters as TOML, tied to the robot they belong to.

Layout::

    [meta]
    robot = "er20"                   # checked against the robot on load
    method = "proposed"
    friction_model = "stribeck"      # stribeck | coulomb-viscous | cbrt
    leadthrough_version = "0.1.0"
    J = 38.9                          # on the identification data [N·m]
    k_omega = 1.0
    friction_sweep = true             # the friction was held to a constant-velocity sweep
    command_lag = 0.008               # command-to-position lag [s] (optional: on the recording)

    [noise]                          # residual τ_ω on the identification data (eq. 26, 30, 36)
    mean = [...]                     # τ̄_ω per joint [N·m]
    std = [...]                      # σ per joint [N·m]

    [joints.joint_1]                 # drive parameters
    rotor_inertia = 8.6              # M_j [kg·m²]
    offset = 0.4                     # τ_0 [N·m] (optional, consistent method)
    presliding = 2.2e-4              # z₀ [rad] (optional, from a presliding test)
    load_friction = 0.05             # f_cL [-] (optional: Coulomb level f_c0 + f_cL·|τ_load|)
    f1 = 40.0                        # ... per friction model

    [links.joint_1]                  # standard link parameters (regressor order) [kg, kg·m, kg·m²]
    m = 66.0
    ...

Files are written atomically.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from leadthrough import __version__
from leadthrough.data.recording import is_sim_seed
from leadthrough.dynamics.friction import StribeckParameters
from leadthrough.dynamics.model import (
    MAX_COMMAND_LAG_S,
    MAX_LOAD_FRICTION,
    MAX_PRESLIDING_RAD,
    MAX_PRESLIDING_RELAXATION,
    DriveModelParameters,
    FrictionModel,
)
from leadthrough.dynamics.regressor import LINK_PARAMETER_NAMES
from leadthrough.errors import DataError
from leadthrough.fileio import atomic_write_text, read_toml, toml_number, toml_table
from leadthrough.identification.consistency import min_pseudo_inertia_eigenvalues
from leadthrough.identification.metrics import ResidualStats
from leadthrough.robot.description import Robot

if TYPE_CHECKING:
    from leadthrough.identification.api import IdentificationResult

__all__ = ["ParamsFile", "load_params", "save_params"]

Array = NDArray[np.float64]
#: How far below zero a Stribeck friction coefficient may be (a convex solver's tolerance on
#: its bound) [N·m or N·m·s].
FRICTION_TOLERANCE = 1e-6
#: How far below zero a link's smallest pseudo-inertia eigenvalue may be in a file of the
#: consistent method, per kg of the link (a solver's tolerance) [kg·m²].
PSEUDO_INERTIA_TOLERANCE = 1e-9

_FRICTION_KEYS = {
    FrictionModel.STRIBECK: ("f1", "f2", "qd_sm", "f3", "qd_sg", "f4"),
    FrictionModel.COULOMB_VISCOUS: ("coulomb", "viscous"),
    FrictionModel.CBRT: ("coulomb", "viscous", "cbrt"),
}


@dataclass(frozen=True)
class ParamsFile:
    """A loaded params file.

    Attributes:
        robot: Robot name it belongs to.
        method: Identification method.
        params: The model parameters.
        noise_mean: τ̄_ω per joint [N·m], shape (n,).
        noise_std: σ of τ_ω per joint [N·m], shape (n,).
        J: J on the identification data [N·m].
        path: The file.
        sim_seed: The simulated robot instance the identification data came from (``[meta]
            sim_seed``); None for a real robot.
        friction_sweep: The friction was identified with a constant-velocity friction sweep
            (``[meta] friction_sweep``; absent: False). Hand guiding needs it: without it the
            identified friction is 15–24 % low at guiding speeds.
    """

    robot: str
    method: str
    params: DriveModelParameters
    noise_mean: Array
    noise_std: Array
    J: float
    path: Path | None = None
    sim_seed: int | None = None
    friction_sweep: bool = False

    @classmethod
    def from_result(cls, result: IdentificationResult, path: Path | None = None,
                    sim_seed: int | None = None, friction_sweep: bool = False) -> ParamsFile:
        """The params file an identification result would be saved as (without writing it)."""
        return cls(robot=result.robot, method=result.method, params=result.params,
                   noise_mean=result.stats.mean, noise_std=result.stats.std, J=result.J,
                   path=path, sim_seed=sim_seed, friction_sweep=friction_sweep)


def _fmt(v: float) -> str:
    return repr(float(v))


def save_params(
    path: str | Path, robot: Robot, method: str, params: DriveModelParameters,
    stats: ResidualStats, sim_seed: int | None = None, friction_sweep: bool = False,
) -> Path:
    """Write a params file atomically.

    Args:
        path: Output TOML file.
        robot: The robot the parameters belong to.
        method: Identification method.
        params: Identified parameters.
        stats: Residual statistics on the identification data (J, τ̄_ω, σ).
        sim_seed: The simulated robot instance the data came from (None: a real robot).
        friction_sweep: The friction was held to a friction sweep's curve (written as ``[meta]
            friction_sweep = true``).

    Returns:
        The path written.
    """
    lines = [
        "# leadthrough identified parameters",
        "[meta]",
        f'robot = "{robot.name}"',
        f'method = "{method}"',
        f'friction_model = "{params.friction_model.value}"',
        f'leadthrough_version = "{__version__}"',
        f"J = {_fmt(stats.J)}",
        f"k_omega = {_fmt(stats.k_omega)}",
        *([] if sim_seed is None else [f"sim_seed = {int(sim_seed)}"]),
        *(["friction_sweep = true"] if friction_sweep else []),
        *([f"command_lag = {_fmt(params.command_lag)}"] if params.command_lag else []),
        "",
        "[noise]",
        "mean = [" + ", ".join(_fmt(v) for v in stats.mean) + "]",
        "std = [" + ", ".join(_fmt(v) for v in stats.std) + "]",
    ]
    keys = _FRICTION_KEYS[params.friction_model]
    for k, jn in enumerate(robot.joint_names):
        lines += ["", f"[joints.{jn}]", f"rotor_inertia = {_fmt(params.rotor_inertia[k])}"]
        if params.offset.size:
            lines.append(f"offset = {_fmt(params.offset[k])}")
        if params.presliding.size:
            lines.append(f"presliding = {_fmt(params.presliding[k])}")
        if params.presliding_relaxation.size:
            lines.append(f"presliding_relaxation = {_fmt(params.presliding_relaxation[k])}")
        if params.load_friction.size:
            lines.append(f"load_friction = {_fmt(params.load_friction[k])}")
        for key in keys:
            if params.friction_model is FrictionModel.STRIBECK:
                assert params.stribeck is not None
                value = getattr(params.stribeck, key)[k]
            else:
                value = getattr(params, key)[k]
            lines.append(f"{key} = {_fmt(value)}")
    for k, jn in enumerate(robot.joint_names):
        lines += ["", f"[links.{jn}]"]
        lines += [f"{p} = {_fmt(params.phi[10 * k + i])}"
                  for i, p in enumerate(LINK_PARAMETER_NAMES)]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def load_params(path: str | Path, robot: Robot) -> ParamsFile:
    """Read a params file and check it belongs to ``robot``.

    Every number is checked: finite; a link mass > 0 kg; a Coulomb level >= 0 and the
    Coulomb-viscous model's viscous slope >= 0 (the Stribeck coefficients as the paper bounds
    them); a file of the ``consistent`` method, a physical robot, with each rotor inertia >= 0
    and each link's pseudo-inertia positive semi-definite.

    Raises:
        DataError: Missing, malformed, out of range (naming the file, the field, its value and
            the range), or written for another robot.
    """
    path = Path(path)
    doc = read_toml(path, "params file")
    meta, model = _read_meta(path, doc, robot)
    joints = _JointTables(path, robot, model, toml_table(path, doc, "joints"),
                          toml_table(path, doc, "links"))
    joints.check_consistency(str(meta.get("method", "")))
    noise_mean, noise_std = _read_noise(path, toml_table(path, doc, "noise"), robot.n)
    seed = meta.get("sim_seed")
    if seed is not None and not is_sim_seed(seed):
        raise DataError("malformed", source=path, field="meta.sim_seed", value=seed,
                        expected="an integer >= 0 (the simulated robot instance)")
    sweep = meta.get("friction_sweep", False)
    if not isinstance(sweep, bool):
        raise DataError("malformed", source=path, field="meta.friction_sweep", value=sweep,
                        expected="true or false")
    lag = _nonnegative(path, "meta.command_lag", meta.get("command_lag", 0.0))
    if lag > MAX_COMMAND_LAG_S:
        raise DataError("out of range", source=path, field="meta.command_lag", value=lag,
                        expected=f"0 to {MAX_COMMAND_LAG_S:g} s")
    return ParamsFile(robot=robot.name, method=str(meta.get("method", "")),
                      params=replace(joints.parameters(), command_lag=lag),
                      noise_mean=noise_mean, noise_std=noise_std,
                      J=_nonnegative(path, "meta.J", meta.get("J")), path=path,
                      sim_seed=seed, friction_sweep=sweep)


def _read_meta(path: Path, doc: dict[str, Any], robot: Robot
               ) -> tuple[dict[str, Any], FrictionModel]:
    """The ``[meta]`` table, checked to belong to ``robot``, and its friction model."""
    meta = toml_table(path, doc, "meta")
    if meta.get("robot") != robot.name:
        raise DataError("params file belongs to another robot", source=path, field="meta.robot",
                        value=meta.get("robot"), expected=f"'{robot.name}' (identify this robot "
                                                          "first, or pass the matching --robot)")
    try:
        model = FrictionModel(str(meta.get("friction_model")))
    except ValueError as e:
        raise DataError("unknown friction model", source=path, field="meta.friction_model",
                        value=meta.get("friction_model"),
                        expected=f"one of {[m.value for m in FrictionModel]}") from e
    return meta, model


def _read_noise(path: Path, noise: dict[str, Any], n: int) -> tuple[Array, Array]:
    """τ̄_ω and σ per joint from the ``[noise]`` table (σ > 0)."""
    arrays = {}
    for key in ("mean", "std"):
        v = noise.get(key)
        if not isinstance(v, list) or len(v) != n:
            raise DataError("malformed", source=path, field=f"noise.{key}", value=v,
                            expected=f"a list of {n} numbers")
        arrays[key] = np.array([toml_number(path, f"noise.{key}", x) for x in v])
    if np.any(arrays["std"] <= 0):
        j = int(np.argmax(arrays["std"] <= 0))
        raise DataError("out of range", source=path, field=f"noise.std[{j}]",
                        value=float(arrays["std"][j]), expected="> 0 N·m (the residual's σ)")
    return arrays["mean"], arrays["std"]


class _JointTables:
    """The ``[joints.*]`` and ``[links.*]`` tables of a params file, read and checked."""

    def __init__(self, path: Path, robot: Robot, model: FrictionModel, joints: dict[str, Any],
                 links: dict[str, Any]) -> None:
        self.path, self.model, n = path, model, robot.n
        self._joint_names = robot.joint_names
        self.keys = _FRICTION_KEYS[model]
        self.drive = {key: np.zeros(n) for key in (*self.keys, "rotor_inertia")}
        self.offset, self.presliding, self.load = np.zeros(n), np.zeros(n), np.zeros(n)
        self.relaxation = np.zeros(n)
        self.has_offset, self.presliding_joints, self.load_joints = False, 0, 0
        self.relaxation_joints = 0
        self.phi = np.zeros(10 * n)
        for table, name in ((joints, "joints"), (links, "links")):
            extra = sorted(set(table) - set(robot.joint_names))
            if extra:
                raise DataError("not a joint of the robot", source=path,
                                field=f"{name}.{extra[0]}",
                                expected=f"tables for the joints {list(robot.joint_names)} only")
        for k, jn in enumerate(robot.joint_names):
            jt, lt = joints.get(jn), links.get(jn)
            if not isinstance(jt, dict) or not isinstance(lt, dict):
                raise DataError("missing joint", source=path, field=f"joints.{jn} / links.{jn}",
                                expected="a table per joint of the robot")
            self._read_joint(k, jn, jt)
            self._read_link(k, jn, lt)
        for key, count in (("presliding", self.presliding_joints),
                           ("presliding_relaxation", self.relaxation_joints),
                           ("load_friction", self.load_joints)):
            if count not in (0, n):
                raise DataError(f"{key} given for some joints only", source=path,
                                field=f"joints.*.{key}", value=count,
                                expected=f"all {n} joints or none")
        if self.relaxation_joints and not self.presliding_joints:
            raise DataError("presliding_relaxation without presliding", source=path,
                            field="joints.*.presliding_relaxation", value=n,
                            expected="with the presliding lengths of the same test")

    def _read_joint(self, k: int, jn: str, jt: dict[str, Any]) -> None:
        path = self.path
        _only(path, f"joints.{jn}", jt, {*self.drive, "offset", "presliding",
                                         "presliding_relaxation", "load_friction"})
        if "offset" in jt:
            self.offset[k] = toml_number(path, f"joints.{jn}.offset", jt["offset"])
            self.has_offset = True
        if "presliding" in jt:
            z0 = self.presliding[k] = toml_number(path, f"joints.{jn}.presliding", jt["presliding"])
            if not 0 < z0 <= MAX_PRESLIDING_RAD:
                raise DataError("out of range", source=path, field=f"joints.{jn}.presliding",
                                value=z0, expected=f"0 < z0 <= {MAX_PRESLIDING_RAD:g} rad")
            self.presliding_joints += 1
        if "presliding_relaxation" in jt:
            field = f"joints.{jn}.presliding_relaxation"
            rate = self.relaxation[k] = toml_number(path, field, jt["presliding_relaxation"])
            if not 0 <= rate <= MAX_PRESLIDING_RELAXATION:
                raise DataError("out of range", source=path, field=field, value=rate,
                                expected=f"0 <= rate <= {MAX_PRESLIDING_RELAXATION:g} 1/s")
            self.relaxation_joints += 1
        if "load_friction" in jt:
            fl = self.load[k] = toml_number(path, f"joints.{jn}.load_friction", jt["load_friction"])
            if not 0 <= fl < MAX_LOAD_FRICTION:
                raise DataError("out of range", source=path, field=f"joints.{jn}.load_friction",
                                value=fl, expected=f"0 <= f_cL < {MAX_LOAD_FRICTION:g} (extra "
                                                   "Coulomb friction per N·m transmitted)")
            self.load_joints += 1
        for key, values in self.drive.items():
            values[k] = toml_number(path, f"joints.{jn}.{key}", _required(path, f"joints.{jn}", jt,
                                                                       key))
            # a Coulomb level is never negative, nor the viscous slope of the Coulomb-viscous
            # model (with the cube-root term of ols-cbrt the two share the slope: either may
            # be; its rotor inertia too, fitted with the links' base combinations)
            signed = key == "coulomb" or (self.model is FrictionModel.COULOMB_VISCOUS
                                          and key == "viscous")
            if signed and values[k] < -FRICTION_TOLERANCE:
                raise DataError("out of range", source=path, field=f"joints.{jn}.{key}",
                                value=values[k],
                                expected=f">= 0 {'N·m' if key == 'coulomb' else 'N·m·s'}")
            if self.model is FrictionModel.STRIBECK and key != "rotor_inertia":
                # the paper's bounds (friction > 0, met by the solvers to their tolerance);
                # the velocities divide
                strict = key in ("qd_sm", "qd_sg")
                if values[k] < -FRICTION_TOLERANCE or (strict and values[k] <= 0):
                    raise DataError("out of range", source=path, field=f"joints.{jn}.{key}",
                                    value=values[k],
                                    expected="> 0 [rad/s]" if strict else ">= 0 [N·m, N·m·s]")

    def _read_link(self, k: int, jn: str, lt: dict[str, Any]) -> None:
        _only(self.path, f"links.{jn}", lt, set(LINK_PARAMETER_NAMES))
        for i, p in enumerate(LINK_PARAMETER_NAMES):
            self.phi[10 * k + i] = toml_number(self.path, f"links.{jn}.{p}",
                                           _required(self.path, f"links.{jn}", lt, p))
        mass = self.phi[10 * k]
        if not mass > 0:   # a body's mass; zero or less inverts the estimator's gravity
            raise DataError("out of range", source=self.path, field=f"links.{jn}.m",
                            value=float(mass), expected="a link mass > 0 kg")

    def check_consistency(self, method: str) -> None:
        """A file of the ``consistent`` method claims a physical robot: each rotor inertia
        >= 0 and each link's pseudo-inertia positive semi-definite (its solver keeps a margin;
        the other methods' standard parameters and rotor inertias need not be physical, only
        their base combinations are identified, and are checked for a positive mass only).

        Raises:
            DataError: Naming the first rotor inertia below zero, or the first link whose
                pseudo-inertia has a negative eigenvalue.
        """
        if method != "consistent":
            return
        rotor = self.drive["rotor_inertia"]
        if np.any(rotor < -FRICTION_TOLERANCE):
            jn = self._joint_names[int(np.argmax(rotor < -FRICTION_TOLERANCE))]
            raise DataError("out of range", source=self.path,
                            field=f"joints.{jn}.rotor_inertia",
                            value=float(rotor[self._joint_names.index(jn)]),
                            expected=">= 0 kg·m² (a rotor's inertia)")
        eig = min_pseudo_inertia_eigenvalues(self.phi)
        for k, value in enumerate(eig):
            scale = max(1.0, float(self.phi[10 * k]))
            if value < -PSEUDO_INERTIA_TOLERANCE * scale:
                jn = self._joint_names[k]
                raise DataError("not a physical body: the link's pseudo-inertia has a "
                                "negative eigenvalue (its inertia and first moments fit no "
                                "mass distribution)", source=self.path,
                                field=f"links.{jn}.Ixx..Izz", value=float(value),
                                expected="a pseudo-inertia eigenvalue >= 0 kg·m² (what "
                                         "'identify --method consistent' writes)")

    def parameters(self) -> DriveModelParameters:
        """The model parameters the tables hold."""
        fr, n = self.drive, self.phi.size // 10
        offset = self.offset if self.has_offset else np.zeros(0)
        presliding = self.presliding if self.presliding_joints else np.zeros(0)
        relaxation = self.relaxation if self.relaxation_joints else np.zeros(0)
        load = self.load if self.load_joints else np.zeros(0)
        if self.model is FrictionModel.STRIBECK:
            return DriveModelParameters(
                phi=self.phi, friction_model=self.model, rotor_inertia=fr["rotor_inertia"],
                stribeck=StribeckParameters(**{key: fr[key] for key in self.keys}),
                offset=offset, presliding=presliding, presliding_relaxation=relaxation,
                load_friction=load)
        return DriveModelParameters(
            phi=self.phi, friction_model=self.model, rotor_inertia=fr["rotor_inertia"],
            coulomb=fr["coulomb"], viscous=fr["viscous"], cbrt=fr.get("cbrt", np.zeros(n)),
            offset=offset, presliding=presliding, presliding_relaxation=relaxation,
            load_friction=load)


def _only(path: Path, where: str, table: dict[str, Any], allowed: set[str]) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise DataError("unknown field", source=path, field=f"{where}.{unknown[0]}",
                        expected=f"one of {sorted(allowed)}")


def _required(path: Path, where: str, table: dict[str, Any], key: str) -> Any:
    if key not in table:
        raise DataError("missing", source=path, field=f"{where}.{key}",
                        expected="the field to be present")
    return table[key]


def _nonnegative(path: Path, field: str, value: object) -> float:
    x = toml_number(path, field, value)
    if x < 0:
        raise DataError("out of range", source=path, field=field, value=x, expected=">= 0")
    return x
