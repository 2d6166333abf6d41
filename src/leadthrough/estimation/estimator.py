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

Per sample, ``update`` makes two compiled calls (:mod:`leadthrough.estimation.estimator_step`:
the state lives in one named record) around two or four Pinocchio calls (RNEA or
CRBA/Coriolis/gravity, and the TCP Jacobian); ``benchmarks/estimator_speed.py`` measures it.

``update`` validates nothing but the input's sizes and finiteness (configuration is checked once
at construction), never raises, never reads the clock: a non-finite sample (q, current, t, and
``qd_cmd`` when the friction follows the command), or a result that is not finite (an input
too large for the filters), sets ``EstimatorStatus.FAULT_NONFINITE``; an input or output made for
another robot sets ``EstimatorStatus.FAULT_INPUT_SIZE``. Either keeps the last valid output and
latches until ``reset``.
Missed samples (t advanced by k ≥ 2 periods) are bridged: the differentiator steps through q
interpolated over the gap, so the jump of q is not read as one period's velocity.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from leadthrough.dynamics.model import DriveModelParameters
from leadthrough.dynamics.presliding import relaxation_factor
from leadthrough.errors import DataError
from leadthrough.estimation.estimator_config import (
    DEFAULT_PRESLIDING_RAD,
    EstimatorConfig,
    command_delay_samples,
    presliding_lengths,
)
from leadthrough.estimation.estimator_step import (
    EstimatorStatus,
    estimator_dtype,
    finish_sample,
    input_dtype,
    output_dtype,
    read_sample,
)
from leadthrough.estimation.filters import differentiator_coefficients, low_pass_alpha
from leadthrough.estimation.identified_model import IdentifiedModel
from leadthrough.robot.description import Robot
from leadthrough.state_records import RecordView, field, new_record, view

__all__ = [
    "DEFAULT_PRESLIDING_RAD",
    "EstimatorConfig",
    "EstimatorInput",
    "EstimatorOutput",
    "EstimatorStatus",
    "ExternalForceEstimator",
    "presliding_lengths",
]

Array = NDArray[np.float64]


class EstimatorInput(RecordView):
    """One sample (``ExternalForceEstimator.make_input``; fill the arrays in place).

    Args:
        n: Number of joints.
    """

    __slots__ = ()

    t = field("t", "Time [s] (an advance of k ≥ 2 periods since the last sample: k − 1 samples "
                   "were missed, and the differentiator bridges them).", float)
    q = field[Array]("q", "Joint positions [rad], shape (n,).")
    current = field[Array]("current", "Motor currents [A], shape (n,).")
    qd_cmd = field[Array]("qd_cmd", "Joint velocity commanded to the servo for this period "
                                    "[rad/s], shape (n,) (used with "
                                    "``friction_velocity=\"command\"``).")

    def __init__(self, n: int) -> None:
        super().__init__(input_dtype(n))


class EstimatorOutput(RecordView):
    """The estimate, filled by ``update`` (``ExternalForceEstimator.make_output``).

    Args:
        n: Number of joints.
    """

    __slots__ = ()

    tau_ext = field[Array]("tau_ext", "External joint torque [N·m], shape (n,).")
    wrench = field[Array]("wrench", "External wrench at the TCP [N, N·m], shape (6,) (force "
                                    "first), in the configured frame.")
    qd = field[Array]("qd", "Estimated joint velocities [rad/s], shape (n,).")
    manipulability = field("manipulability", "μ = √det(J Jᵀ) at the current pose.", float)
    damping = field("damping", "λ used in the pseudo-inverse [m] (``axes=\"force\"``: from the "
                               "shortest lever arm, see ``EstimatorConfig.min_force_lever``).",
                    float)
    status = field("status", "Status of the last update.", EstimatorStatus)

    def __init__(self, n: int) -> None:
        super().__init__(output_dtype(n))
        self.status = EstimatorStatus.WARMING_UP


class ExternalForceEstimator:
    """External force estimator (direct eq. 27 or momentum observer).

    Args:
        robot: The robot.
        params: Identified parameters (from calibration).
        noise_mean: τ̄_ω per joint [N·m] from calibration (params file ``[noise] mean``).
        config: Settings.
        noise_std: σ of τ_ω per joint [N·m] (params file ``[noise] std``); weights of the
            ``axes="force"`` fit (default: equal weights).

    Attributes:
        record: The estimator's record (:func:`~leadthrough.estimation.estimator_step.
            estimator_dtype`): settings, constants and state, read by field.
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
        self.model = mdl = IdentifiedModel(robot, params)
        self._ref = pin.LOCAL_WORLD_ALIGNED if cfg.frame == "base" else pin.LOCAL
        self.record = new_record(estimator_dtype(n))
        s = self._s = view(self.record)
        s.friction = mdl.friction[0]
        s.inverse_standstill_velocity = 1.0 / cfg.standstill_velocity
        s.torque_per_amp = robot.torque_per_amp
        s.noise_std = std
        s.rotor_inertia = mdl.rotor
        s.offset = mdl.offset
        s.noise_mean = noise_mean if cfg.remove_mean_noise else 0.0
        s.rest_presliding = presliding_lengths(params.presliding, n, None)
        s.rest_decay = relaxation_factor(params.presliding_relaxation, cfg.dt) \
            if params.presliding_relaxation.size else 1.0
        s.command_presliding = presliding_lengths(np.empty(0), n, cfg.presliding_length)
        # the encoder drives a creeping joint's friction only with a measured z₀
        s.slow_command = cfg.slow_command_velocity if params.presliding.size else 0.0
        s.play_half_width = 0.5 * cfg.presliding_play_counts * robot.encoder_resolution
        lag = params.command_lag if cfg.command_lag is None else cfg.command_lag
        s.command_delay = command_delay_samples(lag, cfg.dt)
        self._configure(cfg)
        # views handed to Pinocchio every sample
        self._q, self._qd, self._qdd = s.q_filtered, s.qd_filtered, s.qdd_filtered
        self._unused = np.zeros((n, n))
        self._layouts = (input_dtype(n), output_dtype(n))
        self._direct = cfg.method == "direct"
        self._tare_len = round(cfg.tare_s / cfg.dt)
        self.reset(np.zeros(n))

    def _configure(self, cfg: EstimatorConfig) -> None:
        """The record's settings."""
        s = self._s
        s.dt = cfg.dt
        s.differentiator = differentiator_coefficients(cfg.velocity_cutoff_hz, cfg.dt)[0]
        s.low_pass_alpha = low_pass_alpha(cfg.output_cutoff_hz, cfg.dt)
        s.observer_gain = 2.0 * np.pi * cfg.output_cutoff_hz
        s.direct = cfg.method == "direct"
        s.force_only = cfg.axes == "force"
        s.manipulability_threshold = cfg.manipulability_threshold
        s.max_damping = cfg.max_damping
        s.min_force_lever = cfg.min_force_lever
        s.friction_follows_command = cfg.friction_velocity == "command"
        s.weigh_by_friction = cfg.friction_weighting > 0
        s.friction_weighting = cfg.friction_weighting
        s.envelope_decay = float(np.exp(-cfg.dt * np.pi * cfg.output_cutoff_hz))
        s.warm_up_samples = round(cfg.warm_up_s / cfg.dt)

    def make_input(self) -> EstimatorInput:
        """A preallocated input."""
        return EstimatorInput(self.robot.n)

    def make_output(self) -> EstimatorOutput:
        """A preallocated output."""
        return EstimatorOutput(self.robot.n)

    def reset(self, q: Array) -> None:
        """Restart at rest at ``q``: clears a latched fault and the tare (re-tares if set)."""
        s = self._s
        for name in _STATE_FIELDS:
            getattr(s, name)[:] = 0.0
        s.last_t = 0.0
        s.q_filtered = q
        s.joint_weight = 1.0 / s.noise_std
        s.tare_left = s.tare_taken = self._tare_len
        s.rezero_left = s.samples = s.command_slot = 0
        s.faulted = False
        s.first = True
        s.status = EstimatorStatus.WARMING_UP

    def warm_up(self) -> None:
        """Load (or compile) the sample's compiled functions, on copies of the records: the next
        sample then runs at its steady-state speed. Call it before a real-time loop starts; it
        changes nothing of the estimator's state."""
        est = self.record.copy()
        inp, out = self.make_input(), self.make_output()
        inp.q[:] = self._q
        read_sample(inp.record, est, out.record)
        mdl, q = self.model, est["q_filtered"][0]
        jacobian = pin.computeFrameJacobian(mdl.model, mdl.data, q, self.robot.tcp_frame_id,
                                            self._ref)
        finish_sample(q, self._unused, self._unused, q, jacobian, est, out.record)

    def update(self, inp: EstimatorInput, out: EstimatorOutput) -> EstimatorStatus:
        """Process one sample; fills ``out``; never raises."""
        # a tuple compares its items by identity first: fast for the layouts of make_input
        if (inp.record.dtype, out.record.dtype) != self._layouts:
            return self._wrong_size(out)
        est, o = self.record, out.record
        if not read_sample(inp.record, est, o):
            return _STATUS[o["status"][0]]
        mdl = self.model
        m, d, q, u = mdl.model, mdl.data, self._q, self._unused
        jacobian = pin.computeFrameJacobian(m, d, q, self.robot.tcp_frame_id, self._ref)
        if self._direct:
            rnea = pin.rnea(m, d, q, self._qd, self._qdd)
            finish_sample(rnea, u, u, q, jacobian, est, o)
        else:
            mass = pin.crba(m, d, q)  # upper triangle only
            coriolis = pin.computeCoriolisMatrix(m, d, q, self._qd)
            gravity = pin.computeGeneralizedGravity(m, d, q)
            finish_sample(q, mass, coriolis, gravity, jacobian, est, o)
        return _STATUS[o["status"][0]]

    def _wrong_size(self, out: EstimatorOutput) -> EstimatorStatus:
        """An input or output of another robot: ``FAULT_INPUT_SIZE``, latched."""
        s = self._s
        s.faulted = True
        s.status = EstimatorStatus.FAULT_INPUT_SIZE
        if out.record.dtype == self._layouts[1]:
            out.tau_ext[:] = s.last_tau_ext
            out.wrench[:] = s.last_wrench
            out.status = EstimatorStatus.FAULT_INPUT_SIZE
        return EstimatorStatus.FAULT_INPUT_SIZE

    def rezero(self, samples: int) -> None:
        """Zero-velocity update: average τ_ext over the next ``samples`` samples and subtract
        it from then on, status staying OK (real-time safe: no validation, no allocation).

        For the guiding loop once the commanded motion has stopped and settled (the drives keep
        part of their friction after a stop, which no rigid-body model predicts). The robot
        must be untouched meanwhile; :meth:`cancel_rezero` if it moves again.

        Args:
            samples: Window length [samples], >= 1 (NaN or less: 1; capped at 2³¹).
        """
        s = self._s
        s.rezero_sum = 0.0
        # no exception for any argument: NaN or < 1 is one sample, a huge window is capped
        s.rezero_left = s.rezero_taken = int(min(samples, _MAX_WINDOW)) if samples >= 1 else 1

    def cancel_rezero(self) -> None:
        """Abandon a :meth:`rezero` in progress (the tare is kept as it was)."""
        self._s.rezero_left = 0

    @property
    def rezeroing(self) -> bool:
        """A :meth:`rezero` is in progress."""
        return bool(self._s.rezero_left > 0)

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
        s = self._s
        s.tare_sum = 0.0
        s.tare_left = s.tare_taken = max(1, round(duration_s / self.config.dt))

    @property
    def tare_torque(self) -> Array:
        """The joint torque subtracted by taring [N·m], shape (n,) (a copy)."""
        return np.array(self._s.tare)


#: The statuses by value (a dictionary lookup is cheaper than the enum's constructor).
_STATUS = {int(s): s for s in EstimatorStatus}

#: Longest re-zero window [samples] (about 25 days at 1 kHz).
_MAX_WINDOW = 2**31

#: The per-joint state the reset clears.
_STATE_FIELDS = (
    "q_filtered", "qd_filtered", "qdd_filtered", "last_q", "gap_q", "drive_torque",
    "load_torque", "friction_torque", "friction_state", "friction_level", "friction_sign",
    "friction_envelope", "play", "play_increment", "joint_weight", "residual_low_pass",
    "observer_p0", "observer_integral", "observer_residual", "observer_momentum", "tare",
    "tare_sum", "rezero_sum", "last_tau_ext", "last_wrench", "command_history",
    "friction_command", "encoder_friction")
