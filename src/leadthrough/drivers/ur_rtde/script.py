"""The URScript program that moves a UR arm from RTDE input registers (``servoj`` + watchdog).

The program (``data/leadthrough_servo.script``) reads six joint targets from
``input_double_register_{R}..{R+5}``, a watchdog counter from ``input_int_register_{R}`` and a
mode from ``input_int_register_{R+1}`` (0 hold, 1 servo, 2 stop), and reports its state in
``output_int_register_{R}`` (1 running, 2 stopped on request, 3 stopped by the watchdog);
R is the register offset (0, or 24 for the upper range). Each cycle it calls
``servoj(q, 0, 0, period, lookahead_time, gain)``. Once the client has changed the counter,
when the counter then has not changed for ``watchdog_timeout`` it decelerates with ``stopj``
and halts (before the first change it idles in hold, so the client may load the program and
finish its set-up before commanding).

:func:`upload_script` sends the program to the controller's secondary interface (TCP 30002),
which runs a URScript program it receives (the robot must be in remote control on e-Series).

:func:`servo_script` fills in the parameters after checking them against the ranges of the
URScript manual (``servoj``: lookahead_time 0.03-0.2 s, gain 100-2000).

Sources: Universal Robots, URScript manual (``servoj``, ``stopj``, ``read_input_float_register``,
``read_input_integer_register``, ``write_output_integer_register``, ``halt``) and RTDE guide
(general-purpose registers 0-47, 24-47 being the upper range used by external tools); SDU's
``ur_rtde`` control script for the register-mailbox pattern; Universal Robots, "Remote
control via TCP/IP" support article (the client interfaces: primary 30001 and secondary 30002
run the URScript they receive).
"""

from __future__ import annotations

import math
import socket
from dataclasses import dataclass
from enum import IntEnum
from importlib import resources

from leadthrough.errors import DriverError, check_fields

__all__ = ["SECONDARY_PORT", "Mode", "ScriptState", "ServoScriptParameters", "servo_script",
           "upload_script"]

SCRIPT_NAME = "leadthrough_servo.script"
SECONDARY_PORT = 30002


class Mode(IntEnum):
    """Values of the mode register."""

    HOLD = 0
    SERVO = 1
    STOP = 2


class ScriptState(IntEnum):
    """Values of the program-state output register."""

    NOT_RUNNING = 0
    RUNNING = 1
    STOPPED = 2
    WATCHDOG = 3


@dataclass(frozen=True)
class ServoScriptParameters:
    """Parameters of the URScript program.

    Attributes:
        period: ``servoj`` time t, one RTDE cycle [s] (0.002 e-Series, 0.008 CB3).
        lookahead_time: ``servoj`` lookahead time [s], 0.03..0.2.
        gain: ``servoj`` gain, 100..2000.
        watchdog_timeout: Longest time without a new watchdog counter [s] before the program
            stops the arm, > period.
        stop_deceleration: Joint deceleration of the stops [rad/s²], > 0.
        register_offset: First register used, 0 or 24.
    """

    period: float = 0.002
    lookahead_time: float = 0.1
    gain: float = 300.0
    watchdog_timeout: float = 0.05
    stop_deceleration: float = 4.0
    register_offset: int = 0

    def __post_init__(self) -> None:
        fin = math.isfinite
        check_fields("servo_script", self, [
            ("period", fin(self.period) and 0.001 <= self.period <= 0.1,
             "0.001..0.1 s (0.002 e-Series, 0.008 CB3)"),
            ("lookahead_time", fin(self.lookahead_time) and 0.03 <= self.lookahead_time <= 0.2,
             "0.03..0.2 s (URScript servoj)"),
            ("gain", fin(self.gain) and 100 <= self.gain <= 2000, "100..2000 (URScript servoj)"),
            ("watchdog_timeout", fin(self.watchdog_timeout)
             and self.period < self.watchdog_timeout <= 1.0, "period < timeout <= 1 s"),
            ("stop_deceleration", fin(self.stop_deceleration) and self.stop_deceleration > 0,
             "> 0 rad/s^2"),
            ("register_offset", self.register_offset in (0, 24), "0 or 24"),
        ])


def servo_script(params: ServoScriptParameters | None = None) -> str:
    """The URScript program with its parameters filled in.

    Args:
        params: The parameters (default :class:`ServoScriptParameters`).

    Returns:
        URScript source, ready to send to the controller.
    """
    p = params if params is not None else ServoScriptParameters()
    text = (resources.files("leadthrough.drivers.ur_rtde") / "data" / SCRIPT_NAME).read_text(
        encoding="utf-8")
    values = {"PERIOD": p.period, "LOOKAHEAD_TIME": p.lookahead_time, "GAIN": p.gain,
              "WATCHDOG_TIMEOUT": p.watchdog_timeout,
              "STOP_DECELERATION": p.stop_deceleration, "REGISTER_OFFSET": p.register_offset}
    for name, value in values.items():
        text = text.replace("{{" + name + "}}", repr(value))
    return text


def upload_script(host: str, program: str, port: int = SECONDARY_PORT,
                  timeout: float = 2.0) -> None:
    """Send a URScript program to the controller's secondary interface, which runs it.

    Args:
        host: Controller address.
        program: URScript source (e.g. :func:`servo_script`).
        port: Secondary interface port (30002).
        timeout: Connection timeout [s].

    Raises:
        DriverError: The interface cannot be reached or the program not sent.
    """
    try:
        with socket.create_connection((host, port), timeout) as sock:
            sock.sendall(program.encode("utf-8"))
    except OSError as e:
        raise DriverError(f"cannot send the servo program: {e}", field="host:script_port",
                          value=f"{host}:{port}",
                          expected="a UR controller's secondary interface (remote control "
                          "on e-Series)") from e
