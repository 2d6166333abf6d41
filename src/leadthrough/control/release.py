"""A release: the operator's hand letting go of the tool at rest.

The paper applies a larger "stopping friction" once the force is removed (eq. 32–33,
:mod:`leadthrough.control.virtual_friction`). At rest the guiding controller extends that: for a
while after every stop and every release, breaking away takes the stopping friction (see
``GuidingConfig.settle_s``), because the drives' friction then unloads and the force estimate
swings the other way, by up to twice the released force.

A release is detected per axis on the estimated wrench (:func:`release_step`, compiled: Numba,
``nopython``, cached on disk, run by the guiding cycle): the smoothed force falls back from a
peak of at least :data:`RELEASE_HOLD` × δ by :data:`RELEASE_DROP` × δ or more within about
:data:`RELEASE_WINDOW_S` (the peak forgets slow drifts, so the estimate's slow drift under a
steady hand is not a release). A hand's hold that the estimate read below
:data:`RELEASE_DROP` × δ counts once the estimate swings past zero by the rest of that fall
while the force (or torque) stays small: at rest the estimate reads only part of a hold, the
swing after letting go follows the whole of it, and a push adds force where a letting go
leaves little.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["RELEASE_DROP", "RELEASE_HOLD", "RELEASE_SMOOTHING_S", "RELEASE_WINDOW_S",
           "release_step"]

Array = NDArray[np.float64]

#: A release at rest: the (smoothed) force on an axis falls back from its peak by this fraction
#: of that axis's friction δ or more.
RELEASE_DROP = 0.5
#: A release needs a peak of at least this fraction of δ before the fall of
#: :data:`RELEASE_DROP` × δ (from a peak under the fall, the fall ends past zero). At
#: rest the gears' static friction carries part of a hand's hold, so the estimate reads less
#: than the hand pushes (on the simulated er20 a 23.5 N hold read 7 N), while the swing after
#: letting go follows what the hand pushed (there: 17 N the other way within 1 s, which moved
#: the tool by itself). Below this fraction a peak is the estimate's noise at rest. Such a
#: fall counts only while the part's (force or torque) magnitude is under
#: :data:`RELEASE_DROP` × δ: a push against a standing phantom adds force. The cost: a push
#: along the phantom's own axis, against it, counts until it has added that much, and restarts
#: the settling.
RELEASE_HOLD = 0.25
#: Time constant of the first-order smoothing of the force for the release [s] (estimator noise
#: below δ must not look like a release).
RELEASE_SMOOTHING_S = 0.05
#: Time constant with which the release's peak forgets slow changes [s]: letting go drops the
#: estimate within ~0.2 s (the estimator's 3 Hz filter), while under a steady hand at rest the
#: estimate drifts by up to ~10 N/s as the drives' static friction takes up or gives back
#: load; such a drift must not renew the stopping friction again and again.
RELEASE_WINDOW_S = 0.3


@njit(cache=True, nogil=True)
def release_step(wrench: Array, friction: Array, drop: float, hold: float, alpha: float,
                 forget: float, smooth: Array, peak: Array, moving: bool) -> bool:
    """A release at rest: on some axis the smoothed w_i held a peak of at least ``drop``·δ_i
    and fell back from it by ``drop``·δ_i or more; or it held at least ``hold``·δ_i, fell
    back by ``drop``·δ_i (so past zero) and its part's (force or torque) smoothed magnitude
    is under ``drop``·δ_i (:data:`RELEASE_HOLD`: the estimate at rest reads less than the
    hand held; a letting go leaves little force at first, where a push against a standing
    phantom adds force). Letting go is quick; the peak
    forgets slow changes (it relaxes toward w_i by the factor ``forget`` per cycle), so that
    the estimate's slow drift at rest under a steady hand is not a release.

    Args:
        wrench: Estimated wrench in the controller's frame, force first, shape (6,).
        friction: δ per axis, shape (6,).
        drop: Fraction of δ that counts as a release.
        hold: Fraction of δ the peak must reach, <= ``drop``.
        alpha: Weight of the new sample in the first-order smoothing, in (0, 1].
        forget: Per-cycle factor of the peak's relaxation, in [0, 1] (1: never forgets).
        smooth: Smoothed wrench, shape (6,); updated in place.
        peak: Signed smoothed w_i of largest magnitude since the tool came to rest or since
            the last release, relaxed by ``forget``, shape (6,); updated in place.
        moving: The tool moves: the peak follows the smoothed wrench (a release counts only
            from rest).

    Returns:
        Whether some axis was released this cycle.
    """
    released = False
    for i in range(6):
        smooth[i] += alpha * (wrench[i] - smooth[i])
    force = math.sqrt(smooth[0] ** 2 + smooth[1] ** 2 + smooth[2] ** 2)
    torque = math.sqrt(smooth[3] ** 2 + smooth[4] ** 2 + smooth[5] ** 2)
    for i in range(6):
        w = smooth[i]
        p = w + (peak[i] - w) * forget
        back = p - w if p >= 0.0 else w - p      # how far w fell back from the peak
        level = drop * friction[i]
        part = force if i < 3 else torque        # the axis's part's smoothed magnitude
        held = abs(p) >= level or (abs(p) >= hold * friction[i] and part < level)
        if back >= level and held:
            released = True
            peak[i] = w
        elif abs(w) > abs(p):
            peak[i] = w
        else:
            peak[i] = p
        if moving:
            peak[i] = w
    return released
