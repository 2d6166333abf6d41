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

Parsing: a document is parsed by expat with handlers that refuse at once what RSI never
sends: a ``DOCTYPE`` (so no entity is ever declared: a billion-laughs document costs
microseconds, not the tens of milliseconds of expanding it), processing instructions, elements
nested below the root's children, a child element twice (a duplicated ``<AIPos>`` is not
silently the first one), more than :data:`MAX_ELEMENTS` elements, attribute values or texts over
:data:`MAX_TEXT` characters, non-ASCII bytes and documents over :data:`MAX_DOCUMENT_BYTES`. Numbers
are ASCII decimals (or the ``nan`` / ``inf`` tokens, kept for the receiver to judge); ``IPOC`` has
at most :data:`IPOC_DIGITS` digits and fits a uint64, ``Delay D`` an int32, ``DiL`` the shipped
configuration's 16 inputs. A refusal is a :class:`~leadthrough.drivers.wire.PacketError` with its
:class:`~leadthrough.drivers.wire.BadPacket` code.

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
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar
from xml.parsers import expat

from leadthrough.drivers.wire import BadPacket, PacketError
from leadthrough.errors import DataError

__all__ = ["AXES", "CARTESIAN", "DIL_BITS", "IPOC_DIGITS", "MAX_DOCUMENT_BYTES",
           "RobotMessage", "SensorMessage"]

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
CARTESIAN = ("X", "Y", "Z", "A", "B", "C")
T = TypeVar("T")

#: A document longer than this is refused unparsed [bytes] (ours are about 600; FZI's full
#: ``<Rob>`` document with every optional element about 1 200).
MAX_DOCUMENT_BYTES = 4096
#: Elements in one document at most (the root included).
MAX_ELEMENTS = 48
#: Characters of one attribute value or element text at most.
MAX_TEXT = 40
#: Digits of an IPOC at most (a uint64 has 20).
IPOC_DIGITS = 20
#: IPOC at most (uint64).
MAX_IPOC = (1 << 64) - 1
#: Width of ``DiL`` [bits]: the shipped configuration's DIGIN word, ``$IN[1..16]``.
DIL_BITS = 16
#: ``Delay D`` at most: a KRL LONG (int32).
MAX_DELAY = (1 << 31) - 1

# a decimal number as a KRL REAL is written (ASCII digits, optional exponent), or the tokens
# a non-finite value prints as (kept: the receiver judges them)
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d{1,3})?|nan|[+-]?inf",
                     re.ASCII)
_WHITESPACE = " \t\r\n"


@dataclass
class _Element:
    tag: str
    attrs: dict[str, str]
    text: list[str] = field(default_factory=list)


@dataclass
class _Document:
    """A parsed RSI document: the root's attributes and its child elements by tag (RSI
    documents are flat: one level of elements under the root, each at most once)."""

    tag: str
    attrs: dict[str, str]
    children: dict[str, _Element]

    def get(self, key: str, default: str = "") -> str:
        return self.attrs.get(key, default)


def _refuse(code: BadPacket, message: str, source: str, field: str, value: object = None,
            expected: str | None = None) -> PacketError:
    return PacketError(message, code=code, source=source, field=field, value=value,
                       expected=expected)


class _Reader:
    """expat's handlers for one RSI document (see :func:`_parse`): the root, its children,
    and a refusal at the first thing RSI never sends."""

    def __init__(self, root_tag: str, source: str) -> None:
        self.root_tag, self.source = root_tag, source
        self.root: list[_Document] = []
        self.stack: list[_Element | None] = []
        self.count = 0

    def start(self, tag: str, attrs: dict[str, str]) -> None:
        self.count += 1
        if self.count > MAX_ELEMENTS:
            raise _refuse(BadPacket.STRUCTURE, "too many elements", self.source, "document",
                          self.count, f"<= {MAX_ELEMENTS} elements")
        for k, v in attrs.items():
            if len(v) > MAX_TEXT:
                raise _refuse(BadPacket.FIELD, "attribute value too long", self.source,
                              f"{tag}.{k}", v[:MAX_TEXT], f"<= {MAX_TEXT} characters")
        depth = len(self.stack)
        if depth == 0:  # a wrong root is refused once the document is known well-formed
            self.root.append(_Document(tag, dict(attrs), {}))
            self.stack.append(None)
        elif depth == 1:
            children = self.root[0].children
            if tag in children:
                raise _refuse(BadPacket.STRUCTURE, "element given twice", self.source, tag,
                              None, f"at most one <{tag}>")
            children[tag] = el = _Element(tag, dict(attrs))
            self.stack.append(el)
        else:
            raise _refuse(BadPacket.STRUCTURE, "nested element", self.source, tag, None,
                          f"elements only directly under <{self.root_tag}>")

    def end(self, tag: str) -> None:
        self.stack.pop()

    def text(self, chars: str) -> None:
        el = self.stack[-1] if self.stack else None
        if el is None:
            if chars.strip(_WHITESPACE):
                raise _refuse(BadPacket.STRUCTURE, "text outside an element", self.source,
                              self.root_tag, chars[:MAX_TEXT], "elements only")
            return
        el.text.append(chars)
        if sum(len(t) for t in el.text) > MAX_TEXT:
            raise _refuse(BadPacket.FIELD, "text too long", self.source, el.tag,
                          chars[:MAX_TEXT], f"<= {MAX_TEXT} characters")

    def doctype(self, *_: object) -> None:
        raise _refuse(BadPacket.FORBIDDEN, "DOCTYPE refused", self.source, "DOCTYPE", None,
                      "no DTD (RSI documents have none; entities are refused)")

    def entity(self, *_: object) -> None:
        raise _refuse(BadPacket.FORBIDDEN, "entity declaration refused", self.source,
                      "ENTITY", None, "no entities")

    def instruction(self, target: str, _data: str) -> None:
        raise _refuse(BadPacket.FORBIDDEN, "processing instruction refused", self.source,
                      target, None, "no processing instructions")

    def parser(self) -> Any:
        """An expat parser with these handlers."""
        parser = expat.ParserCreate()
        parser.StartDoctypeDeclHandler = self.doctype
        parser.EntityDeclHandler = self.entity
        parser.UnparsedEntityDeclHandler = self.entity
        parser.ExternalEntityRefHandler = self.entity  # type: ignore[assignment]
        parser.ProcessingInstructionHandler = self.instruction
        parser.StartElementHandler = self.start
        parser.EndElementHandler = self.end
        parser.CharacterDataHandler = self.text
        return parser


def _parse(data: bytes | str, root_tag: str, source: str) -> _Document:
    """Parse an RSI document with expat, refusing at once what RSI never sends: a DOCTYPE
    (and so every entity declaration: no billion laughs, no external entity), processing
    instructions, elements nested below the root's children, a child element twice, more
    than :data:`MAX_ELEMENTS` elements, texts or attribute values over :data:`MAX_TEXT`
    characters, non-ASCII bytes, and documents over :data:`MAX_DOCUMENT_BYTES`.

    Raises:
        PacketError: Naming the code, the field and what was expected.
    """
    raw = data.encode("utf-8", "replace") if isinstance(data, str) else bytes(data)
    if len(raw) > MAX_DOCUMENT_BYTES:
        raise _refuse(BadPacket.SIZE, "document too long", source, "length", len(raw),
                      f"<= {MAX_DOCUMENT_BYTES} bytes")
    if not raw.isascii():
        raise _refuse(BadPacket.SYNTAX, "not ASCII", source, "document", raw[:40],
                      "an ASCII document (RSI writes tags and numbers in ASCII)")
    reader = _Reader(root_tag, source)
    try:
        reader.parser().Parse(raw, True)
    except expat.ExpatError as e:
        raise _refuse(BadPacket.SYNTAX, f"not well-formed XML: {e}", source, "document",
                      raw[:60], f"a <{root_tag}> document") from None
    except RecursionError:  # not reachable with the depth limit; kept typed all the same
        raise _refuse(BadPacket.STRUCTURE, "too deep", source, "document", None,
                      "a flat document") from None
    if not reader.root:
        raise _refuse(BadPacket.SYNTAX, "no root element", source, "document", raw[:60],
                      f"a <{root_tag}> document")
    if reader.root[0].tag != root_tag:
        raise _refuse(BadPacket.STRUCTURE, "wrong root element", source, "root",
                      reader.root[0].tag, f"<{root_tag}>")
    return reader.root[0]


def _need(value: T | None, source: str, field: str, expected: str) -> T:
    if value is None:
        raise _refuse(BadPacket.STRUCTURE, "missing element", source, field, None, expected)
    return value


def _vector(root: _Document, tag: str, keys: Sequence[str],
            source: str) -> tuple[float, ...] | None:
    el = root.children.get(tag)
    if el is None:
        return None
    extra = el.attrs.keys() - set(keys)
    if extra:
        raise _refuse(BadPacket.STRUCTURE, "unknown attribute", source,
                      f"{tag}.{sorted(extra)[0]}", None, "attributes " + " ".join(keys))
    out = []
    for k in keys:
        text = el.attrs.get(k)
        if text is None or not _NUMBER.fullmatch(text.strip(_WHITESPACE)):
            raise _refuse(BadPacket.FIELD, "missing or not a number", source, f"{tag}.{k}",
                          text, "a decimal number")
        out.append(float(text))
    return tuple(out)


def _integer(root: _Document, tag: str, source: str, maximum: int, digits: int,
             attr: str | None = None) -> int | None:
    el = root.children.get(tag)
    if el is None:
        return None
    text = "".join(el.text) if attr is None else el.attrs.get(attr)
    if text is None:
        return None
    body = text.strip(_WHITESPACE)
    if not (0 < len(body) <= digits and body.isascii() and body.isdigit()):
        raise _refuse(BadPacket.FIELD, "not an integer in range", source, tag,
                      text[:MAX_TEXT], f"a decimal integer 0..{maximum}")
    value = int(body)
    if value > maximum:
        raise _refuse(BadPacket.FIELD, "not an integer in range", source, tag,
                      text[:MAX_TEXT], f"a decimal integer 0..{maximum}")
    return value


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

        Numbers are kept as sent, NaN included: the receiver judges them. The grammar is
        strict (module doc, "Parsing").

        Raises:
            PacketError: A :class:`~leadthrough.errors.DataError` with its
                :class:`~leadthrough.drivers.wire.BadPacket` code: not XML, a DTD, not
                ``<Rob>``, an element twice, ``AIPos`` / ``IPOC`` missing, a field outside its
                grammar (``IPOC`` over :data:`IPOC_DIGITS` digits, ``DiL`` over
                :data:`DIL_BITS` bits, ``Delay`` over int32).
        """
        src = "RSI <Rob> message"
        root = _parse(data, "Rob", src)
        return cls(
            ipoc=_need(_integer(root, "IPOC", src, MAX_IPOC, IPOC_DIGITS), src, "IPOC",
                       "<IPOC>integer</IPOC>"),
            axis_actual=_need(_vector(root, "AIPos", AXES, src), src, "AIPos",
                              "<AIPos A1=.. A6=../>"),
            axis_setpoint=_vector(root, "ASPos", AXES, src),
            cart_actual=_vector(root, "RIst", CARTESIAN, src),
            cart_setpoint=_vector(root, "RSol", CARTESIAN, src),
            delay=_integer(root, "Delay", src, MAX_DELAY, 10, attr="D"),
            gear_torque=_vector(root, "GearTorque", AXES, src),
            digital_inputs=_integer(root, "DiL", src, (1 << DIL_BITS) - 1, 5),
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
            PacketError: Not XML, not ``<Sen>``, or ``AK`` / ``IPOC`` missing or malformed
                (the grammar of :meth:`RobotMessage.decode`; ``Stop`` 0 or 1).
        """
        src = "RSI <Sen> message"
        root = _parse(data, "Sen", src)
        return cls(
            ipoc=_need(_integer(root, "IPOC", src, MAX_IPOC, IPOC_DIGITS), src, "IPOC",
                       "<IPOC>integer</IPOC>"),
            correction=_need(_vector(root, "AK", AXES, src), src, "AK", "<AK A1=.. A6=../>"),
            sentype=root.get("Type", ""), stop=bool(_integer(root, "Stop", src, 1, 1)))
