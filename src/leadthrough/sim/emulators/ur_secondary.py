"""The secondary interface of the emulated UR controller: it receives URScript programs.

A UR controller runs the URScript it receives on its secondary interface (TCP 30002). The
emulator only runs leadthrough's servo program (:mod:`leadthrough.drivers.ur_rtde.script`),
whose behaviour it models; :class:`ScriptListener` accepts connections, collects each one's
text until the sender closes it, and hands back the parameters of a servo program it finds
(:class:`ReceivedProgram`). Any other text is counted and ignored.
"""

from __future__ import annotations

import re
import socket
from dataclasses import dataclass

__all__ = ["ReceivedProgram", "ScriptListener"]

_PARAM = re.compile(r"^\s*(PERIOD|WATCHDOG_TIMEOUT|REG)\s*=\s*([0-9.eE+-]+)\s*$", re.MULTILINE)


@dataclass(frozen=True)
class ReceivedProgram:
    """The parameters of a received servo program.

    Attributes:
        period: ``PERIOD`` [s].
        watchdog_timeout: ``WATCHDOG_TIMEOUT`` [s].
        register_offset: ``REG``.
    """

    period: float
    watchdog_timeout: float
    register_offset: int

    @classmethod
    def parse(cls, text: str) -> ReceivedProgram | None:
        """The servo program's parameters, or None if ``text`` is not that program."""
        if "def leadthrough_servo():" not in text:
            return None
        values = dict(_PARAM.findall(text))
        try:
            return cls(float(values["PERIOD"]), float(values["WATCHDOG_TIMEOUT"]),
                       int(values["REG"]))
        except (KeyError, ValueError):
            return None


class ScriptListener:
    """Non-blocking TCP listener of the secondary interface.

    Args:
        host: Address to listen on.
        port: Port (0: any free port).
    """

    def __init__(self, host: str, port: int) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(4)
        sock.setblocking(False)
        self._sock: socket.socket | None = sock
        self._conns: list[tuple[socket.socket, bytearray]] = []
        self.ignored = 0

    @property
    def port(self) -> int:
        """The listening port (0 once closed)."""
        return int(self._sock.getsockname()[1]) if self._sock is not None else 0

    def poll(self) -> list[ReceivedProgram]:
        """Accept, read, and return the servo programs whose senders finished."""
        while self._sock is not None:
            try:
                conn, _ = self._sock.accept()
            except BlockingIOError:
                break
            conn.setblocking(False)
            self._conns.append((conn, bytearray()))
        done: list[ReceivedProgram] = []
        keep = []
        for conn, buf in self._conns:
            if self._read(conn, buf):
                keep.append((conn, buf))
                continue
            conn.close()
            program = ReceivedProgram.parse(buf.decode("utf-8", errors="replace"))
            if program is None:
                self.ignored += 1
            else:
                done.append(program)
        self._conns = keep
        return done

    @staticmethod
    def _read(conn: socket.socket, buf: bytearray) -> bool:
        """Read what arrived; False once the sender closed (or the connection broke)."""
        while True:
            try:
                data = conn.recv(65536)
            except BlockingIOError:
                return True
            except OSError:
                return False
            if not data:
                return False
            buf.extend(data)

    def close(self) -> None:
        """Close the listener and every connection."""
        for conn, _ in self._conns:
            conn.close()
        self._conns.clear()
        if self._sock is not None:
            self._sock.close()
            self._sock = None
