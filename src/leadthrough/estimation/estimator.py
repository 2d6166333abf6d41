"""Real-time external force estimation (paper eq. 27–30), ruckig style.

    est = ExternalForceEstimator(robot, params, noise_mean, EstimatorConfig())
    inp, out = est.make_input(), est.make_output()
    est.reset(q0)
    every 1 ms: inp.t, inp.q[:], inp.current[:] = ...; status = est.update(inp, out)

Two estimators share the interface:

* ``direct`` (the paper's): τ_ext = τ̂_d(q, q̇, q̈) − τ̂_j(i) (eq. 27) with q̇, q̈ from a causal
  state-variable filter, then a first-order low-pass (default 3 Hz, human motion), then the
  identified mean noise τ̄_ω is removed (eq. 30): τ_ext ← τ_ext + τ̄_ω (τ_ω = τ_j − τ_d).
* ``momentum``: De Luca's generalized-momentum observer, no q̈ needed:
  r = K_O·(p − p₀ − ∫(τ_j + Cᵀq̇ − g − τ_f − τ_0 + r) dt), p = (M(q) + M_j)·q̇, which tracks τ_ext
  with bandwidth K_O (set to the same cut-off).

The joint torque is mapped to a wrench at the TCP through a damped pseudo-inverse of Jᵀ
(eq. 28–30): w = (J Jᵀ + λ²·1)⁻¹·J·τ_ext, λ² = λ_max²·(1 − (μ/μ₀)²) when the manipulability
μ = √det(J Jᵀ) falls below μ₀, so the wrench shrinks toward zero near a singularity instead of
blowing up. The force-only fit (``axes="force"``) is damped instead by the TCP's shortest lever
arm, which a wrist singularity leaves intact (``kernels.wrench_from_torque``). The frame is the
base (axes of the base, at the TCP) or the tool.

Per sample, ``update`` makes two compiled calls (:mod:`leadthrough.estimation.fused`: the
state lives in a few packed arrays) around two or four Pinocchio calls (RNEA or
CRBA/Coriolis/gravity, and the TCP Jacobian); ``benchmarks/estimator_speed.py`` measures it.

``update`` validates nothing but the input's sizes and finiteness (configuration is checked once
at construction), never raises, never reads the clock: a non-finite sample (q, current, t, and
``qd_cmd`` when the friction follows the command), or a result that is not finite (an input
too large for the filters), sets ``Status.FAULT_NONFINITE``; input arrays of the wrong size set
``Status.FAULT_INPUT_SIZE``. Either keeps the last valid output and latches until ``reset``.
Missed samples (t advanced by k ≥ 2 periods) are bridged: the differentiator steps through q
interpolated over the gap, so the jump of q is not read as one period's velocity.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.dynamics.model import MAX_PRESLIDING_RAD, DriveModelParameters
from leadthrough.errors import DataError, check_fields
from leadthrough.estimation import fused, kernels
from leadthrough.estimation.filters import FirstOrderLowPass, StateVariableDifferentiator
from leadthrough.estimation.identified_model import IdentifiedModel
from leadthrough.robot.description import Robot

__all__ = [
    "EstimatorConfig",
    "EstimatorInput",
    "EstimatorOutput",
    "ExternalForceEstimator",
    "Status",
]

Array = NDArray[np.float64]


class Status(IntEnum):
    """Result of one update."""

    OK = 0
    WARMING_UP = 1
    TARING = 2
    #: A non-finite input, or a result that overflowed (latched until ``reset``).
    FAULT_NONFINITE = -1
    #: ``q``, ``current`` (or ``qd_cmd``, when used) not of shape (n,) (latched until ``reset``).
    FAULT_INPUT_SIZE = -2


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
        presliding_rad: z₀ of the ``"command"`` friction while a joint is commanded to move
            [rad]: the friction turns over a commanded displacement of a few z₀, which is the
            gear's presliding plus the servo's lag. A smaller z₀ turns the model's friction
            ahead of the gear's, a larger one behind it: on the simulated er20 (gear presliding
            1.5–2.5e-4 rad plus the servo's lag) 1e-3 stalls a 40 N start and 2e-4 over-reads
            starts and reversals by up to 2×; 4e-4 follows both. A joint commanded to stand
            still is driven by its measured displacement instead, with the params' identified
            z₀ per joint (``DriveModelParameters.presliding``, from a presliding test), or
            this value where none was identified.
        presliding_play_counts: Width of the play operator on the encoder that drives the
            friction at rest [encoder counts] (``presliding_kernels.play_step``): chatter
            within it moves nothing. 0 passes every count.
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
    presliding_rad: float = 4e-4
    presliding_play_counts: float = 2.5
    friction_weighting: float = 0.0

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
            ("presliding_rad", 0 < self.presliding_rad <= MAX_PRESLIDING_RAD,
             f"0 < z0 <= {MAX_PRESLIDING_RAD:g} rad"),
            ("presliding_play_counts", 0 <= self.presliding_play_counts < 1e6,
             "0 <= width < 1e6 counts"),
            ("friction_weighting",
             0 <= self.friction_weighting < np.inf
             and (self.friction_weighting == 0
                  or (self.axes == "force" and self.friction_velocity == "command")),
             "a finite value >= 0; > 0 only with axes='force' and friction_velocity='command'"),
        ])


@dataclass
class EstimatorInput:
    """One sample (write into the arrays in place).

    Attributes:
        t: Time [s] (an advance of k ≥ 2 periods since the last sample: k − 1 samples were
            missed, and the differentiator bridges them).
        q: Joint positions [rad], shape (n,).
        current: Motor currents [A], shape (n,).
        qd_cmd: Joint velocity commanded to the servo for this period [rad/s], shape (n,)
            (used with ``friction_velocity="command"``).
    """

    t: float
    q: Array
    current: Array
    qd_cmd: Array = field(default_factory=lambda: np.zeros(0))


@dataclass
class EstimatorOutput:
    """The estimate, filled by ``update``.

    Attributes:
        tau_ext: External joint torque [N·m], shape (n,).
        wrench: External wrench at the TCP [N, N·m], shape (6,) (force first), in the
            configured frame.
        manipulability: μ = √det(J Jᵀ) at the current pose.
        damping: λ used in the pseudo-inverse [m] (``axes="force"``: from the shortest lever
            arm, see ``EstimatorConfig.min_force_lever``).
        qd: Estimated joint velocities [rad/s], shape (n,).
        status: Status of the last update.
    """

    tau_ext: Array
    wrench: Array
    manipulability: float = 0.0
    damping: float = 0.0
    qd: Array = field(default_factory=lambda: np.zeros(0))
    status: Status = Status.WARMING_UP


class ExternalForceEstimator:
    """External force estimator (direct eq. 27 or momentum observer).

    Args:
        robot: The robot.
        params: Identified parameters (from calibration).
        noise_mean: τ̄_ω per joint [N·m] from calibration (params file ``[noise] mean``).
        config: Settings.
        noise_std: σ of τ_ω per joint [N·m] (params file ``[noise] std``); weights of the
            ``axes="force"`` fit (default: equal weights).
    """

    def __init__(self, robot: Robot, params: DriveModelParameters, noise_mean: Array,
                 config: EstimatorConfig | None = None, noise_std: Array | None = None
                 ) -> None:
        self.config = cfg = config if config is not None else EstimatorConfig()
        n = robot.n
        noise_mean = np.asarray(noise_mean, dtype=float)
        if noise_mean.shape != (n,):
            raise DataError("wrong size", field="noise_mean", value=noise_mean.shape,
                            expected=f"({n},)")
        std = np.ones(n) if noise_std is None else np.asarray(noise_std, dtype=float)
        if std.shape != (n,) or not np.all(std > 0):
            raise DataError("wrong size or not positive", field="noise_std", value=std.tolist(),
                            expected=f"{n} positive values")
        self.robot = robot
        self.model = mdl = IdentifiedModel(robot, params, cfg.standstill_velocity)
        self._ref = pin.LOCAL_WORLD_ALIGNED if cfg.frame == "base" else pin.LOCAL
        # packed state of the compiled sample (leadthrough.estimation.fused)
        const = self._const = np.zeros((fused.CONST_ROWS, n))
        const[:kernels.FRICTION_ROWS] = mdl.friction_rows
        const[fused.TORQUE_PER_AMP] = robot.torque_per_amp
        const[fused.STD] = std
        const[fused.ROTOR] = mdl.rotor
        const[fused.OFFSET] = mdl.offset
        const[fused.NOISE_MEAN] = noise_mean if cfg.remove_mean_noise else 0.0
        const[fused.REST_PRESLIDING] = (params.presliding if params.presliding.size
                                        else cfg.presliding_rad)
        const[fused.HALF_PLAY] = 0.5 * cfg.presliding_play_counts * robot.encoder_resolution
        st = self._settings = np.zeros(fused.SETTINGS_SLOTS)
        st[fused.SVF:fused.SVF + 7] = StateVariableDifferentiator(
            n, cfg.velocity_cutoff_hz, cfg.dt).coef
        st[fused.DT] = cfg.dt
        st[fused.PRESLIDING_RAD] = cfg.presliding_rad
        st[fused.ENVELOPE_DECAY] = float(np.exp(-cfg.dt * np.pi * cfg.output_cutoff_hz))
        st[fused.KAPPA] = cfg.friction_weighting
        st[fused.ALPHA] = FirstOrderLowPass(n, cfg.output_cutoff_hz, cfg.dt).alpha
        st[fused.OBSERVER_GAIN] = 2.0 * np.pi * cfg.output_cutoff_hz
        st[fused.MU0] = cfg.manipulability_threshold
        st[fused.MAX_DAMPING] = cfg.max_damping
        st[fused.MIN_LEVER] = cfg.min_force_lever
        c = self._counters = np.zeros(fused.COUNTER_SLOTS, dtype=np.int64)
        c[fused.WARM] = round(cfg.warm_up_s / cfg.dt)
        c[fused.STRIBECK] = mdl.stribeck
        c[fused.FRICTION_COMMAND] = cfg.friction_velocity == "command"
        c[fused.WEIGH] = cfg.friction_weighting > 0
        c[fused.DIRECT] = cfg.method == "direct"
        c[fused.FORCE_ONLY] = cfg.axes == "force"
        self._state = np.zeros((fused.STATE_ROWS, n))
        # views handed to Pinocchio every sample
        self._q, self._qd, self._qdd = (self._state[r] for r in (fused.POS, fused.VEL,
                                                                 fused.ACC))
        self._unused = np.zeros((n, n))
        self._scratch = np.zeros((2, 6, 6))
        self._info = np.zeros(2)
        self._last_wrench = np.zeros(6)
        self._tare_len = round(cfg.tare_s / cfg.dt)
        self.reset(np.zeros(n))

    def make_input(self) -> EstimatorInput:
        """A preallocated input."""
        n = self.robot.n
        return EstimatorInput(t=0.0, q=np.zeros(n), current=np.zeros(n), qd_cmd=np.zeros(n))

    def make_output(self) -> EstimatorOutput:
        """A preallocated output."""
        n = self.robot.n
        return EstimatorOutput(tau_ext=np.zeros(n), wrench=np.zeros(6), qd=np.zeros(n))

    def reset(self, q: Array) -> None:
        """Restart at rest at ``q``: clears a latched fault and the tare (re-tares if set)."""
        s, c = self._state, self._counters
        s[:] = 0.0
        s[fused.POS] = q
        np.divide(1.0, self._const[fused.STD], out=s[fused.WEIGHT])
        c[fused.TARE_LEFT] = c[fused.TARE_TAKEN] = self._tare_len
        c[fused.REZERO_LEFT] = c[fused.SAMPLES] = c[fused.FAULT] = 0
        c[fused.FIRST] = 1
        c[fused.STATUS] = fused.STATUS_WARMING_UP
        self._last_wrench[:] = 0.0

    def update(self, inp: EstimatorInput, out: EstimatorOutput) -> Status:
        """Process one sample; fills ``out``; never raises."""
        st, c, s, k, info = (self._settings, self._counters, self._state, self._const,
                             self._info)
        if not fused.sample_front(inp.q, inp.current, inp.qd_cmd, inp.t, k, st, c, s):
            out.tau_ext[:] = s[fused.LAST_TAU]
            out.wrench[:] = self._last_wrench
            out.status = _STATUS[c[fused.STATUS]]
            return out.status
        mdl = self.model
        m, d, q, u = mdl.model, mdl.data, self._q, self._unused
        J = pin.computeFrameJacobian(m, d, q, self.robot.tcp_frame_id, self._ref)
        if c[fused.DIRECT]:
            rnea = pin.rnea(m, d, q, self._qd, self._qdd)
            fused.sample_back(rnea, u, u, q, J, k, st, c, s, out.tau_ext, out.wrench, out.qd,
                              self._last_wrench, self._scratch, info)
        else:
            M = pin.crba(m, d, q)  # upper triangle only
            C = pin.computeCoriolisMatrix(m, d, q, self._qd)
            g = pin.computeGeneralizedGravity(m, d, q)
            fused.sample_back(q, M, C, g, J, k, st, c, s, out.tau_ext, out.wrench, out.qd,
                              self._last_wrench, self._scratch, info)
        out.manipulability = info[0]
        out.damping = info[1]
        out.status = _STATUS[c[fused.STATUS]]
        return out.status

    def rezero(self, samples: int) -> None:
        """Zero-velocity update: average τ_ext over the next ``samples`` samples and subtract
        it from then on, status staying OK (real-time safe: no validation, no allocation).

        For the guiding loop once the commanded motion has stopped and settled (the drives keep
        part of their friction after a stop, which no rigid-body model predicts). The robot
        must be untouched meanwhile; :meth:`cancel_rezero` if it moves again.

        Args:
            samples: Window length [samples], >= 1 (NaN or less: 1; capped at 2³¹).
        """
        self._state[fused.REZERO_SUM] = 0.0
        c = self._counters
        # no exception for any argument: NaN or < 1 is one sample, a huge window is capped
        c[fused.REZERO_LEFT] = c[fused.REZERO_TAKEN] = (
            int(min(samples, _MAX_WINDOW)) if samples >= 1 else 1)

    def cancel_rezero(self) -> None:
        """Abandon a :meth:`rezero` in progress (the tare is kept as it was)."""
        self._counters[fused.REZERO_LEFT] = 0

    @property
    def rezeroing(self) -> bool:
        """A :meth:`rezero` is in progress."""
        return bool(self._counters[fused.REZERO_LEFT] > 0)

    def tare(self, duration_s: float) -> None:
        """Start taring now: average τ_ext over ``duration_s`` and subtract it from then on.

        The robot must be untouched meanwhile (status TARING). Call outside the hot path (it
        validates its argument).

        Raises:
            DataError: Duration not positive.
        """
        if not (np.isfinite(duration_s) and duration_s > 0):
            raise DataError("tare duration must be > 0", field="duration_s", value=duration_s,
                            expected="> 0 s")
        self._state[fused.TARE_SUM] = 0.0
        c = self._counters
        c[fused.TARE_LEFT] = c[fused.TARE_TAKEN] = max(1, round(duration_s / self.config.dt))

    @property
    def tare_torque(self) -> Array:
        """The joint torque subtracted by taring [N·m], shape (n,) (a copy)."""
        return self._state[fused.TARE].copy()


#: Longest re-zero window [samples] (about 25 days at 1 kHz).
_MAX_WINDOW = 2**31

#: Status by the compiled sample's code.
_STATUS = {fused.STATUS_OK: Status.OK, fused.STATUS_WARMING_UP: Status.WARMING_UP,
           fused.STATUS_TARING: Status.TARING, fused.STATUS_FAULT: Status.FAULT_NONFINITE,
           fused.STATUS_FAULT_SIZE: Status.FAULT_INPUT_SIZE}
