"""Who may reach the pendant's page: a secret token in the URL, the served address's own Host
and Origin, a few pages at once, small messages.

The pendant's page can move the robot, so its web server answers only requests that carry the
run's token as the first segment of the path (``http://127.0.0.1:8080/<token>/``, printed on
the terminal, as Jupyter's token), name the served address in their ``Host`` header (a page
reached through a DNS-rebinding name is refused) and, when they carry an ``Origin`` header,
come from that same address (a WebSocket opened by another site's page in the operator's
browser is refused: cross-site WebSocket hijacking). Every other request, HTTP or WebSocket,
is answered ``403 Forbidden`` before the page's server allocates anything for it, and logged
(one line each, rate-limited: a flood of refusals cannot fill the log). At most
``max_clients`` pages are connected at once (a further WebSocket is answered ``503``), and a
message from a page larger than ``max_message_bytes`` closes that page's connection only.

viser (the page's server) has no hook for any of this: :func:`serve_gated` constructs the
:class:`viser.ViserServer` while ``websockets.asyncio.server.serve`` — which viser calls from
its own thread, once per port it tries, before its constructor returns — is wrapped so that
the gate's :meth:`Gate.process_request` runs first and the message-size limit is the gate's.
The original is restored as soon as the constructor returns. The gate strips the token from
the path and hands the request on to viser's own file server.

What this does not do: the page is served over plain http, so anyone who can read the traffic
(on a network: anyone on its path) can read the token; the token also stays in the browser's
history. Serving anywhere but this machine (``allow_remote``) is the operator's decision.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gzip
import hmac
import http
import ipaddress
import logging
import re
import secrets
import socket
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from leadthrough.errors import DataError

__all__ = [
    "DEFAULT_MAX_CLIENTS",
    "MAX_CLIENTS_LIMIT",
    "MAX_MESSAGE_BYTES",
    "PAGE_GUARD",
    "TOKEN_MAX_CHARS",
    "TOKEN_MIN_CHARS",
    "Gate",
    "check_token",
    "is_loopback",
    "new_token",
    "read_token_file",
    "serve_gated",
]

#: Pages connected at once without ``max_clients``.
DEFAULT_MAX_CLIENTS = 4
#: Most pages connected at once that may be asked for.
MAX_CLIENTS_LIMIT = 16
#: Largest message a page may send [bytes]. viser's client sends small msgpack messages (a
#: camera update, a button click, a gizmo drag, a text field's value: well under 4 kB each);
#: viser itself allows 50 MB (for rendered images and file uploads, which the pendant does
#: not use).
MAX_MESSAGE_BYTES = 256 * 1024
#: Characters of a token, fewest and most (a generated one has 43: 32 random bytes).
TOKEN_MIN_CHARS = 32
TOKEN_MAX_CHARS = 128
#: The hold-to-run script the page runs, injected into the page's ``<head>`` when it exists.
PAGE_GUARD = Path(__file__).resolve().parent / "page_guard.js"

_TOKEN_CHARS = re.compile(r"[A-Za-z0-9_-]+")
_TOKEN_EXPECTED = (f"one line of {TOKEN_MIN_CHARS}-{TOKEN_MAX_CHARS} characters from "
                   "A-Z a-z 0-9 _ - (e.g. python -c 'import secrets; "
                   "print(secrets.token_urlsafe(32))')")
_LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
#: Headers of every page the gate lets through: the token must not leak through a Referer;
#: no other site may frame the page; nothing cached (the page's URL holds the token).
_SAFE_HEADERS = {
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-store",
}
#: The page's Content-Security-Policy (``{host}``: the request's checked Host). viser's page
#: is one inline script that decompresses its bundle with WebAssembly and runs it as a created
#: inline module, and the bundle evaluates a string as code once (Chromium reports it), so
#: scripts need 'unsafe-inline', 'unsafe-eval' and 'wasm-unsafe-eval': the policy does not
#: stop a script injected into the page. What it forbids: connections to anywhere but the
#: page's own server (``ws://{host}`` named too: older Safari does not match it to 'self'),
#: being framed by another page, forms, plugins and a changed base URL.
_CSP = ("default-src 'self'; "
        "script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval'; "
        "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
        "font-src 'self' data:; worker-src 'self' blob:; "
        "connect-src 'self' ws://{host} data: blob:; "
        "frame-ancestors 'none'; base-uri 'none'; form-action 'none'; object-src 'none'")

_log = logging.getLogger("leadthrough.pendant.access")


def new_token() -> str:
    """A new random token (32 bytes from :mod:`secrets`, URL-safe: 43 characters)."""
    return secrets.token_urlsafe(32)


def check_token(value: str, *, source: str | Path | None = None,
                field: str = "token") -> str:
    """A token: ``TOKEN_MIN_CHARS``-``TOKEN_MAX_CHARS`` characters from ``A-Z a-z 0-9 _ -``.

    Raises:
        DataError: Naming ``source`` and ``field`` (never the value: it is a secret).
    """
    if not isinstance(value, str):
        raise DataError("not text", source=source, field=field, expected=_TOKEN_EXPECTED)
    if not TOKEN_MIN_CHARS <= len(value) <= TOKEN_MAX_CHARS:
        raise DataError(f"a token of {len(value)} characters", source=source, field=field,
                        expected=_TOKEN_EXPECTED)
    if _TOKEN_CHARS.fullmatch(value) is None:
        raise DataError("a token with characters other than A-Z a-z 0-9 _ -", source=source,
                        field=field, expected=_TOKEN_EXPECTED)
    return value


def read_token_file(path: Path) -> str:
    """The token in ``path``: one line (a final newline is allowed), checked by
    :func:`check_token`.

    Raises:
        DataError: Naming ``--token-file`` and the file: unreadable, not text, more than one
            line, or not a token.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(TOKEN_MAX_CHARS + 3)
    except OSError as e:
        raise DataError(f"cannot read it: {e.strerror or e}", field="--token-file",
                        value=str(path), expected=_TOKEN_EXPECTED) from e
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as e:
        raise DataError("not ASCII text", field="--token-file", value=str(path),
                        expected=_TOKEN_EXPECTED) from e
    if text.endswith("\r\n"):
        text = text[:-2]
    elif text.endswith("\n"):
        text = text[:-1]
    if "\n" in text or "\r" in text:
        raise DataError("more than one line", field="--token-file", value=str(path),
                        expected=_TOKEN_EXPECTED)
    return check_token(text, source=path, field="--token-file")


def is_loopback(bind: str) -> bool:
    """Whether every address ``bind`` names is one of this machine's loopback addresses
    (``127.0.0.0/8``, ``::1``; a name such as ``localhost`` is resolved). An address that does
    not resolve is not loopback."""
    name = bind.strip("[]")
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(name, None, socket.AF_UNSPEC, socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return False
    addresses = {info[4][0] for info in infos}
    return bool(addresses) and all(ipaddress.ip_address(str(a).split("%")[0]).is_loopback
                                   for a in addresses)


class _RefusalLog:
    """One log line per refusal, at most ``burst`` lines at once and then one per
    ``every_s``, each counting the refusals left out since the last line."""

    def __init__(self, burst: int = 10, every_s: float = 10.0) -> None:
        self.burst, self.every_s = burst, every_s
        self._credit, self._at, self._left_out = float(burst), time.monotonic(), 0
        self._lock = threading.Lock()

    def refused(self, text: str) -> None:
        with self._lock:
            now = time.monotonic()
            self._credit = min(float(self.burst),
                               self._credit + (now - self._at) * self.burst / self.every_s)
            self._at = now
            if self._credit < 1.0:
                self._left_out += 1
                return
            self._credit -= 1.0
            more, self._left_out = self._left_out, 0
        note = f" ({more} more refused, not logged)" if more else ""
        _log.warning("pendant: refused %s%s", text, note)


def _shown(value: str | None) -> str:
    """A header's value for the log: quoted, control characters escaped, at most 80."""
    if value is None:
        return "none"
    return repr(value[:80] + ("..." if len(value) > 80 else ""))


@dataclasses.dataclass
class _Verdict:
    kind: str               # "token", "host", "origin" or "clients"
    status: http.HTTPStatus
    reason: str


class Gate:
    """The checks every request to the pendant's page passes (see the module's text).

    Args:
        token: The secret first segment of every path (:func:`new_token`; checked by
            :func:`check_token`).
        bind: The address the page is served on.
        allow_remote: Whether ``bind`` may be other than loopback.
        max_clients: Pages connected at once, 1 to :data:`MAX_CLIENTS_LIMIT`.
        max_message_bytes: Largest message a page may send [bytes].
        page_script: JavaScript run by the page before viser's (inserted before
            ``</head>``); default: the content of :data:`PAGE_GUARD` if that file exists.

    Raises:
        DataError: A bad token, a remote ``bind`` without ``allow_remote``, a limit out of
            range, or a page script that could end its ``<script>`` element.
    """

    def __init__(self, token: str, bind: str = "127.0.0.1", *, allow_remote: bool = False,
                 max_clients: int = DEFAULT_MAX_CLIENTS,
                 max_message_bytes: int = MAX_MESSAGE_BYTES,
                 page_script: str | None = None) -> None:
        self.token = check_token(token)
        self._token_bytes = token.encode("ascii")
        self.bind = bind
        self.loopback = is_loopback(bind)
        if not self.loopback and not allow_remote:
            raise DataError("serves the page to the network, where anyone who has its URL "
                            "can move the robot", field="--bind", value=bind,
                            expected="127.0.0.1 (this machine only), or --allow-remote")
        if not (isinstance(max_clients, int) and 1 <= max_clients <= MAX_CLIENTS_LIMIT):
            raise DataError("out of range", field="--max-clients", value=max_clients,
                            expected=f"an integer 1-{MAX_CLIENTS_LIMIT}")
        if not (isinstance(max_message_bytes, int) and max_message_bytes >= 4096):
            raise DataError("out of range", field="max_message_bytes", value=max_message_bytes,
                            expected="an integer >= 4096 [bytes]")
        self.max_clients, self.max_message_bytes = max_clients, max_message_bytes
        if page_script is None and PAGE_GUARD.is_file():
            page_script = PAGE_GUARD.read_text(encoding="utf-8")
        if page_script is not None and "</script" in page_script.lower():
            raise DataError("the page script contains '</script'", source=PAGE_GUARD,
                            expected="JavaScript without the text '</script'")
        self.page_script = page_script
        self._names = self._host_names()
        self._log = _RefusalLog()
        self._admitted: weakref.WeakSet[Any] = weakref.WeakSet()
        self._page: dict[bool, bytes] = {}
        #: Refused requests so far, by why: no or a wrong ``"token"``, a foreign ``"host"`` or
        #: ``"origin"``, too many ``"clients"``.
        self.refused: dict[str, int] = dict.fromkeys(("token", "host", "origin", "clients"), 0)

    # ------------------------------------------------------------------ addresses
    def _host_names(self) -> set[str]:
        """The names a Host header may give (lower case, IPv6 in brackets); bound to all
        addresses, any IP address literal as well (:meth:`_host_allowed`)."""
        names = set(_LOOPBACK_NAMES)
        bind = self.bind.strip("[]").lower()
        try:
            ip = ipaddress.ip_address(bind)
            names.add(f"[{ip}]" if ip.version == 6 else str(ip))
        except ValueError:
            names.add(bind)
        if not self.loopback:
            host = socket.gethostname().lower()
            names |= {host, f"{host}.local", socket.getfqdn().lower()}
        return names

    def _wildcard(self) -> bool:
        return self.bind.strip("[]") in ("0.0.0.0", "::", "")

    def _host_allowed(self, host: str, port: int) -> bool:
        """Whether a Host header names the served address and port (no user info)."""
        if not host or "@" in host or any(c.isspace() for c in host):
            return False
        try:
            parts = urlsplit("//" + host)
            given = parts.port
        except ValueError:
            return False
        name = (parts.hostname or "").lower()
        if (given is None and port != 80) or (given is not None and given != port):
            return False
        if ":" in name:
            name = f"[{name}]"
        if name in self._names:
            return True
        if self._wildcard():      # any address of this machine: an IP literal cannot rebind
            try:
                ipaddress.ip_address(name.strip("[]"))
                return True
            except ValueError:
                return False
        return False

    # ------------------------------------------------------------------ the checks
    def verdict(self, path: str, headers: Any, port: int, upgrade: bool,
                live_clients: int) -> _Verdict | None:
        """Why a request is refused (a status and a reason), or None if it passes.

        Args:
            path: The request's path (with its query).
            headers: Its headers (websockets' ``Headers``: ``.get_all(name)``).
            port: The port it came in on (the served port).
            upgrade: Whether it asks for a WebSocket.
            live_clients: Pages connected now.
        """
        first = path.partition("?")[0].lstrip("/").partition("/")[0]
        if not hmac.compare_digest(first.encode("utf-8", "replace"), self._token_bytes):
            return _Verdict("token", http.HTTPStatus.FORBIDDEN, "no token or a wrong one")
        hosts, origins = headers.get_all("Host"), headers.get_all("Origin")
        host = hosts[0] if len(hosts) == 1 else None
        if host is None or not self._host_allowed(host, port):
            return _Verdict("host", http.HTTPStatus.FORBIDDEN,
                            f"Host {_shown(host) if len(hosts) <= 1 else 'given twice'}")
        if len(origins) > 1 or (origins and origins[0].lower() != f"http://{host.lower()}"):
            return _Verdict("origin", http.HTTPStatus.FORBIDDEN,
                            f"Origin {_shown(origins[0]) if len(origins) == 1 else 'twice'}")
        if upgrade and live_clients >= self.max_clients:
            return _Verdict("clients", http.HTTPStatus.SERVICE_UNAVAILABLE,
                            f"{live_clients} pages connected, at most {self.max_clients}")
        return None

    def process_request(self, viser_http: Callable[[Any, Any], Any] | None,
                        connection: Any, request: Any) -> Any:
        """websockets' ``process_request``: refuse (a response), pass a WebSocket on (None),
        or answer an HTTP request through viser's file server with the token stripped."""
        upgrade = "websocket" in (v.lower() for v in request.headers.get_all("Upgrade"))
        server = connection.server
        live = sum(1 for c in self._admitted if c in server.handlers)
        port = int(connection.local_address[1])
        refused = self.verdict(request.path, request.headers, port, upgrade, live)
        if refused is not None:
            self.refused[refused.kind] += 1
            peer = connection.remote_address
            where = f"{peer[0]}:{peer[1]}" if peer else "unknown"
            kind = "WebSocket" if upgrade else "HTTP request"
            self._log.refused(f"{kind} from {where}: {refused.reason} "
                              f"({int(refused.status)})")
            text = ("the pendant serves only the page at the URL it printed\n"
                    if refused.status == http.HTTPStatus.FORBIDDEN else
                    f"the pendant serves at most {self.max_clients} pages at once\n")
            return connection.respond(refused.status, text)
        if upgrade:
            self._admitted.add(connection)
            return None
        rest = request.path.partition("?")[0].lstrip("/").partition("/")[2]
        if viser_http is None:
            return connection.respond(http.HTTPStatus.NOT_FOUND, "NOT FOUND\n")
        if rest in ("", "index.html") and self.page_script is not None:
            response = self._index(viser_http, connection, request)
        else:
            response = viser_http(connection, dataclasses.replace(request, path="/" + rest))
        if response is not None:
            for name, value in _SAFE_HEADERS.items():
                _set(response.headers, name, value)
            if any(v.startswith("text/html") for v in response.headers.get_all("Content-Type")):
                host = request.headers.get_all("Host")[0]      # (checked: exactly one)
                _set(response.headers, "Content-Security-Policy", _CSP.format(host=host))
        return response

    def _index(self, viser_http: Callable[[Any, Any], Any], connection: Any,
               request: Any) -> Any:
        """viser's page with the page script inserted before ``</head>``."""
        gzipped = any("gzip" in v for v in request.headers.get_all("Accept-Encoding"))
        if gzipped not in self._page:
            headers = request.headers.copy()
            if "Accept-Encoding" in headers:
                del headers["Accept-Encoding"]
            plain = viser_http(connection, dataclasses.replace(request, path="/",
                                                               headers=headers))
            if plain is None or plain.status_code != 200:
                return plain
            body = bytes(plain.body)
            at = body.rfind(b"</head>")
            if at < 0:
                raise DataError("viser's page has no </head>", field="index.html",
                                expected="viser's page, to insert the page script")
            assert self.page_script is not None
            script = f"<script>{self.page_script}</script>".encode()
            page = body[:at] + script + body[at:]
            self._page[gzipped] = gzip.compress(page) if gzipped else page
        body = self._page[gzipped]
        response = dataclasses.replace(connection.respond(http.HTTPStatus.OK, ""), body=body)
        _set(response.headers, "Content-Type", "text/html; charset=utf-8")
        _set(response.headers, "Content-Length", str(len(body)))
        _set(response.headers, "Content-Encoding", "gzip" if gzipped else "identity")
        return response

    # ------------------------------------------------------------------ the URL
    def url(self, host: str, port: int) -> str:
        """The page's URL on ``host`` and ``port`` (``0.0.0.0``/``::``: this machine's
        loopback address), with the token."""
        if host in ("0.0.0.0", "::", ""):
            host = "127.0.0.1"
        elif ":" in host and not host.startswith("["):
            host = f"[{host}]"
        return f"http://{host}:{port}/{self.token}/"


def _set(headers: Any, name: str, value: str) -> None:
    """Set one header of websockets' ``Headers`` (whose ``[name] = value`` appends)."""
    if name in headers:
        del headers[name]
    headers[name] = value


_patch_lock = threading.Lock()


@contextlib.contextmanager
def _gated_serve(gate: Gate) -> Iterator[None]:
    """While the context runs, ``websockets.asyncio.server.serve`` goes through ``gate``."""
    import websockets.asyncio.server as ws_server

    original = ws_server.serve

    def serve(handler: Any, *args: Any, **kwargs: Any) -> Any:
        viser_http = kwargs.get("process_request")
        kwargs["process_request"] = (
            lambda connection, request: gate.process_request(viser_http, connection, request))
        kwargs["max_size"] = gate.max_message_bytes
        return original(handler, *args, **kwargs)

    with _patch_lock:
        ws_server.serve = serve  # type: ignore[misc,assignment]
        try:
            yield
        finally:
            ws_server.serve = original  # type: ignore[misc]


def serve_gated(gate: Gate, **viser_args: Any) -> Any:
    """A :class:`viser.ViserServer` (with ``viser_args``) whose every request passes
    ``gate``."""
    import rich
    import viser

    show = rich.print

    def no_panel(*objects: Any, **kwargs: Any) -> None:
        # viser prints its URLs in a panel, without the token: they would only be refused
        if not any(type(o).__name__ == "Panel" for o in objects):
            show(*objects, **kwargs)

    with _gated_serve(gate):
        rich.print = no_panel
        try:
            server = viser.ViserServer(**viser_args)
        finally:
            rich.print = show

    def no_share(verbose: bool = True) -> None:
        # a page's "share" request would open a tunnel to viser's public relay: the internet
        gate._log.refused("a page's request to share the pendant through viser's relay")

    server.request_share_url = no_share  # type: ignore[method-assign]
    return server
