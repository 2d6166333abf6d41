"""KUKA RobotSensorInterface over Ethernet: XML messages (:mod:`.messages`), the shipped
controller configuration (:mod:`.config`), the client transport (:class:`RsiClient`) and the
driver (:class:`KukaRsiDriver`)."""

from leadthrough.drivers.kuka_rsi.client import DEFAULT_PORT, RsiClient
from leadthrough.drivers.kuka_rsi.config import EthernetConfig, RsiContext, RsiElement, shipped_file
from leadthrough.drivers.kuka_rsi.driver import KukaRsiDriver
from leadthrough.drivers.kuka_rsi.messages import RobotMessage, SensorMessage

__all__ = [
           "DEFAULT_PORT",
           "EthernetConfig",
           "KukaRsiDriver",
           "RobotMessage",
           "RsiClient",
           "RsiContext",
           "RsiElement",
           "SensorMessage",
           "shipped_file",
]
