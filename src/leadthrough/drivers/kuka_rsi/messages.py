"""KUKA Robot Sensor Interface (RSI) over Ethernet: the XML messages (wire codec).

UDP, one XML document per datagram. Every RSI cycle (4 ms on KR C4/C5, 12 ms on KR C2) the
robot sends a ``<Rob>`` document to the sensor PC, whose address and port come from the
Ethernet configuration file, and expects a ``<Sen>`` answer carrying the same ``<IPOC>`` time
stamp before its next cycle; a late or missing answer is counted (``<Delay D=..>``) and after
the ETHERNET object's ``Timeout`` late packets RSI stops the robot.

Robot → sensor, with the elements our shipped configuration
(``data/leadthrough_rsi_ethernet.xml``) lists in ``<SEND>``::

    <Rob TYPE="KUKA">
      <RIst X=".." Y=".." Z=".." A=".." B=".." C=".."/>     DEF_RIst: actual TCP [mm, deg]
      <RSol X=".." .../>                                     DEF_RSol: TCP setpoint
      <AIPos A1=".." A2=".." A3=".." A4=".." A5=".." A6=".."/>  DEF_AIPos: axes actual [deg]
      <ASPos A1=".." .../>                                   DEF_ASPos: axes setpoint [deg]
      <Delay D=".."/>                                        DEF_Delay: late packets so far
      <GearTorque A1=".." .../>                              GEARTORQUE object [N·m]
      <DiL>..</DiL>                                          digital inputs (DIGIN, a word)
      <IPOC>..</IPOC>                                        time stamp [ms]
    </Rob>

Sensor → robot (``<RECEIVE>``: ``AK.A1`` .. ``AK.A6``, ``HOLDON="1"``; ``Stop``, ``HOLDON="0"``)::

    <Sen Type="ImFree"><AK A1=".." A2=".." A3=".." A4=".." A5=".." A6=".."/>
    <IPOC>..</IPOC></Sen>

and, to end the session, one last answer with ``<Stop>1</Stop>`` (before ``<IPOC>``): the
configuration wires ``Stop`` to the context's STOP object, which ends ``RSI_MOVECORR()`` (the
KRL program goes on to ``RSI_OFF``) instead of RSI counting ``Timeout`` late answers.

``AK`` are axis corrections [deg]. With ``RSI_ON(#ABSOLUTE)`` (our KRL program) they are
offsets from the axis positions at ``RSI_ON``, i.e. target = start + AK; ``ASPos`` reports the
setpoint the robot is following. Numbers are written with the ETHERNET object's ``Precision``
decimals (4 in our context).

Sources:
    * ros-industrial ``kuka_experimental`` / ``kuka_rsi_hw_interface`` (BSD): the
      ``ros_rsi_ethernet.xml`` SEND/RECEIVE lists, the ``<Rob TYPE="KUKA">`` and
      ``<Sen Type="ImFree">`` documents (``rsi_state.h``, ``rsi_command.h``, the
      ``kuka_rsi_simulator`` script), absolute corrections from the initial ``ASPos``, the
      4 ms cycle and the Timeout counter (``krl/KR_C4/README.md``).
    * FZI ``kuka_rsi_driver`` (BSD): torque feedback through a GEARTORQUE object wired to
      ETHERNET inputs and sent as ``GearTorque.A1..A6``, the ``Delay``, ``ProgStatus`` and
      ``OvPro`` elements, and a parser test with a full ``<Rob>`` document (IPOC
      123645634563).
    * KUKA Hungaria's ``kuka-external-control-sdk`` (Apache-2.0, github.com/kroshu): the
      ``Stop`` element (``<ELEMENT TAG="Stop" TYPE="BOOL" INDX="1" HOLDON="0"/>`` in
      ``krc_setup/kss/Config/User/Common/SensorInterface/rsi_ethernet.xml``, wired to a
      ``Stop`` RSI object, ObjTypeId 18, in ``rsi_joint_pos.rsix``) and the client's clean
      end (``Robot::StopControlling`` in ``kss/src/rsi/robot_interface.cc``: receive the
      next document if none is waiting, answer its IPOC with the stop flag set).
    * KUKA.RobotSensorInterface manual's Ethernet example as quoted by the above (tag
      ``DiL`` for a LONG of digital inputs; ``TYPE`` attribute on ``Rob``, ``Type`` on
      ``Sen``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

from leadthrough.errors import DataError

__all__ = ["AXES", "CARTESIAN", "RobotMessage", "SensorMessage"]

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
CARTESIAN = ("X", "Y", "Z", "A", "B", "C")
T = TypeVar("T")


def _parse(data: bytes | str, root_tag: str, source: str) -> ET.Element:
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise DataError(f"not well-formed XML: {e}", source=source, field="document",
                        value=bytes(data[:60]) if isinstance(data, bytes) else data[:60],
                        expected=f"a <{root_tag}> document") from e
    if root.tag != root_tag:
        raise DataError("wrong root element", source=source, field="root", value=root.tag,
                        expected=f"<{root_tag}>")
    return root


def _need(value: T | None, source: str, field: str, expected: str) -> T:
    if value is None:
        raise DataError("missing element", source=source, field=field, expected=expected)
    return value


def _vector(root: ET.Element, tag: str, keys: Sequence[str],
            source: str) -> tuple[float, ...] | None:
    el = root.find(tag)
    if el is None:
        return None
    out = []
    for k in keys:
        text = el.get(k)
        try:
            out.append(float(text))  # type: ignore[arg-type]
        except (TypeError, ValueError) as e:
            raise DataError("missing or not a number", source=source, field=f"{tag}.{k}",
                            value=text, expected="a decimal number") from e
    return tuple(out)


def _integer(root: ET.Element, tag: str, source: str, attr: str | None = None) -> int | None:
    el = root.find(tag)
    text = None if el is None else (el.text if attr is None else el.get(attr))
    if text is None:
        return None
    try:
        return int(text.strip())
    except ValueError as e:
        raise DataError("not an integer", source=source, field=tag, value=text,
                        expected="a decimal integer") from e


def _attrs(keys: Sequence[str], values: Sequence[float], precision: int) -> str:
    return " ".join(f'{k}="{v:.{precision}f}"' for k, v in zip(keys, values, strict=True))


def _check_count(source: str, field: str, values: Sequence[float] | None, n: int) -> None:
    if values is not None and len(values) != n:
        raise DataError("wrong number of values", source=source, field=field,
                        value=len(values), expected=f"{n} values")


@dataclass(frozen=True)
class RobotMessage:
    """The robot's ``<Rob>`` document of one RSI cycle.

    Attributes:
        ipoc: Time stamp [ms]; the answer must carry the same value.
        axis_actual: ``AIPos``, axes A1-A6 actual [deg].
        axis_setpoint: ``ASPos``, axes A1-A6 setpoint [deg] (None if not configured).
        cart_actual: ``RIst``, TCP X Y Z [mm] A B C [deg] (None if not configured).
        cart_setpoint: ``RSol``, TCP setpoint (None if not configured).
        delay: ``Delay D``, late answers counted so far (None if not configured).
        gear_torque: ``GearTorque`` A1-A6 [N·m] (None if not configured).
        digital_inputs: ``DiL``, a word of digital inputs (None if not configured).
        robot_type: The ``TYPE`` attribute of ``<Rob>``.
    """

    ipoc: int
    axis_actual: tuple[float, ...]
    axis_setpoint: tuple[float, ...] | None = None
    cart_actual: tuple[float, ...] | None = None
    cart_setpoint: tuple[float, ...] | None = None
    delay: int | None = None
    gear_torque: tuple[float, ...] | None = None
    digital_inputs: int | None = None
    robot_type: str = "KUKA"

    def encode(self, precision: int = 4) -> bytes:
        """The document as the robot sends it (no whitespace between elements).

        Args:
            precision: Decimals of every number (the ETHERNET object's ``Precision``).

        Raises:
            DataError: A vector has the wrong length.
        """
        src = "RSI <Rob> message"
        _check_count(src, "AIPos", self.axis_actual, 6)
        parts = [f'<Rob TYPE="{self.robot_type}">']
        for tag, keys, values in (("RIst", CARTESIAN, self.cart_actual),
                                  ("RSol", CARTESIAN, self.cart_setpoint),
                                  ("AIPos", AXES, self.axis_actual),
                                  ("ASPos", AXES, self.axis_setpoint)):
            if values is not None:
                _check_count(src, tag, values, 6)
                parts.append(f"<{tag} {_attrs(keys, values, precision)} />")
        if self.delay is not None:
            parts.append(f'<Delay D="{self.delay}" />')
        if self.gear_torque is not None:
            _check_count(src, "GearTorque", self.gear_torque, 6)
            parts.append(f"<GearTorque {_attrs(AXES, self.gear_torque, precision)} />")
        if self.digital_inputs is not None:
            parts.append(f"<DiL>{self.digital_inputs}</DiL>")
        parts.append(f"<IPOC>{self.ipoc}</IPOC></Rob>")
        return "".join(parts).encode("ascii")

    @classmethod
    def decode(cls, data: bytes | str) -> RobotMessage:
        """Parse a ``<Rob>`` document (elements in any order, whitespace allowed).

        Numbers are kept as sent, NaN included: the receiver judges them.

        Raises:
            DataError: Not XML, not ``<Rob>``, or ``AIPos`` / ``IPOC`` missing or malformed.
        """
        src = "RSI <Rob> message"
        root = _parse(data, "Rob", src)
        return cls(
            ipoc=_need(_integer(root, "IPOC", src), src, "IPOC", "<IPOC>integer</IPOC>"),
            axis_actual=_need(_vector(root, "AIPos", AXES, src), src, "AIPos",
                              "<AIPos A1=.. A6=../>"),
            axis_setpoint=_vector(root, "ASPos", AXES, src),
            cart_actual=_vector(root, "RIst", CARTESIAN, src),
            cart_setpoint=_vector(root, "RSol", CARTESIAN, src),
            delay=_integer(root, "Delay", src, attr="D"),
            gear_torque=_vector(root, "GearTorque", AXES, src),
            digital_inputs=_integer(root, "DiL", src),
            robot_type=root.get("TYPE", root.get("Type", "")))


@dataclass(frozen=True)
class SensorMessage:
    """The sensor PC's ``<Sen>`` answer.

    Attributes:
        ipoc: The IPOC of the ``<Rob>`` document answered.
        correction: ``AK`` A1-A6 axis corrections [deg], finite.
        sentype: The ``Type`` attribute (the configuration's ``SENTYPE``).
        stop: ``<Stop>1</Stop>``: the session's last answer (RSI_MOVECORR ends).
    """

    ipoc: int
    correction: tuple[float, ...]
    sentype: str = "ImFree"
    stop: bool = False

    def encode(self, precision: int = 4) -> bytes:
        """The document as sent (no whitespace between elements).

        Raises:
            DataError: Not 6 corrections, a non-finite correction, or a negative IPOC
                (nothing is sent).
        """
        src = "RSI <Sen> message"
        _check_count(src, "AK", self.correction, 6)
        for k, v in zip(AXES, self.correction, strict=True):
            if not math.isfinite(v):
                raise DataError("not finite", source=src, field=f"AK.{k}", value=v,
                                expected="a finite correction [deg]")
        if self.ipoc < 0:
            raise DataError("negative", source=src, field="IPOC", value=self.ipoc,
                            expected=">= 0")
        stop = "<Stop>1</Stop>" if self.stop else ""
        return (f'<Sen Type="{self.sentype}"><AK {_attrs(AXES, self.correction, precision)}'
                f" />{stop}<IPOC>{self.ipoc}</IPOC></Sen>").encode("ascii")

    @classmethod
    def decode(cls, data: bytes | str) -> SensorMessage:
        """Parse a ``<Sen>`` document; non-finite corrections are kept (the robot judges).

        Raises:
            DataError: Not XML, not ``<Sen>``, or ``AK`` / ``IPOC`` missing or malformed.
        """
        src = "RSI <Sen> message"
        root = _parse(data, "Sen", src)
        return cls(
            ipoc=_need(_integer(root, "IPOC", src), src, "IPOC", "<IPOC>integer</IPOC>"),
            correction=_need(_vector(root, "AK", AXES, src), src, "AK", "<AK A1=.. A6=../>"),
            sentype=root.get("Type", ""), stop=bool(_integer(root, "Stop", src)))
