"""The operator's hand letting go of a moving tool, and the stop that follows.

The paper's law (eq. 31–33, :mod:`leadthrough.control.virtual_friction`) stops the tool once
the estimated force falls below δ: the stopping friction δ_s then decelerates it. That holds
only where the estimate is right. After a hand lets go, the estimate keeps a residual of the
model's error (drive friction that unloads, a mass or friction a few per cent off): tens of
newtons on the simulated er20's realistic plant. A residual above δ keeps the tool going on
its own (issue 24: the random pushes' run-on reached 57–363 mm).

So the guiding cycle watches the estimate itself, not only its level:

* **letting go** (:func:`let_go_step`, while moving): per part (force, torque) the smoothed
  magnitude ‖F̄‖ falls from its recent peak P by max(δ, ``drop_fraction``·(P − δ)) or more.
  δ (the law's friction, the part's largest; eq. 36's when automatic) is the smallest force a
  push must hold to move the tool (eq. 32–33), so a hand that lets go removes at least δ
  whatever the model's error; a fall of half of the force above δ is demanded from a larger
  hold, so that the estimate's swings under a steady large push (the model's error follows
  the motion) are no release. The peak holds for ``window_s`` (the estimator's 3 Hz filter
  and the smoothing spread a release's fall over ~0.2 s), then forgets with that time
  constant (a slow decrease of the force is the operator slowing down, which the law follows);
* **the stop**: from a letting go the commanded twist decelerates at the acceleration limit
  (:func:`leadthrough.control.limits.decelerate_twist`, the dominant part at Table IV's limit)
  to rest and stays there, whatever the estimate says: the stop needs no force model. What it
  needs is to see the fall: a residual that stays within δ of the held force (a model error
  as large as the push less δ) is not seen, and the paper's law then applies;
* **a fresh rise** (:func:`fresh_rise`): guiding resumes, no sooner than ``lockout_s`` after
  the letting go (the estimate falls within the estimator's filter time), when on some part
  ‖F̄‖ rises by δ or more over a reference that follows its falls at once and its rises with
  the time constant ``rise_window_s`` (a hand that grips again: a step, passed at the
  estimator filter's pace; the drives unloading after a release swing the estimate the other
  way, by up to twice the released force, but over about a second, too slowly to count).
  A level alone does not resume it, however high: on the simulated er20 the swing after
  letting go of a 37 N hold at rest reached 54 N (above δ_s) 1.7 s later. A letting go at
  rest (a hand that held the tool still, :mod:`leadthrough.control.release`) holds the tool
  the same way;
* **the settled level**: once the drives have settled (``GuidingConfig.settle_s`` after the
  letting go) the estimate's level is taken as the drives' own
  (:mod:`leadthrough.control.rest_drift` follows its slow drift from there), and a rise of δ
  over it on some axis resumes guiding too (a hand that leans in slowly). A hand may already
  hold the tool then: its grip is no fresh rise where it pushes against a standing phantom
  (the magnitude falls), and a level that took up its hold reads its letting go, the
  estimate's return to the phantom, as a rise of δ with no hand on the tool (issue 24: the
  late restarts of the run-on benchmark). So a **letting go of a hold the level took up**
  (:func:`level_let_go`: a change of δ/2 within about 0.3 s back against the level, toward
  zero and beyond) clears the level, and it is taken again ``settle_s`` after the last such
  change. A change along the level is not one: a hand that leans on harder, or the drives'
  ramp at rest, still counts as a rise over it (the ramp is what restarts the stop with no
  hand on the tool in the rest of the run-on benchmark's late releases; with a hand on it, as
  on the seam, it is what resumes guiding there, and no rule on the estimate tells the two
  apart: README, Limitations).

After guiding resumes, the law is the paper's again, with the settling after a stop or a
release (``GuidingConfig.settle_s``: eq. 33's δ_s at rest).

Compiled (Numba, ``nopython``, cached on disk), run by :mod:`leadthrough.control.guiding_cycle`
on the controller's record (fields ``hand_*``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from leadthrough.errors import ControlError, check_fields

__all__ = ["HandReleaseConfig", "fresh_rise", "let_go_step", "level_let_go", "part_level"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class HandReleaseConfig:
    """The stop after the hand lets go of a moving tool (module docstring), validated once.

    Attributes:
        enabled: Detect letting go in motion and stop at the acceleration limit (False, the
            default: the paper's law alone, eq. 31–33). Off by default because it brakes the
            seam's operator where the hand eases off to stop at P1 / P2 (issue 24: seam end
            points median 11–63 mm against 5 mm with the paper's law; README, Limitations).
        drop_fraction: Fraction of the peak's excess over δ whose fall is a letting go, in
            (0, 1] (1: all of it; smaller: more sensitive, more false stops).
        lockout_s: Time after a letting go before a rise may resume guiding [s], >= 0.
        smoothing_s: Time constant of the force's first-order smoothing [s], > 0 (the
            estimator's noise, eq. 36's σ of a few N, must not look like a fall).
        window_s: How long the peak holds, and then the time constant with which it
            forgets [s], > 0.
        rise_window_s: Time constant with which the rise's reference forgets [s], > 0: a
            hand that grips again is a step the estimator passes within its filter's time
            (3 Hz: τ = 53 ms), so a rise of δ against a reference that lags by about three
            times that is a grip (with δ = 15 N: a step of 35 N or more); the estimate's
            drift after a release (the drives unloading, up to ~100 N/s) lags less than δ.
    """

    enabled: bool = False
    drop_fraction: float = 0.5
    lockout_s: float = 0.3
    smoothing_s: float = 0.05
    window_s: float = 0.3
    rise_window_s: float = 0.15

    def __post_init__(self) -> None:
        check_fields("hand_release", self, [
            ("enabled", isinstance(self.enabled, bool), "True or False"),
            ("drop_fraction", 0.0 < self.drop_fraction <= 1.0, "in (0, 1]"),
            ("lockout_s", math.isfinite(self.lockout_s) and self.lockout_s >= 0.0,
             "finite, >= 0 [s]"),
            ("smoothing_s", math.isfinite(self.smoothing_s) and self.smoothing_s > 0.0,
             "finite, > 0 [s]"),
            ("window_s", math.isfinite(self.window_s) and self.window_s > 0.0,
             "finite, > 0 [s]"),
            ("rise_window_s", math.isfinite(self.rise_window_s) and self.rise_window_s > 0.0,
             "finite, > 0 [s]"),
        ], ControlError)

    def alpha(self, dt: float) -> float:
        """Weight of a new sample in the smoothing for a cycle of ``dt`` [s], in (0, 1)."""
        return dt / (self.smoothing_s + dt)

    def forget(self, dt: float) -> float:
        """Per-cycle factor of the peak's relaxation for a cycle of ``dt`` [s], in (0, 1)."""
        return math.exp(-dt / self.window_s)

    def rise_forget(self, dt: float) -> float:
        """Per-cycle factor of the rise reference's relaxation, in (0, 1)."""
        return math.exp(-dt / self.rise_window_s)


@njit(cache=True, nogil=True)
def part_level(values: Array, part: int) -> float:
    """The largest of a part's three values (part 0: force [N], 1: torque [N·m])."""
    i = 3 * part
    return max(values[i], values[i + 1], values[i + 2])


@njit(cache=True, nogil=True)
def let_go_step(wrench: Array, friction: Array, alpha: float, dt: float, hold_s: float,
                forget: float, drop_fraction: float, smooth: Array, peak: Array,
                peak_age: Array) -> bool:
    """One cycle of the letting-go detector: smooth the wrench, follow each part's peak, and
    tell whether some part's magnitude fell from its peak P by max(δ, ``drop_fraction``·(P −
    δ)) (δ: the part's largest friction).

    The peak holds for ``hold_s`` after it was last reached (so that all of a release's fall,
    which the estimator's filter and the smoothing spread over ~0.2 s, counts), then relaxes
    toward the smoothed wrench by ``forget`` per cycle (a slow decrease is the operator
    slowing down, not letting go).

    Args:
        wrench: Estimated wrench in the controller's frame [N, N·m], shape (6,).
        friction: The law's δ per axis [N, N·m], shape (6,).
        alpha: Weight of the new sample in the smoothing, in (0, 1].
        dt: Controller cycle [s].
        hold_s: How long the peak holds [s].
        forget: Per-cycle relaxation factor of the peak after the hold, in [0, 1].
        drop_fraction: Fraction of the peak's excess over δ whose fall is a letting go.
        smooth: Smoothed wrench, shape (6,); updated in place.
        peak: The smoothed wrench at each part's peak magnitude, shape (6,); updated in place
            (restarts from the smoothed wrench after a letting go).
        peak_age: Time since each part's peak was reached [s], shape (2,); updated in place.

    Returns:
        Whether some part let go this cycle.
    """
    fell_any = False
    for part in range(2):
        i = 3 * part
        relax = forget if peak_age[part] >= hold_s else 1.0
        m2 = p2 = 0.0
        for k in range(i, i + 3):
            smooth[k] += alpha * (wrench[k] - smooth[k])
            peak[k] = smooth[k] + (peak[k] - smooth[k]) * relax
            m2 += smooth[k] * smooth[k]
            p2 += peak[k] * peak[k]
        m, p = math.sqrt(m2), math.sqrt(p2)
        d = part_level(friction, part)
        fell = p - m >= max(d, drop_fraction * (p - d))
        if fell or m >= p:
            peak[i:i + 3] = smooth[i:i + 3]
            peak_age[part] = 0.0
        else:
            peak_age[part] += dt
        fell_any = fell_any or fell
    return fell_any


@njit(cache=True, nogil=True)
def fresh_rise(smooth: Array, friction: Array, forget: float, reference: Array) -> bool:
    """Whether a hand grips again: on some part the smoothed wrench moved away from its
    reference by δ (the part's largest) or more while its magnitude did not fall. The reference
    follows a falling magnitude at once and relaxes toward a rising one by ``forget`` per cycle.

    Args:
        smooth: Smoothed wrench (:func:`let_go_step`'s) [N, N·m], shape (6,).
        friction: δ per axis [N, N·m], shape (6,).
        forget: Per-cycle relaxation factor of the reference, in [0, 1].
        reference: The reference, shape (6,); updated in place.
    """
    rose = False
    for part in range(2):
        i = 3 * part
        m2 = r2 = d2 = 0.0
        for k in range(i, i + 3):
            relaxed = smooth[k] + (reference[k] - smooth[k]) * forget
            m2 += smooth[k] * smooth[k]
            r2 += reference[k] * reference[k]
            d2 += (smooth[k] - relaxed) * (smooth[k] - relaxed)
        falling = m2 < r2
        rose = rose or (not falling and math.sqrt(d2) >= part_level(friction, part))
        for k in range(i, i + 3):
            if falling:
                reference[k] = smooth[k]
            else:
                reference[k] = smooth[k] + (reference[k] - smooth[k]) * forget
    return rose


@njit(cache=True, nogil=True)
def level_let_go(smooth: Array, friction: Array, band: float, forget: float, level: Array,
                 reference: Array) -> bool:
    """Whether a hand let go of a hold that ``level`` took up: on some part the smoothed wrench
    moved away from a lagging reference by ``band``·δ (the part's largest) or more, back
    against the level's direction (the change's dot product with the level is negative: the
    estimate leaves the hold toward zero and beyond). The reference relaxes toward the
    smoothed wrench by ``forget`` per cycle, so a step of S (a letting go, passed by the
    estimator's 3 Hz filter) leaves a gap of about half of S, and a ramp of rate ρ a gap of ρ
    times the reference's lag.

    The stop after a letting go takes the level the estimate settles to as the drives' own
    (``guiding_cycle._hand_release``); a hand that gripped against a standing phantom is no
    :func:`fresh_rise` (the magnitude falls), and if that level took up its hold, its letting go
    would read as a rise over it. A change along the level (a hand that leans on harder, or
    the drives' ramp at rest) is not counted: it is what the rise over the level is for.

    Args:
        smooth: Smoothed wrench (:func:`let_go_step`'s) [N, N·m], shape (6,).
        friction: δ per axis [N, N·m], shape (6,).
        band: Fraction of δ that counts as a hand's change, > 0.
        forget: Per-cycle relaxation factor of the reference, in [0, 1].
        level: The level the estimate settled to [N, N·m], shape (6,).
        reference: The reference, shape (6,); updated in place.

    Returns:
        Whether some part moved back against the level by ``band``·δ or more this cycle.
    """
    active = False
    for part in range(2):
        i = 3 * part
        d2 = along = 0.0
        for k in range(i, i + 3):
            reference[k] = smooth[k] + (reference[k] - smooth[k]) * forget
            d2 += (smooth[k] - reference[k]) * (smooth[k] - reference[k])
            along += (smooth[k] - reference[k]) * level[k]
        active = active or (along < 0.0 and math.sqrt(d2) >= band * part_level(friction, part))
    return active
