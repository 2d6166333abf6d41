"""A recording: what a robot controller logs during a motion.

Time [s], joint positions q [rad], and either motor currents [A] or joint torques [N·m] (some
controllers log torque, e.g. current × drive gain), plus optionally the commanded positions.
Construction validates everything once; invalid data raise :class:`~leadthrough.errors.DataError`
naming the field and what was expected.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leadthrough.errors import DataError, DataWarning
from leadthrough.robot.description import Robot

__all__ = ["Recording", "is_sim_seed"]

Array = NDArray[np.float64]

#: How far a recorded joint position may lie outside the robot's limits without a warning [rad]
#: (encoder offsets; a URDF's limits a little inside the mechanical ones).
JOINT_RANGE_TOLERANCE = 0.1


def is_sim_seed(value: object) -> bool:
    """Whether ``value`` names a simulated robot instance: an integer >= 0 (not a bool). The
    one rule for a recording's, a params file's and a session's ``sim_seed``."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


@dataclass(frozen=True, eq=False)
class Recording:
    """A logged motion.

    Attributes:
        time: Sample times [s], shape (N,), strictly increasing.
        q: Joint positions [rad], shape (N, n).
        current: Motor currents [A], shape (N, n), or None if the log holds torque.
        torque: Joint torques [N·m], shape (N, n), or None if the log holds current.
        q_cmd: Commanded joint positions [rad], shape (N, n), or None.
        robot: Name of the robot it was recorded on, if known.
        source: Where it came from (file path), for error messages.
        sim_seed: The simulated robot instance that recorded it (``leadthrough record
            --seed``); None for a real robot. Carried into the params file, so that a session
            runs on the simulated robot the parameters were identified on.
    """

    time: Array
    q: Array
    current: Array | None = None
    torque: Array | None = None
    q_cmd: Array | None = None
    robot: str | None = None
    source: str | None = None
    sim_seed: int | None = None

    def __post_init__(self) -> None:
        src = self.source
        if self.sim_seed is not None and not is_sim_seed(self.sim_seed):
            raise DataError("not a simulated robot instance", source=src, field="sim_seed",
                            value=self.sim_seed, expected="None or an integer >= 0")
        t = np.asarray(self.time, dtype=float)
        q = np.asarray(self.q, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise DataError("needs at least 2 samples", source=src, field="time",
                            value=t.shape, expected="a 1-D array of N >= 2 times")
        if q.ndim != 2 or q.shape[0] != t.size:
            raise DataError("does not match the time column", source=src, field="q",
                            value=q.shape, expected=f"shape ({t.size}, n)")
        if (self.current is None) == (self.torque is None):
            raise DataError("needs exactly one of current and torque", source=src,
                            field="current/torque",
                            expected="motor currents [A] or joint torques [N·m]")
        arrays = {"time": t, "q": q}
        for name in ("current", "torque", "q_cmd"):
            v = getattr(self, name)
            if v is None:
                continue
            v = np.asarray(v, dtype=float)
            if v.shape != q.shape:
                raise DataError("does not match q", source=src, field=name, value=v.shape,
                                expected=f"shape {q.shape}")
            arrays[name] = v
        for name, v in arrays.items():
            if not np.all(np.isfinite(v)):
                bad = int(np.sum(~np.isfinite(v).reshape(v.shape[0], -1).all(axis=1)))
                raise DataError(f"{bad} rows are not finite", source=src, field=name,
                                expected="finite values (drop NaN rows when loading)")
            object.__setattr__(self, name, v)
        dt = np.diff(t)
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0)) + 1
            raise DataError("time is not strictly increasing", source=src, field="time",
                            value=f"row {k}: {float(t[k - 1])!r} -> {float(t[k])!r} s",
                            expected="strictly increasing sample times [s]")

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.q.shape[1])

    @property
    def samples(self) -> int:
        """Number of samples N."""
        return int(self.time.size)

    @property
    def duration(self) -> float:
        """Recording length [s]."""
        return float(self.time[-1] - self.time[0])

    @property
    def signal(self) -> str:
        """``"current"`` or ``"torque"``: what the log holds."""
        return "current" if self.current is not None else "torque"

    def uniform_rate(self, what: str) -> float:
        """The sample rate [Hz] of a uniformly sampled recording.

        Args:
            what: What the recording is for, in the error message (e.g. ``"the sweep"``).

        Raises:
            DataError: Fewer than 10 samples, or time steps varying by more than 10 %.
        """
        dt = np.diff(self.time)
        if self.time.size < 10 or np.ptp(dt) > 0.1 * float(np.median(dt)):
            raise DataError(f"{what} must be uniformly sampled", source=self.source,
                            field="time", expected="at least 10 uniform time stamps")
        return 1.0 / float(np.median(dt))

    def check_robot(self, robot: Robot) -> None:
        """Raise a DataError unless the recording fits ``robot`` (joint count, name)."""
        if self.n != robot.n:
            raise DataError("joint count does not match the robot", source=self.source,
                            field="q", value=self.n,
                            expected=f"{robot.n} joints for robot '{robot.name}'")
        if self.robot is not None and self.robot != robot.name:
            raise DataError("recorded on another robot", source=self.source, field="robot",
                            value=self.robot, expected=f"'{robot.name}'")

    def check_joint_range(self, robot: Robot, tolerance: float = JOINT_RANGE_TOLERANCE) -> None:
        """Check the positions against ``robot``'s joint limits.

        A position more than half a turn outside them is corrupt (or the file is another
        robot's): an error. One more than ``tolerance`` [rad] outside them is a warning: the
        column map's offsets and the robot file's limits may use different angle conventions.

        Raises:
            DataError: A position more than π outside the limits, naming the joint's column, the
                row and the value.

        Warns:
            DataWarning: A position more than ``tolerance`` outside the limits.
        """
        self.check_robot(robot)
        lo, hi = robot.lower_limits, robot.upper_limits
        excess = np.maximum(lo - self.q, self.q - hi)
        for limit, report in ((math.pi, "error"), (tolerance, "warning")):
            bad = excess > limit
            if not bad.any():
                continue
            row, j = (int(x) for x in np.argwhere(bad)[0])
            value = float(self.q[row, j])
            if report == "error":
                raise DataError(f"joint position far outside the limits of '{robot.name}' in "
                                f"row {row} (a corrupt file, or another robot's)",
                                source=self.source, field=f"q{j + 1}", value=value,
                                expected=f"{lo[j] - limit:.4g} .. {hi[j] + limit:.4g} rad (the "
                                         "limits ± π)")
            where = f"{self.source}: " if self.source else ""
            warnings.warn(f"{where}q{j + 1} = {value:.4g} rad in row {row} lies "
                          f"{float(excess[row, j]):.3g} rad outside the joint limits of "
                          f"'{robot.name}' ({lo[j]:.4g} .. {hi[j]:.4g} rad): check the column "
                          "map's offsets against the robot file's limits", DataWarning,
                          stacklevel=2)
            return

    def joint_torque(self, robot: Robot) -> Array:
        """Joint torque [N·m], shape (N, n): logged torque, or R·Kt·current."""
        self.check_robot(robot)
        if self.torque is not None:
            return self.torque
        assert self.current is not None
        return robot.current_to_torque(self.current)

    def slice(self, start: int, stop: int) -> Recording:
        """Rows ``start:stop`` as a new recording."""
        def cut(v: Array | None) -> Array | None:
            return None if v is None else v[start:stop]
        return Recording(time=self.time[start:stop], q=self.q[start:stop],
                         current=cut(self.current), torque=cut(self.torque),
                         q_cmd=cut(self.q_cmd), robot=self.robot, source=self.source)
