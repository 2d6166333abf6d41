"""Drive friction with memory (presliding): the play operator on the encoder, the Dahl step, and
eq. 15 as the steady state of a LuGre/Dahl friction state, per sample.

At standstill a gear's friction is a state that turns over a displacement of a few z₀ (its
presliding length) and keeps its value when the motion stops (Dahl 1968; Canudas de Wit et al.
1995). The real-time estimator (:mod:`leadthrough.estimation`) drives this model every sample,
and the presliding test (:mod:`leadthrough.identification.presliding`) fits z₀ with the same
functions, so the fit and the estimator run one model. Compiled (Numba, ``nopython``, cached on
disk); eq. 15 itself comes from :mod:`leadthrough.dynamics.friction`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.dynamics.friction import coulomb_level, stribeck_terms

__all__ = ["dahl_step", "play_step", "presliding_friction_step", "relaxation_factor"]

Array = NDArray[np.float64]


def relaxation_factor(relaxation: Array, dt: float) -> Array:
    """The factor e^{−r·dt} by which the friction held at rest relaxes in one step of ``dt``.

    The one discretisation of the relaxation at rest: the estimator's record
    (:func:`presliding_friction_step`'s ``rest_decay``) and the presliding test's fit
    (:mod:`leadthrough.identification.presliding`) both take it from here.

    Args:
        relaxation: r per joint [1/s], shape (n,) (the params' ``presliding_relaxation``).
        dt: Step [s].

    Returns:
        The factor per joint, in (0, 1], shape (n,).
    """
    return np.exp(-dt * np.asarray(relaxation, dtype=float))


@njit(cache=True, nogil=True)
def play_step(q: Array, half_width: Array, play: Array, increment: Array) -> None:
    """The play (backlash) operator on the encoder, one step (in place on ``play``).

    The output follows the input only once it leaves a band of ±``half_width`` around it, so
    quantisation chatter of one or two counts at rest moves nothing. A friction state driven by
    the raw encoder would otherwise be worn down by thousands of tiny reversals.

    Args:
        q: Measured joint positions [rad], shape (n,).
        half_width: Half the band per joint [rad], shape (n,), ≥ 0.
        play: The operator's output (state) [rad], shape (n,).
        increment: Output: this step's change of ``play`` [rad], shape (n,).
    """
    for j in range(q.size):
        new = min(max(play[j], q[j] - half_width[j]), q[j] + half_width[j])
        increment[j] = new - play[j]
        play[j] = new


@njit(cache=True, nogil=True)
def dahl_step(state: float, displacement: float, level: float, presliding: float) -> float:
    """One exact step of a Dahl friction state driven by a displacement.

    F turns toward ±``level`` (the sign of the displacement) by the factor
    e^{−|displacement|/z₀}: dF = (g·sgn(dq) − F)·|dq|/z₀, exact for one monotone step.

    Args:
        state: F before the step [N·m] (or normalised, with ``level`` 1).
        displacement: dq of the step [rad], non-zero.
        level: g [N·m], > 0.
        presliding: z₀ [rad], > 0.

    Returns:
        F after the step.
    """
    target = level if displacement > 0.0 else -level
    return target + (state - target) * np.exp(-abs(displacement) / presliding)


@njit(cache=True, nogil=True)
def presliding_friction_step(qd: Array, increment: Array, fp: Any, load_torque: Array,
                             dt: float, slow: Array, command_presliding: Array,
                             rest_presliding: Array, rest_decay: Array, state: Array,
                             out: Array, level: Array) -> None:
    """Friction with memory, one step: eq. 15 as the steady state of a LuGre/Dahl model.

    The Coulomb + Stribeck part F follows dF = k·(dq − |dq|·F/g(q̇)), with g(q̇) the eq. 15
    level f1 + f2·e^{−(R q̇/q̇sm)²} + f3·e^{−(q̇/q̇sg)²} (f1 the load-dependent Coulomb level
    f_c0 + f_cL·|τ_load|, :func:`~leadthrough.dynamics.friction.coulomb_level`) and the
    presliding stiffness
    k = g(0)/z₀: F turns over a displacement of a few z₀ toward ±g, and keeps its value at
    standstill (a stopped gear still carries the friction it had when it stopped, not the static
    peak). In steady sliding F = g·sgn(q̇), eq. 15 itself. Two drives:

    * a joint commanded to move faster than ``slow`` (|q̇| > slow): dq = q̇·dt with
      ``command_presliding`` (z₀ plus the servo's lag behind the command), the level at the
      commanded speed;
    * a joint commanded to stand still or to creep (|q̇| <= slow): the measured displacement
      ``increment`` (play operator on the encoder, :func:`play_step`) with the joint's own z₀
      (identified by a presliding test, :mod:`leadthrough.identification.presliding`), the
      static level g(0). A push at rest deflects the drive by a fraction of z₀, and how much of
      the push the current then carries follows from that displacement. A creeping command
      (a wrist reversing, or dithering about zero, while the TCP moves) does not say where
      the gear is: its servo builds the torque to move it over many samples, and the gear
      stays in presliding meanwhile, which the encoder sees and the command does not.
      Meanwhile F relaxes toward zero by the factor ``rest_decay`` per step
      (:func:`relaxation_factor` of the params' ``presliding_relaxation``): the servo's
      dither of a joint held still, far below one count, wears the friction down where the
      encoder sees no motion.

    Each step is the exact solution for a constant rate. The viscous (and cube-root) terms of
    the commanded velocity are added as usual.

    Args:
        qd: Joint velocities commanded to the servo [rad/s], shape (n,) (0: at rest).
        increment: Measured displacement of this step, after the play operator [rad], shape
            (n,) (used where |``qd``| <= ``slow``).
        fp: The friction parameters (a record of :func:`~leadthrough.dynamics.friction.
            friction_dtype`).
        load_torque: τ_load of the load-dependent Coulomb level [N·m], shape (n,) (not read
            where f_cL = 0).
        dt: Step [s].
        slow: Per joint, the commanded speed at or below which the encoder drives F [rad/s],
            shape (n,) (0: only a joint commanded to stand still).
        command_presliding: z₀ per joint of the commanded motion [rad], shape (n,).
        rest_presliding: z₀ per joint at rest [rad], shape (n,).
        rest_decay: Per joint, the factor F is multiplied by every step at rest or creeping
            [-], shape (n,), in (0, 1] (1: no relaxation).
        state: F, the Coulomb + Stribeck part [N·m] (in place), shape (n,).
        out: Friction torque [N·m], shape (n,).
        level: The eq. 15 level g(q̇) [N·m] (written), shape (n,).
    """
    for j in range(qd.size):
        v = qd[j]
        g = coulomb_level(fp.coulomb[j], fp.load[j], load_torque[j])
        g0 = g
        if fp.stribeck:
            g += stribeck_terms(v, fp.motor_stribeck[j], fp.motor_rate[j], fp.gear_stribeck[j],
                                fp.gear_rate[j])
            g0 += stribeck_terms(0.0, fp.motor_stribeck[j], fp.motor_rate[j],
                                 fp.gear_stribeck[j], fp.gear_rate[j])
        level[j] = g
        if abs(v) > slow[j]:
            if g > 0.0:
                target = g if v > 0.0 else -g
                state[j] = target + (state[j] - target) * np.exp(
                    -g0 * abs(v) * dt / (command_presliding[j] * g))
        else:
            if increment[j] != 0.0 and g0 > 0.0:
                state[j] = dahl_step(state[j], increment[j], g0, rest_presliding[j])
            state[j] *= rest_decay[j]
        f = state[j] + v * fp.viscous[j]
        if not fp.stribeck:
            f += fp.cbrt[j] * np.cbrt(v)
        out[j] = f
