"""One estimator sample in two compiled calls (Numba, ``nopython``, cached on disk).

:class:`~leadthrough.estimation.estimator.ExternalForceEstimator` spends a sample in three parts:
:func:`sample_front` (finiteness, the causal differentiator, τ̂_j from current, friction and
the force fit's weights), the Pinocchio calls on the filtered state (RNEA, or CRBA + Coriolis +
gravity for the observer, and the TCP Jacobian), and :func:`sample_back` (eq. 27 and 30 or the
momentum observer, the tare, the wrench of eq. 28–30, and the warm-up / tare / re-zero
bookkeeping). With six joints a Python-level NumPy call costs more in dispatch than in
arithmetic, so the state lives in a few packed arrays instead of a dozen small ones: one call
then passes four arrays instead of twenty. The arithmetic itself is that of the element-wise
kernels in :mod:`leadthrough.estimation.kernels`, which these call.

Packed arrays (row and slot names below):

* ``state`` (:data:`STATE_ROWS`, n): per-joint state and scratch of one estimator;
* ``const`` (:data:`CONST_ROWS`, n): per-joint constants: the friction rows of
  :mod:`~leadthrough.estimation.kernels` (0–7) then torque per amp, σ, M_j, τ_0, τ̄_ω, z₀ at
  rest and the play operator's half width;
* ``settings`` (:data:`SETTINGS_SLOTS`,): float settings;
* ``counters`` (:data:`COUNTER_SLOTS`,): int64 counters, flags and the last status.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.estimation import kernels, presliding_kernels

__all__ = [
    "CONST_ROWS",
    "COUNTER_SLOTS",
    "SETTINGS_SLOTS",
    "STATE_ROWS",
    "sample_back",
    "sample_front",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

# rows of ``state``
POS, VEL, ACC = 0, 1, 2            # differentiator: filtered q, q̇, q̈
TAU_J = 3                          # torque from current
FRICTION = 4                       # friction torque τ_f
PRESLIDING = 5                     # F of the friction with memory
LEVEL = 6                          # eq. 15 level g(q̇)
INCREMENT = 7                      # measured displacement after the play operator (scratch)
SIGN = 8                           # smoothed sign (scratch)
ENVELOPE = 9                       # envelope of the friction's uncertainty
WEIGHT = 10                        # weights of the force fit
FILTERED = 11                      # low-pass state of τ̂_d − τ̂_j
TARE, TARE_SUM, REZERO_SUM = 12, 13, 14
LAST_TAU = 15                      # last valid τ_ext
P0, INTEGRAL, RESIDUAL, WORK = 16, 17, 18, 19   # momentum observer
PLAY = 20                          # play operator on the encoder
LAST_Q = 21                        # q of the last sample
GAP_Q = 22                         # q interpolated over missed samples (scratch)
LAST_T = 23                        # column 0: t of the last sample
STATE_ROWS = 24

#: Most missed samples the differentiator steps through (a longer gap: its last ones, from a
#: restart with the gap's mean velocity).
MAX_GAP_SAMPLES = 100

# rows of ``const`` after the friction rows
TORQUE_PER_AMP = kernels.FRICTION_ROWS
STD = TORQUE_PER_AMP + 1
ROTOR = TORQUE_PER_AMP + 2
OFFSET = TORQUE_PER_AMP + 3
NOISE_MEAN = TORQUE_PER_AMP + 4
REST_PRESLIDING = TORQUE_PER_AMP + 5   # z₀ per joint at rest [rad]
HALF_PLAY = TORQUE_PER_AMP + 6         # half width of the play operator [rad]
CONST_ROWS = TORQUE_PER_AMP + 7

# slots of ``settings``: the differentiator's 7 coefficients (kernels.svf_step) then
SVF = 0
DT = 7
PRESLIDING_RAD = 8
ENVELOPE_DECAY = 9
KAPPA = 10
ALPHA = 11                         # low-pass coefficient
OBSERVER_GAIN = 12
MU0 = 13
MAX_DAMPING = 14
MIN_LEVER = 15
SETTINGS_SLOTS = 16

# slots of ``counters``
SAMPLES, WARM = 0, 1
TARE_LEFT, TARE_TAKEN, REZERO_LEFT, REZERO_TAKEN = 2, 3, 4, 5
FAULT, FIRST = 6, 7
STRIBECK, FRICTION_COMMAND, WEIGH, DIRECT, FORCE_ONLY = 8, 9, 10, 11, 12
STATUS = 13
COUNTER_SLOTS = 14

# values of counters[STATUS] (the estimator's Status)
STATUS_OK, STATUS_WARMING_UP, STATUS_TARING, STATUS_FAULT, STATUS_FAULT_SIZE = 0, 1, 2, -1, -2


@njit(cache=True, nogil=True)
def sample_front(q: Array, current: Array, qd_cmd: Array, t: float, const: Array,
                 settings: Array, counters: IntArray, state: Array) -> bool:
    """First half of a sample: checks, differentiator, τ̂_j = K·i, friction, weights.

    Args:
        q: Measured joint positions [rad], shape (n,).
        current: Motor currents [A], shape (n,).
        qd_cmd: Joint velocity commanded to the servo [rad/s], shape (n,) (friction driven by
            the command; else unused).
        t: Time [s]: finite; an advance of k ≥ 2 periods since the last sample bridges k − 1
            missed samples (see ``_bridge_gap``).
        const: Per-joint constants, shape (CONST_ROWS, n).
        settings: Float settings, shape (SETTINGS_SLOTS,).
        counters: Counters and flags (in place), shape (COUNTER_SLOTS,).
        state: Per-joint state (in place), shape (STATE_ROWS, n).

    Returns:
        False if an input has the wrong size (``STATUS_FAULT_SIZE``) or is not finite
        (``STATUS_FAULT``; ``qd_cmd`` only when the friction follows the command), or a fault
        is latched (``counters[FAULT]`` set, ``counters[STATUS]`` the fault; nothing else
        changes), else True.
    """
    if counters[FAULT] != 0:
        return False
    n = const.shape[1]
    command = counters[FRICTION_COMMAND] != 0
    if q.size != n or current.size != n or (command and qd_cmd.size != n):
        counters[FAULT] = 1
        counters[STATUS] = STATUS_FAULT_SIZE
        return False
    ok = np.isfinite(t)
    for j in range(n):
        if not (np.isfinite(q[j]) and np.isfinite(current[j])):
            ok = False
        if command and not np.isfinite(qd_cmd[j]):
            ok = False
    if not ok:
        counters[FAULT] = 1
        counters[STATUS] = STATUS_FAULT
        return False
    if counters[FIRST] != 0:
        _restart_differentiator(q, state)
        for j in range(n):
            state[PLAY, j] = q[j]
        counters[FIRST] = 0
    else:
        _bridge_gap(q, t, settings, state)
    kernels.svf_step(settings[SVF:SVF + 7], q, state[POS], state[VEL], state[ACC])
    for j in range(n):
        state[LAST_Q, j] = q[j]
    state[LAST_T, 0] = t
    for j in range(n):
        state[TAU_J, j] = current[j] * const[TORQUE_PER_AMP, j]
    fp = const[:kernels.FRICTION_ROWS]
    stribeck = counters[STRIBECK] != 0
    if command:
        # driven by the command while it moves, by the measured motion when it is at rest
        presliding_kernels.play_step(q, const[HALF_PLAY], state[PLAY], state[INCREMENT])
        presliding_kernels.presliding_friction_step(
            qd_cmd, state[INCREMENT], fp, stribeck, settings[DT], settings[PRESLIDING_RAD],
            const[REST_PRESLIDING], state[PRESLIDING], state[FRICTION], state[LEVEL])
        if counters[WEIGH] != 0:
            kernels.friction_weights(state[LEVEL], state[PRESLIDING], settings[ENVELOPE_DECAY],
                                     settings[KAPPA], const[STD], state[ENVELOPE],
                                     state[WEIGHT])
    else:
        kernels.smooth_sign(state[VEL], fp, state[SIGN])
        kernels.friction_torque(state[VEL], state[SIGN], fp, stribeck, state[FRICTION])
    return True


@njit(cache=True, nogil=True)
def _restart_differentiator(q: Array, state: Array) -> None:
    """The differentiator at rest at ``q``."""
    for j in range(q.size):
        state[POS, j] = q[j]
        state[VEL, j] = 0.0
        state[ACC, j] = 0.0


@njit(cache=True, nogil=True)
def _bridge_gap(q: Array, t: float, settings: Array, state: Array) -> None:
    """Samples missed since the last one (t advanced by k ≥ 2 periods): step the
    differentiator through q interpolated linearly between the two samples, so that the jump
    of q over the gap is not differentiated as one period's motion. Of a gap longer than
    :data:`MAX_GAP_SAMPLES` only the last that many are stepped, from a restart at the
    interpolated position with the gap's mean velocity (the work per sample stays bounded). A
    t that repeats or goes back is treated as one period."""
    elapsed = t - state[LAST_T, 0]
    periods = elapsed / settings[DT]
    if periods < 1.5:
        return
    missed = int(min(periods, 1e9) + 0.5) - 1
    first = max(1, missed - MAX_GAP_SAMPLES + 1)
    if first > 1:
        w = (first - 1) / (missed + 1.0)
        for j in range(q.size):
            state[POS, j] = state[LAST_Q, j] + w * (q[j] - state[LAST_Q, j])
            state[VEL, j] = (q[j] - state[LAST_Q, j]) / elapsed
            state[ACC, j] = 0.0
    for m in range(first, missed + 1):
        w = m / (missed + 1.0)
        for j in range(q.size):
            state[GAP_Q, j] = state[LAST_Q, j] + w * (q[j] - state[LAST_Q, j])
        kernels.svf_step(settings[SVF:SVF + 7], state[GAP_Q], state[POS], state[VEL], state[ACC])


@njit(cache=True, nogil=True)
def sample_back(rnea: Array, mass_upper: Array, coriolis: Array, gravity: Array,
                jacobian: Array, const: Array, settings: Array, counters: IntArray,
                state: Array, tau_ext: Array, wrench: Array, qd: Array,
                last_wrench: Array, scratch: Array, info: Array) -> None:
    """Second half of a sample: τ_ext, tare, wrench, status (after :func:`sample_front`).

    Args:
        rnea: Rigid-body torque of the identified links at the filtered state [N·m], shape (n,)
            (direct estimator; else unused).
        mass_upper: M(q), upper triangle (observer; else unused), shape (n, n).
        coriolis: C(q, q̇) (observer; else unused), shape (n, n).
        gravity: g(q) [N·m] (observer; else unused), shape (n,).
        jacobian: TCP Jacobian in the output frame, shape (6, n).
        const: Per-joint constants, shape (CONST_ROWS, n).
        settings: Float settings, shape (SETTINGS_SLOTS,).
        counters: Counters and flags (in place); ``counters[STATUS]`` is set.
        state: Per-joint state (in place), shape (STATE_ROWS, n).
        tau_ext: Output: external joint torque [N·m], shape (n,).
        wrench: Output: TCP wrench [N, N·m], shape (6,).
        qd: Output: the estimated joint velocity [rad/s], shape (n,).
        last_wrench: Copy of ``wrench`` kept for a fault (in place), shape (6,).
        scratch: Work space of the wrench, shape (2, 6, 6).
        info: Output: the manipulability μ at the filtered position and the damping λ of the
            wrench map, shape (2,).
    """
    n = tau_ext.size
    if counters[DIRECT] != 0:
        kernels.direct_residual(rnea, state[FRICTION], state[ACC], state[TAU_J], const[ROTOR],
                                const[OFFSET], settings[ALPHA], state[FILTERED],
                                const[NOISE_MEAN], tau_ext)
    else:
        kernels.momentum_step(mass_upper, const[ROTOR], coriolis, gravity, state[VEL],
                              state[FRICTION], state[TAU_J], const[OFFSET], settings[DT],
                              settings[OBSERVER_GAIN], counters[SAMPLES] == 0, state[P0],
                              state[INTEGRAL], state[RESIDUAL], state[WORK],
                              const[NOISE_MEAN], tau_ext)
    for j in range(n):
        tau_ext[j] -= state[TARE, j]
    kernels.wrench_from_torque(jacobian, tau_ext, state[WEIGHT], counters[FORCE_ONLY] != 0,
                               settings[MU0], settings[MAX_DAMPING], settings[MIN_LEVER], wrench,
                               scratch, info)
    finite = True
    for j in range(n):
        finite = finite and np.isfinite(tau_ext[j])
    for r in range(6):
        finite = finite and np.isfinite(wrench[r])
    if not finite:
        # an input too large for the filters overflowed: a fault, the last valid output kept
        for j in range(n):
            tau_ext[j] = state[LAST_TAU, j]
        for r in range(6):
            wrench[r] = last_wrench[r]
        counters[FAULT] = 1
        counters[STATUS] = STATUS_FAULT
        return
    for j in range(n):
        qd[j] = state[VEL, j]
        state[LAST_TAU, j] = tau_ext[j]
    for r in range(6):
        last_wrench[r] = wrench[r]
    counters[SAMPLES] += 1
    if counters[SAMPLES] <= counters[WARM]:
        counters[STATUS] = STATUS_WARMING_UP
    elif counters[TARE_LEFT] > 0:
        counters[TARE_LEFT] = _average_into_tare(state, TARE_SUM, counters[TARE_LEFT],
                                                 counters[TARE_TAKEN], tau_ext)
        counters[STATUS] = STATUS_TARING
    else:
        if counters[REZERO_LEFT] > 0:
            counters[REZERO_LEFT] = _average_into_tare(state, REZERO_SUM, counters[REZERO_LEFT],
                                                       counters[REZERO_TAKEN], tau_ext)
        counters[STATUS] = STATUS_OK


@njit(cache=True, nogil=True)
def _average_into_tare(state: Array, row: int, left: int, taken: int, tau_ext: Array) -> int:
    """One sample of an averaging window (tare or re-zero): add ``tau_ext`` to
    ``state[row]``; on the window's last sample add the mean to the tare. Returns the samples
    left."""
    n = tau_ext.size
    for j in range(n):
        state[row, j] += tau_ext[j]
    left -= 1
    if left == 0:
        for j in range(n):
            state[row, j] *= 1.0 / taken
            state[TARE, j] += state[row, j]
    return left
