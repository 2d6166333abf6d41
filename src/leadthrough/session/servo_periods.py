"""One servo period at a time with a caller-supplied enabling function, for a runner that
drives the periods itself (the pendant's live session, :mod:`leadthrough.pendant.backend`).
:func:`leadthrough.session.loop.run_session` runs
:class:`~leadthrough.session.servo_loop.ServoLoop` instead (requests, enabling inputs, link
faults, recording to disk).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from leadthrough.control.guiding import GuidingController
from leadthrough.control.interpolation import JointInterpolator
from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand
from leadthrough.errors import ControlError
from leadthrough.estimation.estimator import EstimatorStatus, ExternalForceEstimator
from leadthrough.session.pacing import sleep_until
from leadthrough.session.rest_rezero import zero_velocity_update

__all__ = ["ServoPeriods"]

Array = NDArray[np.float64]


class ServoPeriods:
    """One servo period of the loop at a time (preallocated inputs and outputs)."""

    def __init__(self, driver: Driver, estimator: ExternalForceEstimator,
                 controller: GuidingController, interpolator: JointInterpolator, every: int,
                 deadman: Callable[[float], bool] | None,
                 applied_wrench: Callable[[], Array] | None) -> None:
        self.driver, self.estimator, self.controller = driver, estimator, controller
        self.interpolator, self.every = interpolator, every
        self.deadman, self.applied_wrench = deadman, applied_wrench
        self.e_in, self.e_out = estimator.make_input(), estimator.make_output()
        # the feedback's arrays are the estimator input's and the command's velocity is its
        # qd_cmd (the command sent this period until the interpolator writes the next at its
        # end): the driver fills what the estimator reads, with no copies in the period
        self.e_in.q[:] = self.e_in.current[:] = np.nan
        self.fb = DriverFeedback(t=float("nan"), q=self.e_in.q, current=self.e_in.current,
                                 sequence=-1)
        self.cmd = JointCommand(q=np.zeros(driver.n), qd=self.e_in.qd_cmd)
        self.c_in, self.c_out = controller.make_input(), controller.make_output()
        cfg = controller.config
        self.settle_s, self.cycle_s = cfg.settle_s, cfg.dt
        self.rezero_samples = round(cfg.rezero_s / driver.dt)

    def start(self) -> float:
        """The first sample: every part reset there, their compiled code loaded; returns the
        sample's time [s]."""
        driver, fb = self.driver, self.fb
        driver.step()
        if not driver.read(fb):
            raise ControlError("no feedback on the first read (the robot must report a "
                               "position to start from)", field="driver",
                               value=type(driver).__name__,
                               expected="a fresh sample on the first read")
        q0 = fb.q.copy()
        self.estimator.reset(q0)
        self.controller.reset(q0, fb.t)
        self.interpolator.reset(q0)
        for part in (self.estimator, self.controller, self.interpolator):
            part.warm_up()
        self.interpolator.update(self.cmd)
        return fb.t

    def period(self, i: int, t_loop: float, deadline: float | None) -> float:
        """Servo period ``i``: send the command, step, read, estimate, every ``every``
        periods the controller cycle, interpolate. Returns the compute time [µs]."""
        driver, fb, cmd = self.driver, self.fb, self.cmd
        driver.write(cmd)
        if deadline is not None:
            sleep_until(deadline)
        driver.step()
        fresh = driver.read(fb)
        t0 = time.perf_counter()
        if fresh:
            self.e_in.t = fb.t
            self.estimator.update(self.e_in, self.e_out)
        if i % self.every == 0:
            self._cycle(t_loop)
        self.interpolator.update(cmd)
        return (time.perf_counter() - t0) * 1e6

    def _cycle(self, t_loop: float) -> None:
        """The controller cycle and its setpoint for the interpolator."""
        c_in, c_out, e_out, fb = self.c_in, self.c_out, self.e_out, self.fb
        c_in.t = t_loop
        c_in.sequence = fb.sequence
        c_in.q[:] = fb.q
        c_in.current[:] = fb.current
        c_in.wrench_base[:] = e_out.wrench
        status = e_out.status
        held = True if self.deadman is None else self.deadman(t_loop)
        c_in.deadman = held and status == EstimatorStatus.OK
        c_in.estimator_status = int(status)
        self.controller.update(c_in, c_out)
        if self.rezero_samples:
            zero_velocity_update(self.estimator, c_out.rest_s, self.settle_s, self.cycle_s,
                                  self.rezero_samples)
        self.interpolator.set_target(c_out.q, c_out.qd)
