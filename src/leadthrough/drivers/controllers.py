"""The real controllers' drivers by name, as the command line names them (``--driver D --host H
[--port P]``): one place that knows which class speaks which interface and on which port.

* ``fanuc-j519``: :class:`~leadthrough.drivers.fanuc_j519.FanucJ519Driver` (Stream Motion,
  UDP), port 60015 on the controller;
* ``ur-rtde``: :class:`~leadthrough.drivers.ur_rtde.UrRtdeDriver` (RTDE, TCP), port 30004 on
  the controller; the servo program goes to the secondary interface at port − 2 (30002);
* ``kuka-rsi``: :class:`~leadthrough.drivers.kuka_rsi.KukaRsiDriver` (RSI, UDP): the PC
  listens, the robot sends to ``--host:--port`` (49152; ``--host`` is the PC's address to
  listen on, 0.0.0.0 for all).
"""

from __future__ import annotations

from collections.abc import Callable

from leadthrough.drivers.fanuc_j519 import FanucJ519Driver
from leadthrough.drivers.fanuc_j519.packets import DEFAULT_PORT as J519_PORT
from leadthrough.drivers.kuka_rsi import KukaRsiDriver
from leadthrough.drivers.kuka_rsi.client import DEFAULT_PORT as RSI_PORT
from leadthrough.drivers.kuka_rsi.client import parse_address
from leadthrough.drivers.streaming import StreamingDriver
from leadthrough.drivers.ur_rtde import UrRtdeDriver
from leadthrough.drivers.ur_rtde.protocol import DEFAULT_PORT as RTDE_PORT
from leadthrough.errors import ControlError
from leadthrough.robot.description import Robot

__all__ = ["CONTROLLERS", "DEFAULT_PORTS", "connect"]

Factory = Callable[[Robot, str, int], StreamingDriver]


def _ur(robot: Robot, host: str, port: int) -> UrRtdeDriver:
    return UrRtdeDriver(robot, host, port, script_port=port - 2)


#: Driver of each controller interface: ``(robot, host, port) -> driver`` (not opened).
CONTROLLERS: dict[str, Factory] = {
    "fanuc-j519": lambda robot, host, port: FanucJ519Driver(robot, host, port),
    "ur-rtde": _ur,
    "kuka-rsi": lambda robot, host, port: KukaRsiDriver(robot, host, port),
}

#: Each interface's own port.
DEFAULT_PORTS: dict[str, int] = {"fanuc-j519": J519_PORT, "ur-rtde": RTDE_PORT,
                                 "kuka-rsi": RSI_PORT}


def connect(name: str, robot: Robot, host: str | None,
            port: int | None = None, robot_address: str | None = None) -> StreamingDriver:
    """The driver of controller interface ``name`` (not opened: ``with driver:`` opens it).

    Args:
        name: ``fanuc-j519``, ``ur-rtde`` or ``kuka-rsi``.
        robot: The robot file of the arm.
        host: The controller's address (RSI: the address to listen on).
        port: The port (None: the interface's own, :data:`DEFAULT_PORTS`).
        robot_address: ``kuka-rsi`` only: the robot's ``HOST[:PORT]``, the one sender whose
            documents are taken (None: the first valid document's sender).

    Raises:
        ControlError: Unknown interface, no host, a port outside 1–65535 (0–65535 for
            ``kuka-rsi``, where 0 takes a free port), or a robot address for another
            interface than ``kuka-rsi``.
        DriverError: A robot address that is not ``HOST[:PORT]``.
    """
    factory = CONTROLLERS.get(name)
    if factory is None:
        raise ControlError("no such driver", field="--driver", value=name,
                           expected=", ".join(sorted(CONTROLLERS)))
    if not host:
        raise ControlError("a controller needs its address", field="--host", value=host,
                           expected="the controller's IP address or host name")
    port = DEFAULT_PORTS[name] if port is None else port
    lowest = 0 if name == "kuka-rsi" else 1  # the PC listens: 0 takes a free port
    if not lowest <= port <= 65535:
        raise ControlError("out of range", field="--port", value=port,
                           expected=f"{lowest}-65535")
    if robot_address is not None:
        if name != "kuka-rsi":
            raise ControlError("only for kuka-rsi", field="--robot-address",
                               value=robot_address, expected="no --robot-address with "
                               f"--driver {name} (it connects to --host)")
        return KukaRsiDriver(robot, host, port, robot_address=parse_address(robot_address))
    return factory(robot, host, port)
