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

What tells them apart is speed. A hand that grips or lets go changes the estimate by δ or more
(the smallest force that moves the tool, eq. 33) within the estimator's filter time (3 Hz:
~0.2 s); the drives' drift is taken to be slower than δ per ``GuidingConfig.drift_s``
(δ/drift_s: 10 N/s with the defaults, 15 N over 1.5 s). The drift above, 8 N/s, and the
README's "up to ~10 N/s as the drives' static friction takes up load" under a steady hand are
within it; a grip through the 3 Hz filter, δ within ~0.25 s, is six times faster. So
(:func:`drift_step`) the estimate's rate is measured per axis as the gap between two
first-order smoothings of it (the release detector's 0.05 s against estimator noise and its
0.3 s window: a ramp of rate ρ leaves a gap of ρ·0.25 s). While guiding at rest and that rate
is within δ_i/drift_s, a baseline b_i follows the fast smoothing at no more than δ_i/drift_s,
as long as that smoothing is within δ_i/2 of it (the release detector's
:data:`~leadthrough.control.release.RELEASE_DROP`: a change that it counts as a hand's). A
hand's grip or letting go is faster: b holds while it happens and does not take up the level
it leaves, until the estimate comes back to within δ_i/2 of b (the hand lets go). The
threshold of eq. 33 counts from b: the law at rest sees w − b, or w where that is smaller in
magnitude (estimator noise below δ still produces no motion at all). Mostly the baseline only
holds the tool where the paper's law would move it; but with b above 2δ, an estimate between
b/2 and b − δ reads as a push of more than δ against b's sign, and the tool moves that way,
where the paper's law would move it the other way or not at all (right if b is the drives'
and the hand pulls; not, if b took up a hand's push). In
motion the law is the paper's (it sees w) and b relaxes to 0 over ``drift_s`` (the gears slip
and their friction is the sliding one the model describes), so that a single cycle of motion
does not forget it.

Not guiding, the drives drift all the same, and nothing the estimate reads then is a push:
the enabling device is released. So while not guiding at rest (IDLE, or a stop or a fault
come to rest) b is the estimate's level (its fast smoothing), and a press starts guiding from
there: the law sees only what rises over the level at the press. On the simulated er20 the
estimate rose from 9 N to 69 N over the 8 s after a push-x session's enabling device was
released, and read 37-171 N 13 s after a seam's (24 runs over J519, UR and RSI); with b at 0
while not guiding (as it
was), a press with no hand on the tool moved it by itself (4.3 mm at 0.035 m/s after the
push-x, 10.8 mm at 0.053 m/s after a seam). A hand that already pushes when the device is
pressed must add δ to move the tool, as a hand resting on the still tool must; letting go then
leaves w − b larger in magnitude than w, and the law sees w. While the commanded motion is
not at rest and not guiding (a stop), b restarts from 0. With ``drift_s`` 0 the baseline
follows nothing while guiding, but the level at a press is still taken. The velocity law [14]
has no baseline and no dead band: there the estimate at a press moves the tool, and only the
collision check at the press (``safety_rules.deadman``) guards it. With the stop after
letting go (:mod:`leadthrough.control.hand_release`) the guiding cycle restarts b from the level the
estimate settled to, and a rise of δ over b resumes guiding.

What this costs and what it does not cover: a push that rises more slowly than δ/drift_s
from rest is taken for the drives and does not move the tool (it must rise faster; the seam
operator's lean at a point, which grows by design as slowly as the tool is short of it, is
such a push); the part of a hand's rest on the still tool that came slowly or within δ/2 of
b is taken up, so the hand must add δ over it to move the tool; after a motion b has relaxed
toward 0 and follows only once the estimate passes within δ/2 of it (until then the law is
the paper's); the first cycles of a quick rise are followed, so a push from rest may move the
tool a cycle later than the paper's law; a drift faster than δ/drift_s still creeps, later;
and a phantom that arrives quickly after a stop or a release (the gears unloading) and still
exceeds δ when the settling ends moves the tool as the paper's law does.

Compiled (Numba, ``nopython``, cached on disk), run by the guiding cycle
(:mod:`leadthrough.control.guiding_cycle`) on the controller's record (``drift_*``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["drift_step"]

Array = NDArray[np.float64]


@njit(cache=True, nogil=True)
def drift_step(wrench: Array, friction: Array, rate_per_delta: float, band: float, dt: float,
               alpha_fast: float, alpha_slow: float, span_s: float, decay: float, at_rest: bool,
               idle: bool, fast: Array, slow: Array, baseline: Array, out: Array) -> None:
    """One cycle: smooth the estimate twice, let the baseline follow its slow changes while
    guiding at rest (relax it while moving, take the estimate's level while at rest and not
    guiding), and write the law's input.

    Args:
        wrench: Estimated wrench in the controller's frame [N, N·m], shape (6,).
        friction: The law's δ per axis [N, N·m], shape (6,).
        rate_per_delta: 1/drift_s [1/s]: a change of δ_i·rate_per_delta per second or slower
            is the drives' (0: none is, the paper's law).
        band: Fraction of δ_i within which the fast smoothing must be of the baseline for the
            baseline to follow it (a change the release detector counts as a hand's, δ/2, is
            never taken up).
        dt: Controller cycle [s].
        alpha_fast: Weight of a new sample in the fast smoothing, in (0, 1].
        alpha_slow: Weight of a new sample in the slow smoothing, in (0, 1].
        span_s: The slow smoothing's time constant less the fast one's [s], > 0.
        decay: Per-cycle factor of the baseline in motion, in [0, 1].
        at_rest: Guiding at rest (the law's eq. 33 applies).
        idle: At rest and not guiding (IDLE, or a stop or a fault come to rest): the baseline
            is the fast smoothing, whatever its rate and level (``at_rest`` must be False).
        fast: Fast smoothing of the wrench, shape (6,); updated in place.
        slow: Slow smoothing of the wrench, shape (6,); updated in place.
        baseline: b per axis [N, N·m], shape (6,); updated in place.
        out: The law's input: at rest w − b, or w where that is smaller; in motion w; shape
            (6,); must not alias an input.
    """
    for i in range(6):
        w = wrench[i]
        if not math.isfinite(w):       # the cycle faults: restart from 0 when it clears
            fast[i] = slow[i] = baseline[i] = 0.0
            out[i] = w
            continue
        fast[i] += alpha_fast * (w - fast[i])
        slow[i] += alpha_slow * (w - slow[i])
        if idle:
            baseline[i] = fast[i]
            out[i] = w
        elif at_rest:
            limit = friction[i] * rate_per_delta
            if (abs(fast[i] - slow[i]) <= limit * span_s
                    and abs(fast[i] - baseline[i]) <= band * friction[i]):
                step = limit * dt
                baseline[i] += min(max(fast[i] - baseline[i], -step), step)
            r = w - baseline[i]
            out[i] = r if abs(r) < abs(w) else w
        else:
            baseline[i] *= decay
            out[i] = w
