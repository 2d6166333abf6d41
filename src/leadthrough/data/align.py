"""Time alignment of two signals logged on different clocks (e.g. an F/T sensor and the robot).

A force/torque sensor used to validate a sensorless estimate is usually logged by another
process, with its own clock and start time. :func:`estimate_lag` finds the time shift that best
lines up a signal of the second log with one of the first by normalised cross-correlation::

    lag = estimate_lag(t_robot, np.linalg.norm(f_est, axis=1),
                       t_sensor, np.linalg.norm(f_sensor, axis=1), max_lag_s=0.5)
    f_sensor_on_robot_clock = resample(t_sensor, f_sensor, t_robot + lag.lag_s)

Correlate signals that do not depend on the unknown frame (a magnitude such as ‖F‖) or that are
already in the same frame. The reference should be free of filter delay (a zero-phase estimate):
a causal filter's delay would otherwise be mistaken for a clock offset.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError

__all__ = ["LagEstimate", "estimate_lag", "interp_columns", "resample"]

Array = NDArray[np.float64]


class LagEstimate(NamedTuple):
    """Result of :func:`estimate_lag`.

    Attributes:
        lag_s: The shift L [s]: the other signal at time t + L matches the reference at t.
        correlation: Normalised cross-correlation at the best grid shift, in [−1, 1].
        lags_s: The shifts tried [s], shape (K,).
        correlations: The correlation at each shift, shape (K,) (NaN without overlap).
        at_limit: The best shift is the first or last one tried: no peak inside the range,
            the lag is not trustworthy (widen ``max_lag_s`` or check the signals).
    """

    lag_s: float
    correlation: float
    lags_s: Array
    correlations: Array
    at_limit: bool


def _signal(name: str, t: Array, x: Array) -> tuple[Array, Array]:
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise DataError("needs at least 3 samples", field=f"{name} time", value=t.shape,
                        expected="a 1-D array of sample times [s]")
    if x.shape[:1] != t.shape or x.ndim not in (1, 2):
        raise DataError("does not match its time array", field=name, value=x.shape,
                        expected=f"shape ({t.size},) or ({t.size}, k)")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
        raise DataError("not finite", field=name, expected="finite samples")
    if np.any(np.diff(t) <= 0):
        raise DataError("time is not strictly increasing", field=f"{name} time",
                        expected="strictly increasing sample times [s]")
    return t, x.reshape(t.size, -1)


def resample(t: Array, x: Array, t_new: Array) -> Array:
    """Linear interpolation of samples onto other times (held constant beyond the ends).

    Args:
        t: Sample times [s], shape (N,), strictly increasing.
        x: Samples, shape (N,) or (N, k).
        t_new: Times to interpolate at [s], shape (M,).

    Returns:
        Shape (M,) or (M, k), like ``x``.

    Raises:
        DataError: Shapes do not match, non-finite values or non-increasing time.
    """
    t, x2 = _signal("x", t, x)
    t_new = np.asarray(t_new, dtype=float)
    out = interp_columns(t_new, t, x2)
    return out[:, 0] if np.ndim(x) == 1 else out


def interp_columns(t_new: Array, t: Array, x: Array) -> Array:
    """Linear interpolation of every column (no validation; see :func:`resample`).

    Args:
        t_new: Times to interpolate at [s], shape (M,).
        t: Sample times [s], shape (N,), increasing.
        x: Samples, shape (N, k).

    Returns:
        Shape (M, k).
    """
    return np.column_stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])])


def estimate_lag(t_ref: Array, x_ref: Array, t_other: Array, x_other: Array,
                 max_lag_s: float, step_s: float | None = None,
                 min_overlap: float = 0.5) -> LagEstimate:
    """Time shift between two logs by normalised cross-correlation.

    For every shift L on a grid in [−max_lag_s, max_lag_s] the other signal is interpolated at
    t_ref + L and correlated (Pearson; summed over the channels of 2-D signals) with the
    reference where both exist; the best grid shift is refined by a parabola through its
    neighbours.

    Args:
        t_ref: Reference sample times [s], shape (N,), strictly increasing.
        x_ref: Reference signal, shape (N,) or (N, k).
        t_other: Sample times of the other log [s] on its own clock, shape (M,).
        x_other: The other signal, same channels as ``x_ref``, shape (M,) or (M, k).
        max_lag_s: Largest shift tried [s], > 0.
        step_s: Grid step [s]; default: the reference's median sample interval.
        min_overlap: Shifts leaving less than this fraction of the reference inside the
            other log are skipped.

    Returns:
        The shift, its correlation and the whole correlation curve.

    Raises:
        DataError: Malformed signals or settings, or no shift with enough overlap and
            variation in both signals.
    """
    t_ref, a = _signal("x_ref", t_ref, x_ref)
    t_other, b = _signal("x_other", t_other, x_other)
    if a.shape[1] != b.shape[1]:
        raise DataError("channel counts differ", field="x_other", value=b.shape[1],
                        expected=f"{a.shape[1]} channels like x_ref")
    step = float(np.median(np.diff(t_ref))) if step_s is None else float(step_s)
    if not (np.isfinite(max_lag_s) and max_lag_s > 0):
        raise DataError("out of range", field="max_lag_s", value=max_lag_s, expected="> 0 s")
    if not (np.isfinite(step) and 0 < step <= max_lag_s):
        raise DataError("out of range", field="step_s", value=step_s,
                        expected=f"0 < step <= max_lag_s = {max_lag_s} s")
    if not 0 < min_overlap <= 1:
        raise DataError("out of range", field="min_overlap", value=min_overlap,
                        expected="0 < fraction <= 1")
    half = int(np.floor(max_lag_s / step + 1e-9))
    lags = np.arange(-half, half + 1, dtype=float) * step
    corr = np.full(lags.size, np.nan)
    for i, lag in enumerate(lags):
        tq = t_ref + lag
        inside = (tq >= t_other[0]) & (tq <= t_other[-1])
        if inside.mean() < min_overlap:
            continue
        ar = a[inside] - a[inside].mean(axis=0)
        br = interp_columns(tq[inside], t_other, b)
        br -= br.mean(axis=0)
        den = np.sqrt(np.sum(ar * ar) * np.sum(br * br))
        if den > 0:
            corr[i] = float(np.sum(ar * br) / den)
    if not np.any(np.isfinite(corr)):
        raise DataError("no shift with enough overlap and variation in both signals",
                        field="max_lag_s", value=max_lag_s,
                        expected="logs that overlap in time and signals that vary")
    k = int(np.nanargmax(corr))
    valid = np.flatnonzero(np.isfinite(corr))
    lag = float(lags[k])
    if 0 < k < lags.size - 1 and np.all(np.isfinite(corr[k - 1:k + 2])):
        c0, c1, c2 = corr[k - 1], corr[k], corr[k + 1]
        curv = c0 - 2.0 * c1 + c2
        if curv < 0:
            lag += 0.5 * step * (c0 - c2) / curv
    return LagEstimate(lag_s=lag, correlation=float(corr[k]), lags_s=lags, correlations=corr,
                       at_limit=k in (valid[0], valid[-1]))
