"""The estimator re-zeroed while the robot stands still (a zero-velocity update): once the
commanded motion has been at rest for the controller's settling time, the estimator takes the
force it reads there as zero (:meth:`~leadthrough.estimation.estimator.ExternalForceEstimator.
rezero`); a motion that restarts before the re-zero is done abandons it. Run by the loop on
its controller cycles (:mod:`leadthrough.session.servo_loop`).
"""

from __future__ import annotations

from leadthrough.estimation.estimator import ExternalForceEstimator

__all__ = ["zero_velocity_update"]


def zero_velocity_update(estimator: ExternalForceEstimator, rest_s: float, settle_s: float,
                          cycle_s: float, samples: int) -> None:
    """Re-zero the estimator once the commanded motion has been at rest for ``settle_s``
    (in the first controller cycle past it); abandon the re-zero if the motion restarts."""
    if rest_s == 0.0:
        if estimator.rezeroing:
            estimator.cancel_rezero()
    elif settle_s <= rest_s < settle_s + cycle_s:
        estimator.rezero(samples)
