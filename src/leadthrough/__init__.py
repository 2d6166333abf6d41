"""leadthrough: sensorless hand guiding for industrial robots.

Pipeline: robot → dynamics → excitation → data → identification → estimation → control → teach,
with ``sim`` (the simulated robot) and ``drivers`` beside them.
"""

from leadthrough.errors import (
    DataError,
    LeadthroughError,
    RobotFileError,
    SimulationError,
    UnknownRobotError,
)

__version__ = "0.1.0"

__all__ = [
    "DataError",
    "LeadthroughError",
    "RobotFileError",
    "SimulationError",
    "UnknownRobotError",
    "__version__",
]
