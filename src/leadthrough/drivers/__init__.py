"""Robot drivers: the guiding loop's link to a position-mode controller (or the simulator).

:class:`Driver` is the protocol (preallocated :class:`DriverFeedback` and :class:`JointCommand`,
one :meth:`Driver.step` per servo period); :class:`SimDriver` runs it on the simulated robot and
injects feedback faults (:class:`Fault`) for safety tests; :class:`RecordingDriver` records what
any driver delivers and :class:`ReplayDriver` delivers it again.
"""

from leadthrough.drivers.protocol import Driver, DriverFeedback, JointCommand
from leadthrough.drivers.replay import FeedbackTrace, RecordingDriver, ReplayDriver
from leadthrough.drivers.sim_driver import Fault, FaultKind, SimDriver

__all__ = ["Driver", "DriverFeedback", "Fault", "FaultKind", "FeedbackTrace", "JointCommand",
           "RecordingDriver", "ReplayDriver", "SimDriver"]
