"""Universal Robots RTDE: protocol codec (:mod:`.protocol`), the servo URScript program
(:mod:`.script`) and the client transport (:class:`RtdeClient`)."""

from leadthrough.drivers.ur_rtde.client import DEFAULT_OUTPUTS, RtdeClient, RtdeState, ServoCommand
from leadthrough.drivers.ur_rtde.protocol import (
           DEFAULT_PORT,
           ControllerVersion,
           MessageType,
           Recipe,
)
from leadthrough.drivers.ur_rtde.script import (
           Mode,
           ScriptState,
           ServoScriptParameters,
           servo_script,
)

__all__ = ["DEFAULT_OUTPUTS", "DEFAULT_PORT", "ControllerVersion", "MessageType", "Mode", "Recipe",
           "RtdeClient", "RtdeState", "ScriptState", "ServoCommand", "ServoScriptParameters",
           "servo_script"]
