"""Universal Robots RTDE: protocol codec (:mod:`.protocol`), the servo URScript program
(:mod:`.script`), the client transport (:class:`RtdeClient`) and the driver
(:class:`UrRtdeDriver`)."""

from leadthrough.drivers.ur_rtde.client import DEFAULT_OUTPUTS, RtdeClient, RtdeState, ServoCommand
from leadthrough.drivers.ur_rtde.driver import UrRtdeDriver
from leadthrough.drivers.ur_rtde.protocol import (
    DEFAULT_PORT,
    ControllerVersion,
    MessageType,
    Recipe,
)
from leadthrough.drivers.ur_rtde.script import (
    SECONDARY_PORT,
    Mode,
    ScriptState,
    ServoScriptParameters,
    servo_script,
    upload_script,
)

__all__ = ["DEFAULT_OUTPUTS", "DEFAULT_PORT", "SECONDARY_PORT", "ControllerVersion",
           "MessageType", "Mode", "Recipe", "RtdeClient", "RtdeState", "ScriptState",
           "ServoCommand", "ServoScriptParameters", "UrRtdeDriver", "servo_script",
           "upload_script"]
