"""The force estimate's drift at rest, and the level the rest threshold of eq. 33 counts from.

At rest the gears' static friction holds whatever the motors push against it, so the estimate
τ_ext = τ̂_d − τ̂_j(i) reads every change of the motor torque that does not move the joint as
an operator's force. A position servo keeps changing that torque at rest: its integral acts on
the position error the gears' presliding stiffness leaves, and ramps the current until the gear
slips. On the simulated er20 (issue 24, the README's creep after a release) the estimate of a
push-x session drifted from −17 N to +23 N over the 5.5 s after the tool had stopped (about
8 N/s, steady), with the joints still to 1e-5 rad: at 15 N (δ) the paper's law broke away
and the tool crept, in bursts, each one followed by a new settling. No model of the currents
can tell that torque from a hand's: both are load that the gears' static friction holds.

What tells them apart is speed. A hand that grips adds at least δ (the smallest force that
moves the tool, eq. 33) within the estimator's filter time (3 Hz: ~0.2 s); the drives' drift
after the settling (``GuidingConfig.settle_s``, the time the drives are given to settle after
a stop or a release) is taken to be slower than δ per ``settle_s`` (δ/settle_s: 10 N/s with
the defaults; the drift above, 8 N/s, and the README's "up to ~10 N/s as the drives' static
friction takes up load" under a steady hand are within it). So at rest the threshold of
eq. 33 counts from a baseline b_i per axis (:func:`rest_baseline_step`): b_i follows the
estimate w_i at no more than δ_i/settle_s, and only while w_i is within δ_i of it (the band
in which eq. 33's static friction holds the tool anyway); a change of δ_i or more that b_i did
not follow (a hand's push, or a phantom as large as δ that arrives faster than a drift) is
beyond it and moves the tool as before. The law at rest sees w − b; in motion b is 0 and the
law is the paper's (the gears slip and friction is the sliding one the model describes).

What this costs: a hand that holds the tool at rest with a force below δ and then pushes
harder needs to add δ over what it held (the held part is taken for the drives at up to
δ/settle_s), and a push that rises more slowly than δ/settle_s from rest does not move the
tool. A drift faster than δ/settle_s still creeps, later.

Compiled (Numba, ``nopython``, cached on disk), run by the guiding cycle
(:mod:`leadthrough.control.guiding_cycle`) on the controller's record (``rest_baseline``).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["rest_baseline_step"]

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def rest_baseline_step(wrench: Array, friction: Array, rate_cycles: float, baseline: Array,
                       out: Array) -> None:
    """One cycle at rest: move each axis's baseline toward the estimate by at most
    δ_i/``rate_cycles`` while the estimate is within δ_i of it, and write the law's input
    w − b.

    Args:
        wrench: Estimated wrench in the controller's frame [N, N·m], shape (6,).
        friction: The law's δ per axis [N, N·m], shape (6,).
        rate_cycles: Controller cycles over which the baseline may move by δ
            (``settle_s``/dt); 0 or less: no baseline (b stays 0, the paper's law).
        baseline: b per axis [N, N·m], shape (6,); updated in place.
        out: w − b [N, N·m], shape (6,); must not alias an input.
    """
    for i in range(6):
        if rate_cycles > 0.0:
            gap = wrench[i] - baseline[i]
            d = friction[i]
            if abs(gap) < d:
                step = d / rate_cycles
                baseline[i] += min(max(gap, -step), step)
        out[i] = wrench[i] - baseline[i]
