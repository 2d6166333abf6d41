"""The link between the loop's process and its session writer process: messages, and the
shared memory of the recording's chunks.

The loop's process fills a chunk (:class:`~leadthrough.session.recorder.RecordChunk`) whose
arrays live in memory both processes map: an anonymous memory file (Linux ``memfd_create(2)``;
elsewhere an unlinked temporary file), passed to the writer as a file descriptor
(``SCM_RIGHTS`` over a Unix socket, ``unix(7)``; Python's ``socket.send_fds``). A full chunk is
then handed over by its index alone, and nothing of it is copied or converted in the loop's
process. No shared memory name exists, so nothing is left in ``/dev/shm`` whichever process
dies first: the kernel frees a chunk when its last mapping and descriptor are gone.

A message is one pickled tuple behind an 8-byte big-endian length, on a ``SOCK_STREAM`` Unix
socket pair; descriptors ride on the length's bytes. Only the standard library is imported
here: the writer process loads this module before it lowers its priority.
"""

from __future__ import annotations

import mmap
import os
import pickle
import selectors
import socket
import struct
import tempfile
from typing import Any

__all__ = ["SIDECAR_SUFFIX", "MessageReader", "open_chunk_memory", "recv_message",
           "send_message"]

#: Appended to the partial session file's name for its sidecar of metadata and events.
SIDECAR_SUFFIX = ".jsonl"

_HEADER = struct.Struct("!Q")
#: Descriptors one message can carry.
MAX_FDS = 4


def open_chunk_memory(nbytes: int) -> tuple[int, mmap.mmap]:
    """A new shared memory region of ``nbytes`` bytes (zeros): its descriptor and its mapping
    in this process. The caller closes both (the region lives while either is open here or in
    another process)."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("leadthrough-chunk", os.MFD_CLOEXEC)
    else:       # not Linux: an unlinked temporary file
        fd, name = tempfile.mkstemp(prefix="leadthrough-chunk-")
        os.unlink(name)
    try:
        os.ftruncate(fd, max(nbytes, 1))
        return fd, mmap.mmap(fd, max(nbytes, 1))
    except OSError:
        os.close(fd)
        raise


def send_message(sock: socket.socket, message: tuple[Any, ...], fds: tuple[int, ...] = ()
                 ) -> None:
    """Send ``message`` (and pass ``fds`` with it) on ``sock``. On a non-blocking socket a
    message that does not fit in the send buffer raises ``BlockingIOError`` with part of it
    sent: the link is then unusable (the loop's side sends only short messages there, and
    the few it has in flight fit many times over).

    Raises:
        OSError: The socket is closed or broken (the other process is gone), or full.
    """
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    header = _HEADER.pack(len(data))
    if fds:
        sent = socket.send_fds(sock, [header], list(fds))
        sock.sendall(header[sent:] + data)
    else:
        sock.sendall(header + data)


def recv_message(sock: socket.socket) -> tuple[tuple[Any, ...], list[int]] | None:
    """The next message on a blocking ``sock`` and the descriptors passed with it; None when
    the other process has closed its end.

    Raises:
        OSError: A broken socket, or a timeout the socket was given.
    """
    header = b""
    fds: list[int] = []
    while len(header) < _HEADER.size:
        data, got, _, _ = socket.recv_fds(sock, _HEADER.size - len(header), MAX_FDS)
        if not data:
            return None
        header += data
        fds.extend(got)
    size = _HEADER.unpack(header)[0]
    body = bytearray(size)
    view = memoryview(body)
    while view:
        n = sock.recv_into(view)
        if n == 0:
            return None
        view = view[n:]
    return pickle.loads(body), fds


class MessageReader:
    """Reads the messages waiting on a non-blocking socket without waiting for more (the loop's
    side: it must never block on the writer). Messages carry no descriptors this way.

    Args:
        sock: The socket, set non-blocking by the reader.
    """

    def __init__(self, sock: socket.socket) -> None:
        sock.setblocking(False)
        self._sock = sock
        self._buffer = bytearray()
        #: The other process closed its end.
        self.closed = False

    def wait(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for something to read (off the loop only); whether there
        is."""
        with selectors.DefaultSelector() as selector:
            selector.register(self._sock, selectors.EVENT_READ)
            return bool(selector.select(timeout_s))

    def poll(self) -> list[tuple[Any, ...]]:
        """The complete messages received so far (none when nothing is waiting)."""
        while not self.closed:
            try:
                data = self._sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.closed = True
                break
            if not data:
                self.closed = True
                break
            self._buffer += data
        out = []
        while len(self._buffer) >= _HEADER.size:
            size = _HEADER.unpack_from(self._buffer)[0]
            end = _HEADER.size + size
            if len(self._buffer) < end:
                break
            out.append(pickle.loads(self._buffer[_HEADER.size:end]))
            del self._buffer[:end]
        return out
