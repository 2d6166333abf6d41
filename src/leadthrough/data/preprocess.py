"""Pre-processing for calibration (offline, zero phase), as in the paper's Section III-A.

1. Resample to a uniform grid when the log's sample times jitter (real controllers do).
2. Zero-phase Butterworth low-pass (``filtfilt``) of q and of the torque/current signal.
3. q̇ and q̈ by central differences of the filtered q (the paper's offline differentiation).
4. Trim the ends (filter transients) and optionally decimate (after filtering: no aliasing).
5. Mark near-standstill samples per joint (|q̇_j| below a threshold), where friction is
   undetermined; identification ignores those joint equations, as the paper drops them.

Every threshold is in :class:`PreprocessConfig`, with documented defaults.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from leadthrough.data.align import interp_columns
from leadthrough.data.recording import Recording
from leadthrough.errors import DataError, check_fields
from leadthrough.robot.description import Robot

__all__ = ["PreprocessConfig", "ProcessedData", "preprocess"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class PreprocessConfig:
    """Pre-processing settings.

    Attributes:
        position_cutoff_hz: Low-pass cut-off for q before differentiation [Hz]. Default 10 Hz:
            well above the content of excitation trajectories (≤ a few Hz), well below encoder
            and servo noise.
        torque_cutoff_hz: Low-pass cut-off for the current/torque signal [Hz]. Default 10 Hz, the
            same, so that model and measurement see the same filter.
        filter_order: Butterworth order (applied forward and backward: twice the order).
        standstill_velocity: Joint equations with |q̇_j| below this are dropped [rad/s].
        decimate_to_hz: Keep about this rate after filtering [Hz]; None keeps all samples.
        trim_s: Time cut from both ends after filtering [s].
        max_jitter: Resample to a uniform grid when the sample interval varies by more than
            this fraction of its median.
    """

    position_cutoff_hz: float = 10.0
    torque_cutoff_hz: float = 10.0
    filter_order: int = 4
    standstill_velocity: float = 0.02
    decimate_to_hz: float | None = 200.0
    trim_s: float = 0.25
    max_jitter: float = 0.05

    def __post_init__(self) -> None:
        checks = [
            ("position_cutoff_hz", self.position_cutoff_hz > 0, "> 0 Hz"),
            ("torque_cutoff_hz", self.torque_cutoff_hz > 0, "> 0 Hz"),
            ("filter_order", 1 <= self.filter_order <= 10, "1..10"),
            ("standstill_velocity", self.standstill_velocity >= 0, ">= 0 rad/s"),
            ("decimate_to_hz", self.decimate_to_hz is None or self.decimate_to_hz > 0,
             "> 0 Hz or None"),
            ("trim_s", self.trim_s >= 0, ">= 0 s"),
            ("max_jitter", self.max_jitter >= 0, ">= 0"),
        ]
        check_fields("preprocess", self, checks)


@dataclass(frozen=True)
class ProcessedData:
    """Filtered, differentiated samples ready for identification.

    Attributes:
        time: [s], shape (N,).
        q: Filtered positions [rad], shape (N, n).
        qd: Velocities [rad/s], shape (N, n).
        qdd: Accelerations [rad/s²], shape (N, n).
        torque: Filtered joint torque from the drives, R·Kt·i or logged torque [N·m], (N, n).
        moving: Joint equations to use (not near standstill), shape (N, n), bool.
        rate_hz: Sample rate after decimation [Hz].
        source: Where the data came from.
    """

    time: Array
    q: Array
    qd: Array
    qdd: Array
    torque: Array
    moving: NDArray[np.bool_]
    rate_hz: float
    source: str | None

    @property
    def samples(self) -> int:
        """Number of samples N."""
        return int(self.time.size)


def _uniform(rec: Recording, torque: Array, max_jitter: float) -> tuple[Array, Array, Array]:
    dt = np.diff(rec.time)
    med = float(np.median(dt))
    if np.max(np.abs(dt - med)) <= max_jitter * med:
        return rec.time, rec.q, torque
    t = np.arange(rec.time[0], rec.time[-1], med)
    return t, interp_columns(t, rec.time, rec.q), interp_columns(t, rec.time, torque)


def preprocess(rec: Recording, robot: Robot, config: PreprocessConfig | None = None
               ) -> ProcessedData:
    """Filter, differentiate, trim, decimate and mark standstill.

    Args:
        rec: The recording (currents or torques).
        robot: The robot (for R·Kt and the joint count).
        config: Settings; defaults documented in :class:`PreprocessConfig`.

    Returns:
        Processed samples.

    Raises:
        DataError: Wrong joint count, too few samples, or a cut-off above the Nyquist rate.
    """
    cfg = config if config is not None else PreprocessConfig()
    torque_raw = rec.joint_torque(robot)
    t, q, tau = _uniform(rec, torque_raw, cfg.max_jitter)
    dt = float(np.median(np.diff(t)))
    rate = 1.0 / dt
    for name, fc in (("position_cutoff_hz", cfg.position_cutoff_hz),
                     ("torque_cutoff_hz", cfg.torque_cutoff_hz)):
        if fc >= 0.5 * rate:
            raise DataError("cut-off at or above the Nyquist frequency", source=rec.source,
                            field=f"preprocess.{name}", value=fc,
                            expected=f"< {0.5 * rate:g} Hz for a {rate:g} Hz recording")
    trim = round(cfg.trim_s * rate)
    min_samples = 6 * (cfg.filter_order + 1) + 2 * trim + 10
    if t.size < min_samples:
        raise DataError("too few samples", source=rec.source, field="samples", value=t.size,
                        expected=f">= {min_samples} (record a longer motion, at least "
                                 f"{min_samples * dt:.2f} s at {rate:g} Hz)")
    sos_q = scipy.signal.butter(cfg.filter_order, cfg.position_cutoff_hz, fs=rate, output="sos")
    sos_t = scipy.signal.butter(cfg.filter_order, cfg.torque_cutoff_hz, fs=rate, output="sos")
    qf = scipy.signal.sosfiltfilt(sos_q, q, axis=0)
    tf = scipy.signal.sosfiltfilt(sos_t, tau, axis=0)
    qd = np.gradient(qf, dt, axis=0)
    qdd = np.gradient(qd, dt, axis=0)
    keep = slice(trim, t.size - trim if trim else None)
    step = 1 if cfg.decimate_to_hz is None else max(1, round(rate / cfg.decimate_to_hz))
    sel = np.arange(t.size)[keep][::step]
    moving = np.abs(qd[sel]) >= cfg.standstill_velocity
    return ProcessedData(time=t[sel], q=qf[sel], qd=qd[sel], qdd=qdd[sel], torque=tf[sel],
                         moving=moving, rate_hz=rate / step, source=rec.source)
