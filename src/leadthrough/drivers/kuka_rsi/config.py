"""The robot-side RSI configuration leadthrough ships, and parsers for it.

Three files in ``leadthrough/drivers/kuka_rsi/data/`` go to the controller:

* ``leadthrough_rsi_ethernet.xml``: the ETHERNET object's configuration (the PC's address
  and port, ``SENTYPE``, the ``<SEND>`` and ``<RECEIVE>`` element lists), parsed by
  :class:`EthernetConfig`;
* ``leadthrough_rsi.rsix``: the RSI context (ETHERNET, AXISCORR, AXISCORRMON, GEARTORQUE,
  DIGIN), whose limits and timeout :class:`RsiContext` reads;
* ``leadthrough_rsi.src``: the KRL program that loads the context and runs
  ``RSI_ON(#ABSOLUTE)`` / ``RSI_MOVECORR()``.

The emulated robot (:mod:`leadthrough.sim.emulators.kuka_rsi`) reads the same two files, so
what it sends, its correction limits and its late-packet tolerance are those of the shipped
configuration. Sources: see :mod:`leadthrough.drivers.kuka_rsi.messages`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from leadthrough.errors import DataError

__all__ = ["SHIPPED_FILES", "EthernetConfig", "RsiContext", "RsiElement", "shipped_file"]

SHIPPED_FILES = ("leadthrough_rsi_ethernet.xml", "leadthrough_rsi.rsix", "leadthrough_rsi.src")


def shipped_file(name: str) -> Path:
    """Path of a shipped controller file (one of :data:`SHIPPED_FILES`).

    Raises:
        DataError: Unknown name.
    """
    if name not in SHIPPED_FILES:
        raise DataError("no such shipped file", field="name", value=name,
                        expected="one of " + ", ".join(SHIPPED_FILES))
    return Path(str(resources.files("leadthrough.drivers.kuka_rsi") / "data" / name))


def _xml(text: str, source: str) -> ET.Element:
    try:
        return ET.fromstring(text)
    except ET.ParseError as e:
        raise DataError(f"not well-formed XML: {e}", source=source) from e


@dataclass(frozen=True)
class RsiElement:
    """One ``<ELEMENT>`` of a SEND or RECEIVE list.

    Attributes:
        tag: ``TAG``, e.g. ``DEF_AIPos`` or ``AK.A1``.
        type: ``TYPE``: BOOL, STRING, LONG or DOUBLE.
        index: ``INDX``: ETHERNET channel 1-64, or 0 for ``INTERNAL``.
        hold_on: ``HOLDON="1"``: keep the last value when an answer is late.
    """

    tag: str
    type: str
    index: int
    hold_on: bool


@dataclass(frozen=True)
class EthernetConfig:
    """An RSI Ethernet configuration file.

    Attributes:
        ip: ``IP_NUMBER``, the sensor PC's address.
        port: ``PORT``, the UDP port the sensor PC listens on.
        sentype: ``SENTYPE``, the ``Type`` of the ``<Sen>`` answers.
        only_send: ``ONLYSEND``: the robot does not wait for answers.
        send: The ``<SEND>`` elements (robot → PC).
        receive: The ``<RECEIVE>`` elements (PC → robot).
    """

    ip: str
    port: int
    sentype: str
    only_send: bool
    send: tuple[RsiElement, ...]
    receive: tuple[RsiElement, ...]

    @property
    def send_tags(self) -> frozenset[str]:
        """Tags of the SEND list."""
        return frozenset(e.tag for e in self.send)

    @classmethod
    def parse(cls, text: str, source: str = "RSI Ethernet configuration") -> EthernetConfig:
        """Parse the XML text of an Ethernet configuration.

        Raises:
            DataError: Malformed XML, a missing CONFIG entry, a port outside 1..65535 or an
                element without TAG / TYPE / INDX.
        """
        root = _xml(text, source)

        def config(key: str) -> str:
            el = root.find(f"CONFIG/{key}")
            if el is None or not (el.text or "").strip():
                raise DataError("missing entry", source=source, field=f"CONFIG/{key}",
                                expected="a value")
            return (el.text or "").strip()

        try:
            port = int(config("PORT"))
        except ValueError as e:
            raise DataError("not an integer", source=source, field="CONFIG/PORT",
                            value=config("PORT"), expected="1..65535") from e
        if not 1 <= port <= 65535:
            raise DataError("out of range", source=source, field="CONFIG/PORT", value=port,
                            expected="1..65535")
        return cls(ip=config("IP_NUMBER"), port=port, sentype=config("SENTYPE"),
                   only_send=config("ONLYSEND").upper() == "TRUE",
                   send=_elements(root, "SEND", source),
                   receive=_elements(root, "RECEIVE", source))

    @classmethod
    def shipped(cls) -> EthernetConfig:
        """The configuration leadthrough ships (``leadthrough_rsi_ethernet.xml``)."""
        path = shipped_file("leadthrough_rsi_ethernet.xml")
        return cls.parse(path.read_text(encoding="utf-8"), source=str(path))


def _elements(root: ET.Element, section: str, source: str) -> tuple[RsiElement, ...]:
    out = []
    for el in root.findall(f"{section}/ELEMENTS/ELEMENT"):
        tag, typ, indx = el.get("TAG"), el.get("TYPE"), el.get("INDX")
        if not tag or typ not in ("BOOL", "STRING", "LONG", "DOUBLE") or indx is None:
            raise DataError("incomplete element", source=source, field=f"{section}/ELEMENT",
                            value=(tag, typ, indx),
                            expected="TAG, TYPE in BOOL/STRING/LONG/DOUBLE and INDX")
        index = 0 if indx == "INTERNAL" else int(indx)
        out.append(RsiElement(tag, typ, index, el.get("HOLDON") == "1"))
    return tuple(out)


_NS = {"ctx": "RsiContext", "drv": "RsiDriver"}


@dataclass(frozen=True)
class RsiContext:
    """What the emulated robot needs from an RSI context (``.rsix``).

    Attributes:
        timeout: ETHERNET ``Timeout``: late answers in a row before RSI stops.
        precision: ETHERNET ``Precision``: decimals of the numbers sent.
        lower: AXISCORR ``LowerLimA1..A6`` [deg] from the start position.
        upper: AXISCORR ``UpperLimA1..A6`` [deg].
        max_correction: AXISCORRMON ``MaxA1..A6`` [deg]: a larger correction stops RSI.
    """

    timeout: int
    precision: int
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    max_correction: tuple[float, ...]

    @classmethod
    def parse(cls, text: str, source: str = "RSI context") -> RsiContext:
        """Parse an ``.rsix`` context.

        Raises:
            DataError: Malformed XML or a missing object / parameter.
        """
        root = _xml(text, source)
        params: dict[str, dict[str, str]] = {}
        for obj in root.iterfind("drv:RsiObjects/drv:RsiObject", _NS):
            kind = obj.get("ObjType", "")
            params[kind] = {p.get("Name", ""): p.get("ParamValue", "")
                            for p in obj.iterfind("drv:Parameters/drv:Parameter", _NS)}

        def value(kind: str, name: str) -> float:
            try:
                return float(params[kind][name])
            except (KeyError, ValueError) as e:
                raise DataError("missing or not a number", source=source,
                                field=f"{kind}.{name}", value=params.get(kind, {}).get(name),
                                expected="a number") from e

        axes = range(1, 7)
        return cls(timeout=int(value("Ethernet", "Timeout")),
                   precision=int(value("Ethernet", "Precision")),
                   lower=tuple(value("AxisCorr", f"LowerLimA{i}") for i in axes),
                   upper=tuple(value("AxisCorr", f"UpperLimA{i}") for i in axes),
                   max_correction=tuple(value("AxisCorrMon", f"MaxA{i}") for i in axes))

    @classmethod
    def shipped(cls) -> RsiContext:
        """The context leadthrough ships (``leadthrough_rsi.rsix``)."""
        path = shipped_file("leadthrough_rsi.rsix")
        return cls.parse(path.read_text(encoding="utf-8"), source=str(path))
