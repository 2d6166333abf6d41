"""FANUC Stream Motion (option J519): packet codec (:mod:`.packets`, :mod:`.limits`) the
client transport (:class:`StreamMotionClient`) and the driver (:class:`FanucJ519Driver`)."""

from leadthrough.drivers.fanuc_j519.client import StreamMotionClient
from leadthrough.drivers.fanuc_j519.driver import FanucJ519Driver
from leadthrough.drivers.fanuc_j519.limits import LimitAnswer, LimitKind, LimitQuery
from leadthrough.drivers.fanuc_j519.packets import (
    DEFAULT_PORT,
    CommandPacket,
    IoType,
    StartPacket,
    StatusBits,
    StatusPacket,
    StopPacket,
    decode_client_packet,
    decode_robot_packet,
)

__all__ = [
    "DEFAULT_PORT",
    "CommandPacket",
    "FanucJ519Driver",
    "IoType",
    "LimitAnswer",
    "LimitKind",
    "LimitQuery",
    "StartPacket",
    "StatusBits",
    "StatusPacket",
    "StopPacket",
    "StreamMotionClient",
    "decode_client_packet",
    "decode_robot_packet",
]
