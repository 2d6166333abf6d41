"""Robot drivers: the guiding loop's link to a position-mode robot controller.

:class:`Driver` is the protocol (preallocated :class:`DriverFeedback` and :class:`JointCommand`,
one :meth:`Driver.step` per servo period); :class:`RecordingDriver` records what any driver
delivers and :class:`ReplayDriver` delivers it again. The simulated robot's driver (with fault
injection) is :class:`leadthrough.sim.driver.SimDriver`: nothing here imports the simulator.
"""

from leadthrough.drivers.protocol import (
    ControllerState,
    Driver,
    DriverFeedback,
    JointCommand,
    WrappedDriver,
)
from leadthrough.drivers.replay import FeedbackTrace, RecordingDriver, ReplayDriver

__all__ = ["ControllerState", "Driver", "DriverFeedback", "FeedbackTrace", "JointCommand",
           "RecordingDriver", "ReplayDriver", "WrappedDriver"]
