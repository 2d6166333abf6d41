"""The external force estimator's settings (:class:`EstimatorConfig`, validated once) and the
presliding length each joint's friction uses (:func:`presliding_lengths`); the estimator itself:
:mod:`leadthrough.estimation.estimator`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.dynamics.model import MAX_COMMAND_LAG_S, MAX_PRESLIDING_RAD
from leadthrough.errors import DataError, check_fields
from leadthrough.estimation.friction_torque import COMMAND_HISTORY

__all__ = ["DEFAULT_PRESLIDING_RAD", "EstimatorConfig", "command_delay_samples",
           "presliding_lengths"]

Array = NDArray[np.float64]

#: z₀ [rad] where no presliding test measured it: 1.4 arcmin, within the lost motion that
#: catalogues of the precision reducers in industrial robot joints (RV / cycloidal, strain-wave)
#: specify, 1-1.5 arcmin at ±3 % of rated torque (lost motion bounds the displacement over which
#: the gear's torque turns over). Robot-independent and coarse: run the presliding test
#: (``leadthrough excite --presliding``) to measure each joint's z₀.
DEFAULT_PRESLIDING_RAD = 4e-4


@dataclass(frozen=True)
class EstimatorConfig:
    """Settings, validated once.

    Attributes:
        method: ``"direct"`` (eq. 27) or ``"momentum"`` (observer).
        dt: Sample period [s].
        velocity_cutoff_hz: Cut-off of the causal differentiator [Hz].
        output_cutoff_hz: Cut-off of the τ_ext low-pass / observer bandwidth [Hz].
        frame: ``"base"`` (base axes at the TCP) or ``"tool"`` (TCP axes).
        axes: ``"wrench"``: all six components through the damped inverse of Jᵀ (eq. 28–30);
            ``"force"``: the contact is a pure force at the TCP (a hand on a handle), so the
            three force components are fitted to all n joint torques by least squares weighted
            by the calibration's residual σ per joint, which is much less noisy; the torque
            components are reported as zero.
        remove_mean_noise: Add back τ̄_ω (eq. 30).
        manipulability_threshold: μ₀ below which the full wrench's damping starts.
        max_damping: λ_max [m].
        min_force_lever: ``axes="force"``: ℓ₀ [m] below which the force fit's damping starts,
            ℓ the TCP's shortest lever arm about the joints (the smallest singular value of the
            translational Jacobian). The force fit needs only that to be non-zero: at the wrist
            singularity (μ → 0) a force at the TCP stays well observed. 0 disables it.
        warm_up_s: Time after reset during which the status is WARMING_UP [s].
        tare_s: After warm-up, average τ_ext over this long and subtract it from then on
            (status TARING meanwhile); 0 disables. Like taring a force sensor: the robot must
            be untouched meanwhile. It removes the static model error at the tare pose (the
            identified model's gravity error where the excitation did not go, the drives'
            bias), which eq. 30's global mean cannot; the error returns as the pose changes.
            :meth:`ExternalForceEstimator.tare` re-tares on request.
        standstill_velocity: v_ε of the smoothed friction sign [rad/s].
        friction_velocity: Velocity the friction term uses: ``"measured"`` (estimated from
            the encoders) or ``"command"`` (``EstimatorInput.qd_cmd``, the joint velocity
            commanded to the position servo). While guiding, the robot moves because it is
            commanded to, and at the low speeds of a start the measured velocity is mostly
            noise while the drive's friction is at its highest (Stribeck): the command gives
            friction its true direction and the identified Stribeck curve its level. The
            friction then has memory (eq. 15 as the steady state of a LuGre/Dahl model, see
            ``presliding_kernels.presliding_friction_step``): after a stop, the drives keep the
            friction they had while moving, and so does the model.
        presliding_length: z₀ of the ``"command"`` friction while a joint is commanded to move
            [rad]: the friction turns over a commanded displacement of a few z₀, the gear's
            presliding plus the servo's lag. A smaller z₀ turns the model's friction ahead of
            the gear's, a larger one behind it. None (the default):
            :data:`DEFAULT_PRESLIDING_RAD`. The presliding test's z₀
            (``DriveModelParameters.presliding``, :func:`leadthrough.identification.presliding.
            fit_presliding`; the params file's ``joints.*.presliding``) measures the gear's part
            alone. It is used where the encoder drives the friction (else
            :data:`DEFAULT_PRESLIDING_RAD`): at rest, and at or below
            ``slow_command_velocity``. On the simulated er20's tuning instances 1-2, the
            measured 1-3e-4 rad for the command as well made the force in motion worse (push-x
            17.5/13.8 → 20.0/17.2 N RMS). Nothing here comes from the simulator's own bristle
            lengths (issue 24).
        command_lag: The ``"command"`` friction follows the commanded velocity this much later
            [s], rounded to whole samples of ``dt``: the time a command takes to show in the
            measured position (the interface's transport and the servo). Sent at once, the
            command would turn the model's friction over that much before the gear's at a
            reversal (one 8 ms cycle on the emulated J519). None (the
            default): the lag measured on the identification recording
            (``DriveModelParameters.command_lag``, the params file's ``[meta] command_lag``),
            0 where none was measured. It must be the lag of the interface this estimator runs
            on: parameters identified in-process or from logs and used over a controller's
            interface need it given here (``guide --command-lag``).
        presliding_play_counts: Width of the play operator on the encoder that drives the
            friction at rest [encoder counts] (``presliding_kernels.play_step``): chatter
            within it moves nothing. 0 passes every count.
        slow_command_velocity: With ``"command"`` friction, a joint commanded no faster than
            this [rad/s] (and not at rest) has its friction driven by its encoder, as at rest,
            with its measured z₀; faster, by the command. A joint that creeps, reverses slowly
            or dithers about zero while the TCP moves (a wrist, typically) sticks while its
            servo builds the torque to move it, so its gear stays in presliding, which the
            encoder sees and the command does not. Applied only where the params carry a
            presliding test's z₀ (without it, the encoder's turnover length is a guess, and a
            start from rest can stall). 0 (the default here; the guiding loop's default is
            0.01 rad/s, ``leadthrough.session.loop_config``): only a joint commanded to stand
            still.
        friction_weighting: κ of the ``axes="force"`` fit with ``"command"`` friction: each
            joint's weight 1/σ_j becomes 1/√(σ_j² + (κ·u_j)²), u_j the friction's uncertainty
            (see ``kernels.friction_weights``), held over two time constants of the output
            filter. A joint whose friction is turning over (a wrist reversing while the TCP moves
            straight) then counts less than the others, which a pure force at the TCP leaves
            free to (six torques, three unknowns). 0 keeps the fixed weights 1/σ_j.
    """

    method: str = "direct"
    dt: float = 1e-3
    velocity_cutoff_hz: float = 20.0
    output_cutoff_hz: float = 3.0
    frame: str = "base"
    axes: str = "wrench"
    remove_mean_noise: bool = True
    manipulability_threshold: float = 0.02
    max_damping: float = 0.05
    min_force_lever: float = 0.05
    warm_up_s: float = 0.5
    tare_s: float = 0.0
    standstill_velocity: float = 0.02
    friction_velocity: str = "measured"
    presliding_length: float | None = None
    command_lag: float | None = None
    presliding_play_counts: float = 2.5
    friction_weighting: float = 0.0
    slow_command_velocity: float = 0.0

    def __post_init__(self) -> None:
        check_fields("estimator", self, [
            ("method", self.method in ("direct", "momentum"), "'direct' or 'momentum'"),
            ("dt", 0 < self.dt <= 0.02, "0 < dt <= 0.02 s"),
            ("velocity_cutoff_hz", 0 < self.velocity_cutoff_hz < 0.5 / self.dt,
             "0 < f < Nyquist"),
            ("output_cutoff_hz", 0 < self.output_cutoff_hz < 0.5 / self.dt, "0 < f < Nyquist"),
            ("frame", self.frame in ("base", "tool"), "'base' or 'tool'"),
            ("axes", self.axes in ("wrench", "force"), "'wrench' or 'force'"),
            ("manipulability_threshold", self.manipulability_threshold >= 0, ">= 0"),
            ("max_damping", self.max_damping >= 0, ">= 0"),
            ("min_force_lever", 0 <= self.min_force_lever < np.inf, "a finite value >= 0 m"),
            ("warm_up_s", self.warm_up_s >= 0, ">= 0 s"),
            ("tare_s", self.tare_s >= 0, ">= 0 s"),
            ("standstill_velocity", self.standstill_velocity > 0, "> 0 rad/s"),
            ("friction_velocity", self.friction_velocity in ("measured", "command"),
             "'measured' or 'command'"),
            ("presliding_length",
             self.presliding_length is None
             or 0 < self.presliding_length <= MAX_PRESLIDING_RAD,
             f"0 < z0 <= {MAX_PRESLIDING_RAD:g} rad"),
            ("command_lag",
             self.command_lag is None or 0 <= self.command_lag <= MAX_COMMAND_LAG_S,
             f"None or 0 to {MAX_COMMAND_LAG_S:g} s"),
            ("presliding_play_counts", 0 <= self.presliding_play_counts < 1e6,
             "0 <= width < 1e6 counts"),
            ("slow_command_velocity", 0 <= self.slow_command_velocity < np.inf,
             "a finite value >= 0 rad/s"),
            ("friction_weighting",
             0 <= self.friction_weighting < np.inf
             and (self.friction_weighting == 0
                  or (self.axes == "force" and self.friction_velocity == "command")),
             "a finite value >= 0; > 0 only with axes='force' and friction_velocity='command'"),
        ])


def presliding_lengths(identified: Array, n: int, chosen: float | None) -> Array:
    """z₀ per joint [rad], shape (n,): ``chosen`` if given, else the presliding test's
    ``identified`` z₀ (shape (n,), or empty), else :data:`DEFAULT_PRESLIDING_RAD`."""
    if chosen is not None:
        return np.full(n, chosen)
    if identified.size:
        return np.asarray(identified, dtype=float)
    return np.full(n, DEFAULT_PRESLIDING_RAD)


def command_delay_samples(lag: float, dt: float) -> int:
    """The command lag ``lag`` [s] in whole samples of ``dt`` [s] (see
    ``EstimatorConfig.command_lag``).

    Raises:
        DataError: More samples than the estimator's ring of past commands holds.
    """
    samples = round(lag / dt)
    if not 0 <= samples < COMMAND_HISTORY:
        raise DataError("command lag too long for the sample period", field="command_lag",
                        value=lag, expected=f"below {COMMAND_HISTORY} samples of {dt:g} s")
    return samples
