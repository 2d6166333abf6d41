"""The calibration recipe of a robot that is to be guided by hand, and the check that identified
parameters can guide.

    cal = calibrate(excitation, robot, "consistent", friction_sweep=sweep,
                    presliding_test=presliding)
    cal.save("params.toml", robot, sim_seed=rec.sim_seed)
    params = ready_to_guide(load_params("params.toml", robot))

One recipe for every caller (``leadthrough identify``, the demo, the simulator's shipped
guiding parameters):

1. the presliding test, when given, is fitted first (a bad test fails before the long
   identification): each joint's presliding length z₀ and relaxation at rest
   (:mod:`~leadthrough.identification.presliding`);
2. the excitation recording is identified with ``method``; with a friction sweep, the friction
   curve is held to the sweep's (``consistent`` only, :func:`~leadthrough.identification.api.
   identify_with_sweep`);
3. the presliding fit is applied to the identified parameters;
4. the command-to-position lag is measured on the excitation recording where it logged its
   commands (:mod:`~leadthrough.identification.command_lag`; 0 on the in-process simulator,
   which tracks a command in the step it is written).

Parameters can guide (:func:`ready_to_guide`) when their friction was identified with a sweep:
without it the identified friction is 15-24 % low at guiding speeds and a 40 N push barely moves
the robot. ``leadthrough guide`` and ``leadthrough pendant`` check their parameters with it
(opting out with ``--allow-no-sweep``, overriding the lag with ``--command-lag``); a library
caller building a loop itself (:func:`~leadthrough.session.loop_config.build_loop`) calls it
before.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from leadthrough.data.recording import Recording
from leadthrough.dynamics.model import MAX_COMMAND_LAG_S, DriveModelParameters
from leadthrough.errors import DataError
from leadthrough.identification.api import (
    IdentificationResult,
    IdentifyConfig,
    identify,
    identify_with_sweep,
)
from leadthrough.identification.command_lag import CommandLag, measure_command_lag
from leadthrough.identification.friction_sweep import SweepFit
from leadthrough.identification.params_file import ParamsFile, save_params
from leadthrough.identification.presliding import PreslidingFit, fit_presliding
from leadthrough.robot.description import Robot

__all__ = ["Calibration", "calibrate", "check_command_lag", "check_sweep", "ready_to_guide"]


@dataclass(frozen=True)
class Calibration:
    """The outcome of :func:`calibrate`.

    Attributes:
        result: The identification on the excitation recording; its ``params`` are the final
            parameters (with the presliding fit and the command lag where measured).
        sweep: The friction sweep's fit; None without a sweep.
        presliding: The presliding test's fit; None without a test.
        command_lag: The lag measured on the excitation recording; None where it logged no
            commands.
    """

    result: IdentificationResult
    sweep: SweepFit | None = None
    presliding: PreslidingFit | None = None
    command_lag: CommandLag | None = None

    @property
    def params(self) -> DriveModelParameters:
        """The calibrated parameters (those a params file stores)."""
        return self.result.params

    @property
    def friction_sweep(self) -> bool:
        """The friction was held to a friction sweep's curve (the parameters can guide)."""
        return self.sweep is not None

    def params_file(self, path: Path | None = None, sim_seed: int | None = None) -> ParamsFile:
        """The params file :meth:`save` writes, without writing it.

        Args:
            path: Where it is (or will be) stored.
            sim_seed: The simulated robot instance of the recordings; None for a real robot.
        """
        return ParamsFile.from_result(self.result, path, sim_seed,
                                      friction_sweep=self.friction_sweep)

    def save(self, path: str | Path, robot: Robot, sim_seed: int | None = None) -> Path:
        """Write the params file (atomically).

        Args:
            path: Output TOML file.
            robot: The robot calibrated.
            sim_seed: The simulated robot instance of the recordings; None for a real robot.

        Returns:
            The path written.
        """
        return save_params(path, robot, self.result.method, self.params, self.result.stats,
                           sim_seed, friction_sweep=self.friction_sweep)


def calibrate(recording: Recording, robot: Robot, method: str = "consistent",
              config: IdentifyConfig | None = None, *,
              friction_sweep: Recording | None = None,
              presliding_test: Recording | None = None,
              progress: Callable[[int, int], None] | None = None) -> Calibration:
    """Calibrate the robot's model for guiding (the recipe of the module docstring).

    Args:
        recording: The excitation recording (no external force).
        robot: The robot.
        method: Identification method (:data:`~leadthrough.identification.api.METHODS`).
        config: Identification settings.
        friction_sweep: A friction-sweep recording of the same robot; ``consistent`` only.
            Parameters calibrated without one cannot guide (:func:`ready_to_guide`).
        presliding_test: A presliding-test recording of the same robot.
        progress: Progress of the identification, ``progress(done, total)`` (without a sweep).

    Returns:
        The calibration; ``calibrate(...).params`` are the parameters.

    Raises:
        DataError: A sweep with another method than ``consistent``, or as
            :func:`~leadthrough.identification.api.identify`,
            :func:`~leadthrough.identification.api.identify_with_sweep` and
            :func:`~leadthrough.identification.presliding.fit_presliding`.
    """
    if friction_sweep is not None and method != "consistent":
        raise DataError("a friction sweep is used by the consistent method only",
                        field="method", value=method,
                        expected="'consistent' with a friction sweep")
    # the presliding test is fitted first: a bad test fails before the long identification
    pre = None if presliding_test is None else fit_presliding(presliding_test, robot)
    sweep = None
    if friction_sweep is not None:
        with_sweep = identify_with_sweep(recording, friction_sweep, robot, config)
        result, sweep = with_sweep.result, with_sweep.sweep
    else:
        result = identify(recording, robot, method, config, progress=progress)
    params = result.params if pre is None else pre.applied_to(result.params)
    lag = measure_command_lag(recording)  # None where the recording logged no commands
    if lag is not None:
        params = replace(params, command_lag=lag.lag_s)
    return Calibration(result=replace(result, params=params), sweep=sweep, presliding=pre,
                       command_lag=lag)


def check_sweep(params: ParamsFile, allow_no_sweep: bool = False, *,
                opt_out: str = "allow_no_sweep=True") -> ParamsFile:
    """``params`` if they can guide: identified with a friction sweep, or ``allow_no_sweep``.

    Args:
        params: Identified parameters.
        allow_no_sweep: Guide with parameters identified without a sweep anyway.
        opt_out: How the caller's user opts out, for the message (e.g. ``--allow-no-sweep``).

    Raises:
        DataError: Naming the file, ``meta.friction_sweep`` and the ways out.
    """
    if not (params.friction_sweep or allow_no_sweep):
        raise DataError(
            "these parameters cannot guide: their friction was not measured at guiding speeds",
            source=params.path, field="meta.friction_sweep", value=False,
            expected="true: record a friction sweep (leadthrough excite --sweep, then record) "
                     "and identify with --method consistent --friction-sweep; or pass "
                     f"{opt_out} to guide anyway (the identified friction is then 15-24 %"
                     " low at guiding speeds: a 40 N push barely moves the robot)")
    return params


def check_command_lag(params: ParamsFile, lag: float | None, *,
                      field: str = "command_lag") -> ParamsFile:
    """``params`` with ``lag`` [s] in place of their measured command lag if given (when the
    params come from another interface than the one guided, e.g. identified in-process and
    guided over a driver).

    Args:
        params: Identified parameters.
        lag: The interface's command-to-position lag [s]; None: the params' own.
        field: The setting's name, for the message (e.g. ``--command-lag``).

    Raises:
        DataError: Not a finite lag from 0 to ``MAX_COMMAND_LAG_S``.
    """
    if lag is None:
        return params
    if not (np.isfinite(lag) and 0.0 <= lag <= MAX_COMMAND_LAG_S):
        raise DataError("out of range", field=field, value=lag,
                        expected=f"0 <= seconds <= {MAX_COMMAND_LAG_S:g}")
    return replace(params, params=replace(params.params, command_lag=float(lag)))


def ready_to_guide(params: ParamsFile, *, allow_no_sweep: bool = False,
                   command_lag: float | None = None) -> ParamsFile:
    """The parameters a guiding loop runs with, checked that they can guide.

    Args:
        params: Identified parameters.
        allow_no_sweep: Guide with parameters identified without a friction sweep anyway.
        command_lag: The guided interface's command lag [s] in place of the measured one.

    Returns:
        ``params``, with ``command_lag`` if given.

    Raises:
        DataError: No friction sweep and not ``allow_no_sweep`` (:func:`check_sweep`), or a
            lag out of range (:func:`check_command_lag`).
    """
    return check_sweep(check_command_lag(params, command_lag), allow_no_sweep)
