"""leadthrough: sensorless hand guiding for industrial robots.

Pipeline: robot → dynamics → excitation → data → identification → estimation → control → teach,
with ``sim`` (the simulated robot) and ``drivers`` beside them.
"""

from pathlib import Path as _Path

from leadthrough.compiled_cache import refresh_compiled_cache as _refresh_compiled_cache
from leadthrough.errors import (
    DataError,
    LeadthroughError,
    RobotFileError,
    SimulationError,
    UnknownRobotError,
)

__version__ = "0.1.0"

# before any compiled function loads: numba's caches follow their own file only
# (leadthrough.compiled_cache)
_refresh_compiled_cache(_Path(__file__).parent)

__all__ = [
    "DataError",
    "LeadthroughError",
    "RobotFileError",
    "SimulationError",
    "UnknownRobotError",
    "__version__",
]
