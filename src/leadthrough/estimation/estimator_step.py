"""One sample of the external force estimator, in two compiled calls around Pinocchio.

:class:`~leadthrough.estimation.estimator.ExternalForceEstimator` spends a sample in three parts:

1. :func:`read_sample`: the sample's checks, the causal differentiator (q̇, q̈,
   :mod:`~leadthrough.estimation.filters`), the drive torque τ̂_j = K·i, the gear's load torque
   (:func:`transmitted_torque`), the friction τ_f and the force fit's joint weights
   (:mod:`~leadthrough.estimation.friction_torque`: eq. 15 with a smoothed sign, or with
   memory);
2. Pinocchio on the filtered state (RNEA, or CRBA + Coriolis + gravity for the observer, and the
   TCP Jacobian);
3. :func:`finish_sample`: τ_ext (eq. 27 and 30, or the momentum observer,
   :mod:`~leadthrough.estimation.external_torque`), the tare, the wrench (eq. 28–30,
   :mod:`~leadthrough.estimation.wrench`), and the warm-up / tare / re-zero bookkeeping.

Everything lives in one record (:func:`estimator_dtype`: settings, per-joint constants, state),
read by field; the input and output are records too (:func:`input_dtype`, :func:`output_dtype`).
Codes are the members of :class:`EstimatorStatus` themselves. Nothing here allocates.
"""

from __future__ import annotations

from enum import IntEnum
from functools import cache
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.dynamics.friction import friction_dtype
from leadthrough.estimation.external_torque import (
    average_into_tare,
    direct_residual,
    momentum_step,
)
from leadthrough.estimation.filters import (
    DIFFERENTIATOR_DTYPE,
    bridge_gap,
    differentiate,
    restart_differentiator,
)
from leadthrough.estimation.friction_torque import COMMAND_HISTORY, sample_friction
from leadthrough.estimation.wrench import wrench_from_torque

__all__ = [
    "EstimatorStatus",
    "estimator_dtype",
    "finish_sample",
    "input_dtype",
    "output_dtype",
    "read_sample",
    "transmitted_torque",
]

Array = NDArray[np.float64]
Record = Any     # a record of its dtype (compiled code reads it by field)
Records = NDArray[np.void]   # a record as Python passes it: a structured array of one element


class EstimatorStatus(IntEnum):
    """Result of one estimator update."""

    OK = 0
    WARMING_UP = 1
    TARING = 2
    #: A non-finite input, or a result that overflowed (latched until ``reset``).
    FAULT_NONFINITE = -1
    #: An input or output made for another robot (another joint count) (latched until
    #: ``reset``).
    FAULT_INPUT_SIZE = -2


@cache
def input_dtype(n: int) -> np.dtype[Any]:
    """The record of one sample (``EstimatorInput``) for ``n`` joints."""
    f8 = np.float64
    return np.dtype([("t", f8), ("q", f8, (n,)), ("current", f8, (n,)), ("qd_cmd", f8, (n,))])


@cache
def output_dtype(n: int) -> np.dtype[Any]:
    """The record of the estimate (``EstimatorOutput``) for ``n`` joints."""
    f8 = np.float64
    return np.dtype([("tau_ext", f8, (n,)), ("wrench", f8, (6,)), ("qd", f8, (n,)),
                     ("manipulability", f8), ("damping", f8), ("status", np.int64)])


@cache
def estimator_dtype(n: int) -> np.dtype[Any]:
    """The estimator's record for ``n`` joints: settings, per-joint constants, state."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    joints = (f8, (n,))
    return np.dtype([
        # settings
        ("dt", f8), ("differentiator", DIFFERENTIATOR_DTYPE),
        ("low_pass_alpha", f8),               # of τ_ext
        ("observer_gain", f8),                # K_O [1/s]
        ("direct", b1),                       # eq. 27 (else the momentum observer)
        ("force_only", b1),                   # the force-only fit (else the full wrench)
        ("manipulability_threshold", f8), ("max_damping", f8), ("min_force_lever", f8),
        ("friction_follows_command", b1),     # friction with memory, driven by qd_cmd
        ("command_presliding", *joints),      # its z₀ while commanded to move [rad]
        ("slow_command", *joints),            # at or below it the encoder drives it [rad/s]
        ("command_delay", i8),                # samples the friction's command is delayed by
        ("weigh_by_friction", b1), ("friction_weighting", f8), ("envelope_decay", f8),
        ("warm_up_samples", i8),
        # per joint constants
        ("friction", friction_dtype(n)),      # eq. 15 (or the baselines')
        ("inverse_standstill_velocity", *joints),   # 1/v_ε of the smoothed sign [s/rad]
        ("torque_per_amp", *joints), ("noise_std", *joints), ("rotor_inertia", *joints),
        ("offset", *joints), ("noise_mean", *joints),
        ("rest_presliding", *joints),         # z₀ at rest [rad]
        ("rest_decay", *joints),              # e^{−r·dt}: its relaxation at rest per sample
        ("play_half_width", *joints),         # of the play operator on the encoder [rad]
        # state: the differentiator, the last sample
        ("q_filtered", *joints), ("qd_filtered", *joints), ("qdd_filtered", *joints),
        ("last_q", *joints), ("last_t", f8), ("gap_q", *joints),
        # state: drive torque and friction
        ("drive_torque", *joints),            # τ̂_j [N·m]
        ("load_torque", *joints),             # τ_load, the gear's transmitted torque [N·m]
        ("friction_torque", *joints),         # τ_f [N·m]
        ("friction_state", *joints),          # F of the friction with memory [N·m]
        ("friction_level", *joints),          # the eq. 15 level g(q̇) [N·m]
        ("friction_sign", *joints),           # smoothed sign
        ("friction_envelope", *joints),       # envelope of the friction's uncertainty [N·m]
        ("encoder_friction", *joints),        # the friction turned by the encoder [N·m]
        ("play", *joints), ("play_increment", *joints),
        ("command_history", f8, (COMMAND_HISTORY, n)),   # the last qd_cmd, a ring
        ("command_slot", i8),                 # where the next qd_cmd goes in it
        ("friction_command", *joints),        # qd_cmd of command_delay samples ago [rad/s]
        ("joint_weight", *joints),            # of the force fit [1/(N·m)]
        # state: τ_ext
        ("residual_low_pass", *joints),       # low-pass state of τ̂_d − τ̂_j [N·m]
        ("observer_p0", *joints), ("observer_integral", *joints),
        ("observer_residual", *joints), ("observer_momentum", *joints),
        ("tare", *joints), ("tare_sum", *joints), ("rezero_sum", *joints),
        ("last_tau_ext", *joints), ("last_wrench", f8, (6,)),
        ("wrench_gram", f8, (6, 6)), ("wrench_factor", f8, (6, 6)),
        # state: counters and status
        ("samples", i8), ("tare_left", i8), ("tare_taken", i8),
        ("rezero_left", i8), ("rezero_taken", i8),
        ("first", b1), ("faulted", b1), ("status", i8),
    ])


@njit(cache=True, nogil=True)
def read_sample(inputs: Records, estimator: Records, outputs: Records) -> bool:
    """First half of a sample: checks, differentiator, τ̂_j = K·i, friction, weights.

    Args:
        inputs: The sample's record (:func:`input_dtype`): t (finite; an advance of k ≥ 2
            periods since the last sample bridges k − 1 missed samples), q, current, and
            qd_cmd (the joint velocity commanded to the servo; used when the friction follows
            the command).
        estimator: The estimator's record (in place).
        outputs: The output's record (:func:`output_dtype`), written only when this returns
            False.

    Returns:
        False if an input is not finite (``qd_cmd`` only when the friction follows the
        command: ``FAULT_NONFINITE`` latched) or a fault is latched; ``out`` then holds the last
        valid estimate and the status. Else True.
    """
    inp, est, out = inputs[0], estimator[0], outputs[0]
    if not est.faulted and not _finite(inp, est.friction_follows_command):
        est.faulted = True
        est.status = EstimatorStatus.FAULT_NONFINITE
    if est.faulted:
        _hold_last(est, out)
        return False
    q, t = inp.q, inp.t
    if est.first:
        restart_differentiator(q, est.q_filtered, est.qd_filtered, est.qdd_filtered)
        for j in range(q.size):
            est.play[j] = q[j]
        est.first = False
    else:
        bridge_gap(est.differentiator, est.dt, q, t, est.last_q, est.last_t, est.gap_q,
                   est.q_filtered, est.qd_filtered, est.qdd_filtered)
    differentiate(est.differentiator, q, est.q_filtered, est.qd_filtered, est.qdd_filtered)
    for j in range(q.size):
        est.last_q[j] = q[j]
    est.last_t = t
    for j in range(q.size):
        est.drive_torque[j] = inp.current[j] * est.torque_per_amp[j]
    transmitted_torque(est.drive_torque, est.offset, est.rotor_inertia, est.qdd_filtered,
                       est.friction_torque, est.load_torque)
    sample_friction(inp, est)
    return True


@njit(cache=True, nogil=True)
def transmitted_torque(drive: Array, offset: Array, rotor_inertia: Array, qdd: Array,
                       friction: Array, out: Array) -> None:
    """The torque each gear transmits to its link, from the measured drive torque:
    τ_load = τ̂_j − τ_0 − M_j·q̈ − τ_f (eq. 21 solved for the link side, K·φ − τ_ext).

    The load-dependent Coulomb level f_c0 + f_cL·|τ_load| takes it. Measured rather than the
    identified links' RNEA, because the gear carries the operator's push too: with the model's
    torque the friction would miss f_cL·|τ_ext| and scale the estimated force by up to
    1 ± f_cL. (Offline and in calibration, with no external force, both are the same torque and
    the identification uses the link model's: :mod:`leadthrough.identification.load_friction`.)
    τ_f is the previous sample's friction, which itself depends on τ_load: one step per sample
    of the fixed-point iteration τ_load = D − τ_f(τ_load), which contracts by f_cL < 1 per
    step. It touches only ``out``: with f_cL = 0 the friction does not read it.

    Args:
        drive: τ̂_j = K·i [N·m], shape (n,).
        offset: τ_0 [N·m], shape (n,).
        rotor_inertia: M_j [kg·m²], shape (n,).
        qdd: q̈ (filtered) [rad/s²], shape (n,).
        friction: τ_f of the previous sample [N·m], shape (n,).
        out: τ_load [N·m], shape (n,) (written).
    """
    for j in range(drive.size):
        out[j] = drive[j] - offset[j] - rotor_inertia[j] * qdd[j] - friction[j]


@njit(cache=True, nogil=True)
def _finite(inp: Record, command: bool) -> bool:
    """Whether t, q, current (and qd_cmd, when used) are finite."""
    ok = np.isfinite(inp.t)
    for j in range(inp.q.size):
        if not (np.isfinite(inp.q[j]) and np.isfinite(inp.current[j])):
            ok = False
        if command and not np.isfinite(inp.qd_cmd[j]):
            ok = False
    return ok


@njit(cache=True, nogil=True)
def _hold_last(est: Record, out: Record) -> None:
    """A latched fault: the output keeps the last valid estimate."""
    for j in range(est.last_tau_ext.size):
        out.tau_ext[j] = est.last_tau_ext[j]
    for r in range(6):
        out.wrench[r] = est.last_wrench[r]
    out.status = est.status



@njit(cache=True, nogil=True)
def finish_sample(rnea: Array, mass_upper: Array, coriolis: Array, gravity: Array,
                  jacobian: Array, estimator: Records, outputs: Records) -> None:
    """Second half of a sample: τ_ext, tare, wrench, status (after :func:`read_sample`).

    Args:
        rnea: Rigid-body torque of the identified links at the filtered state [N·m], shape (n,)
            (direct estimate; else unused).
        mass_upper: M(q), upper triangle (observer; else unused), shape (n, n).
        coriolis: C(q, q̇) (observer; else unused), shape (n, n).
        gravity: g(q) [N·m] (observer; else unused), shape (n,).
        jacobian: TCP Jacobian in the output frame, shape (6, n).
        estimator: The estimator's record (in place).
        outputs: The output's record (:func:`output_dtype`): τ_ext, wrench, q̇, μ, λ and the
            status.
    """
    est, out = estimator[0], outputs[0]
    tau_ext = out.tau_ext
    if est.direct:
        direct_residual(rnea, est.friction_torque, est.qdd_filtered, est.drive_torque,
                        est.rotor_inertia, est.offset, est.low_pass_alpha,
                        est.residual_low_pass, est.noise_mean, tau_ext)
    else:
        momentum_step(mass_upper, est.rotor_inertia, coriolis, gravity, est.qd_filtered,
                      est.friction_torque, est.drive_torque, est.offset, est.dt,
                      est.observer_gain, est.samples == 0, est.observer_p0,
                      est.observer_integral, est.observer_residual, est.observer_momentum,
                      est.noise_mean, tau_ext)
    for j in range(tau_ext.size):
        tau_ext[j] -= est.tare[j]
    out.manipulability, out.damping = wrench_from_torque(
        jacobian, tau_ext, est.joint_weight, est.force_only, est.manipulability_threshold,
        est.max_damping, est.min_force_lever, out.wrench, est.wrench_gram, est.wrench_factor)
    if not _output_finite(out):
        # an input too large for the filters overflowed: a fault, the last valid output kept
        est.faulted = True
        est.status = EstimatorStatus.FAULT_NONFINITE
        _hold_last(est, out)
        return
    for j in range(tau_ext.size):
        out.qd[j] = est.qd_filtered[j]
        est.last_tau_ext[j] = tau_ext[j]
    for r in range(6):
        est.last_wrench[r] = out.wrench[r]
    est.samples += 1
    if est.samples <= est.warm_up_samples:
        est.status = EstimatorStatus.WARMING_UP
    elif est.tare_left > 0:
        est.tare_left = average_into_tare(est.tare_sum, est.tare, est.tare_left,
                                          est.tare_taken, tau_ext)
        est.status = EstimatorStatus.TARING
    else:
        if est.rezero_left > 0:
            est.rezero_left = average_into_tare(est.rezero_sum, est.tare, est.rezero_left,
                                                est.rezero_taken, tau_ext)
        est.status = EstimatorStatus.OK
    out.status = est.status


@njit(cache=True, nogil=True)
def _output_finite(out: Record) -> bool:
    """Whether τ_ext and the wrench are finite."""
    finite = True
    for j in range(out.tau_ext.size):
        finite = finite and np.isfinite(out.tau_ext[j])
    for r in range(6):
        finite = finite and np.isfinite(out.wrench[r])
    return finite
