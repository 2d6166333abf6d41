"""The friction torque τ_f the force estimator subtracts, per joint, one sample at a time.

Two models, chosen by ``EstimatorConfig.friction_velocity``:

* ``"command"``: friction with memory (a Dahl state whose steady state is eq. 15,
  :func:`~leadthrough.dynamics.presliding.presliding_friction_step`), driven while a joint is
  commanded to move by the commanded joint velocity of a few samples ago
  (:func:`delay_command`: the interface's command-to-position lag, below
  :data:`COMMAND_HISTORY` samples) and at rest, or commanded to creep
  (``EstimatorConfig.slow_command_velocity``), by the encoder (through the play operator,
  :func:`~leadthrough.dynamics.presliding.play_step`); its Coulomb level load-dependent
  (:func:`leadthrough.dynamics.friction.coulomb_level`). Beside it, the same friction as the
  encoder alone would turn it (:func:`encoder_friction_step`): where the two disagree, the
  force fit weighs the joint less (:func:`~leadthrough.estimation.wrench.friction_weights`);
* ``"measured"``: eq. 15 (or the baselines' Coulomb + viscous (+ cube root) model) of the
  filtered measured velocity, with sgn(q̇) smoothed to sat(q̇/v_ε) (:func:`smoothed_friction`).

:func:`sample_friction` runs the chosen one inside the first half of a sample
(:func:`~leadthrough.estimation.estimator_step.read_sample`), on the estimator's record
(:func:`~leadthrough.estimation.estimator_step.estimator_dtype`). Nothing here allocates.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.dynamics.friction import coulomb_level, eq15_friction
from leadthrough.dynamics.presliding import dahl_step, play_step, presliding_friction_step
from leadthrough.estimation.wrench import friction_weights

__all__ = [
    "COMMAND_HISTORY",
    "delay_command",
    "encoder_friction_step",
    "sample_friction",
    "smoothed_friction",
]

Array = NDArray[np.float64]
Record = Any     # a record of its dtype (compiled code reads it by field)

#: Length of the estimator's ring of past commands (``delay_command``) [samples]: the longest
#: command delay is one less.
COMMAND_HISTORY = 128


@njit(cache=True, nogil=True)
def sample_friction(inp: Record, est: Record) -> None:
    """τ_f: with memory, driven by the command while a joint moves and by the measured motion
    at rest or creeping (and the force fit's weights from its uncertainty); or eq. 15 of the
    measured velocity with the smoothed sign sat(q̇/v_ε)."""
    fp = est.friction
    if est.friction_follows_command:
        play_step(inp.q, est.play_half_width, est.play, est.play_increment)
        delay_command(inp.qd_cmd, est)
        presliding_friction_step(est.friction_command, est.play_increment, fp,
                                 est.load_torque, est.dt, est.slow_command,
                                 est.command_presliding, est.rest_presliding,
                                 est.rest_decay, est.friction_state, est.friction_torque,
                                 est.friction_level)
        if est.weigh_by_friction:
            encoder_friction_step(est.play_increment, est.friction_command, est.slow_command,
                                  est.friction_level, est.rest_presliding,
                                  est.friction_state, est.encoder_friction)
            friction_weights(est.friction_level, est.friction_state, est.encoder_friction,
                             est.envelope_decay, est.friction_weighting, est.noise_std,
                             est.friction_envelope, est.joint_weight)
        return
    smoothed_friction(est.qd_filtered, est.inverse_standstill_velocity, fp, est.load_torque,
                      est.friction_sign, est.friction_torque)


@njit(cache=True, nogil=True)
def encoder_friction_step(increment: Array, command: Array, slow: Array, level: Array,
                          presliding: Array, state: Array, out: Array) -> None:
    """The Coulomb + Stribeck friction as the encoder alone would turn it over, one step: while
    a joint is commanded to move, a Dahl state driven by the measured displacement (through
    the play operator) toward the level of the commanded speed. Not the friction the estimate
    uses (turned by the command, see ``presliding_friction_step``): where the two disagree, a
    joint that the command says has reversed has not yet moved back, and its friction is in
    doubt (``friction_weights``). At rest, or commanded no faster than ``slow``, the
    estimate's friction is the encoder's already: the state is set to it, and the next motion
    starts from there.

    Args:
        increment: Measured displacement of this step, after the play operator [rad], (n,).
        command: The commanded velocity the friction follows [rad/s], shape (n,) (0: at rest).
        slow: Per joint, the commanded speed at or below which the estimate's friction is the
            encoder's [rad/s], shape (n,).
        level: The eq. 15 level g at the commanded speed [N·m], shape (n,).
        presliding: z₀ per joint [rad], shape (n,).
        state: The estimate's friction state F after this step [N·m], shape (n,).
        out: The encoder's state F_enc [N·m] (in place), shape (n,).
    """
    for j in range(increment.size):
        if abs(command[j]) <= slow[j]:
            out[j] = state[j]
        elif increment[j] != 0.0 and level[j] > 0.0:
            out[j] = dahl_step(out[j], increment[j], level[j], presliding[j])


@njit(cache=True, nogil=True)
def delay_command(qd_cmd: Array, est: Record) -> None:
    """``est.friction_command`` = the ``qd_cmd`` of ``delay`` samples ago: the velocity the
    joint has now when the command reaches the measured position ``delay`` samples after it
    was sent (the interface's command-to-position lag, see ``EstimatorConfig.command_lag``).
    Samples before the last reset count as zero (a reset is at rest).

    Args:
        qd_cmd: This sample's commanded joint velocity [rad/s], shape (n,).
        est: The estimator's record: ``command_delay`` (0 <= delay < ``COMMAND_HISTORY``
            samples), the ring ``command_history`` of the last commands, shape
            (COMMAND_HISTORY, n), and ``command_slot`` (both in place); ``friction_command``
            (written).
    """
    out, delay, history = est.friction_command, est.command_delay, est.command_history
    if delay == 0:
        for j in range(qd_cmd.size):
            out[j] = qd_cmd[j]
        return
    slot = est.command_slot
    size = history.shape[0]
    for j in range(qd_cmd.size):
        history[slot, j] = qd_cmd[j]
    source = (slot - delay) % size
    for j in range(qd_cmd.size):
        out[j] = history[source, j]
    est.command_slot = (slot + 1) % size


@njit(cache=True, nogil=True)
def smoothed_friction(qd: Array, inverse_standstill_velocity: Array, fp: Record,
                      load_torque: Array, sign: Array, out: Array) -> None:
    """Friction of the measured velocity with a smoothed sign: eq. 15 (or the baselines'
    Coulomb + viscous (+ cube root) model) with sgn(q̇) replaced by sat(q̇/v_ε), which fades the
    friction to zero below the calibration's standstill threshold v_ε (the sign of a noisy
    velocity estimate at standstill means nothing).

    Args:
        qd: Joint velocities [rad/s], shape (n,).
        inverse_standstill_velocity: 1/v_ε per joint [s/rad], shape (n,).
        fp: The friction parameters (:func:`~leadthrough.dynamics.friction.friction_dtype`).
        load_torque: τ_load of the load-dependent Coulomb level [N·m], shape (n,) (not read
            where f_cL = 0).
        sign: Output: the smoothed sign in [−1, 1], shape (n,).
        out: Output: the friction torque [N·m], shape (n,).
    """
    for j in range(qd.size):
        sign[j] = min(1.0, max(-1.0, qd[j] * inverse_standstill_velocity[j]))
        v = qd[j]
        coulomb = coulomb_level(fp.coulomb[j], fp.load[j], load_torque[j])
        if fp.stribeck:
            out[j] = eq15_friction(v, sign[j], coulomb, fp.motor_stribeck[j],
                                   fp.motor_rate[j], fp.gear_stribeck[j], fp.gear_rate[j],
                                   fp.viscous[j])
        else:
            out[j] = sign[j] * coulomb + v * fp.viscous[j] + fp.cbrt[j] * np.cbrt(v)

