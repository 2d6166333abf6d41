"""Who may reach the pendant's page (``leadthrough.pendant.access``), tried as an attacker on
the same computer would: a WebSocket client of our own (the ``websockets`` library) and plain
HTTP requests, on 127.0.0.1, against a :class:`~leadthrough.pendant.app.Pendant` on a live
simulated session. Refused: no token or a wrong one, a foreign Origin (another site's page in
the operator's browser), a foreign Host (DNS rebinding), a page beyond the client limit; an
oversize message closes only its sender's connection. Each time nothing reaches the pendant,
the robot does not move and the session stays alive. The command's own checks (``--bind``
without ``--allow-remote``, ``--token-file``) exit 2 before anything starts."""

from __future__ import annotations

import asyncio
import http.client
import logging
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
import viser
import websockets
import websockets.asyncio.client as ws_client
import zstandard

from leadthrough.cli import main
from leadthrough.cli.pendant_cmd import check_access, remote_warning
from leadthrough.control.safety import State
from leadthrough.errors import DataError
from leadthrough.pendant.access import (
    MAX_MESSAGE_BYTES,
    Gate,
    is_loopback,
    new_token,
    read_token_file,
)
from leadthrough.pendant.app import Pendant, wait_for_clients
from leadthrough.pendant.simulated import SimulatedPendantSession, simulated_session
from leadthrough.robot import Robot

SUBPROTOCOL = f"viser-v{viser.__version__}"       # what viser's own page asks for
EVIL = "http://evil.example"


@pytest.fixture(scope="module")
def sim(er20: Robot) -> Iterator[SimulatedPendantSession]:
    """A live simulated session, idle, shared by the module's pendants."""
    s = simulated_session(er20)
    s.live.start()
    try:
        yield s
    finally:
        s.live.stop()
        s.live.close()


class Spy:
    """Which of the pendant's operator actions a client's messages reached."""

    def __init__(self, app: Pendant) -> None:
        self.calls: list[tuple[str, tuple[Any, ...]]] = []
        for name in ("arm", "hold_device", "release_device", "take_control", "mark", "export",
                     "push", "adjust", "clear_fault"):
            if hasattr(app, name):
                setattr(app, name, self._record(name, getattr(app, name)))

    def _record(self, name: str, original: Any) -> Any:
        def call(*args: Any, **kwargs: Any) -> Any:
            self.calls.append((name, args))
            return original(*args, **kwargs)
        return call


@pytest.fixture
def app(sim: SimulatedPendantSession, tmp_path: Path) -> Iterator[Pendant]:
    pendant = Pendant(sim.live, tmp_path / "out", hand=sim.hand, port=0, max_clients=2)
    pendant.start()
    try:
        yield pendant
    finally:
        pendant.stop()


def _ws_url(app: Pendant, token: str | None = None) -> str:
    token = app.gate.token if token is None else token
    return f"ws://127.0.0.1:{app.server.get_port()}/{token}"


def _own_origin(app: Pendant) -> str:
    return f"http://127.0.0.1:{app.server.get_port()}"


def _get(app: Pendant, path: str, **headers: str) -> tuple[int, bytes, http.client.HTTPMessage]:
    conn = http.client.HTTPConnection("127.0.0.1", app.server.get_port(), timeout=10)
    try:
        conn.request("GET", path, headers=headers)
        response = conn.getresponse()
        return response.status, response.read(), response.headers
    finally:
        conn.close()


def _decode(frame: bytes) -> list[dict[str, Any]]:
    """The messages of one of viser's server-to-page frames (zstd-compressed msgpack)."""
    size = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + size])
    return list(msgspec.msgpack.decode(inner)["messages"])


def _uuid_of(messages: list[dict[str, Any]], label: str) -> str | None:
    def search(node: Any, uuid: str | None) -> str | None:
        if isinstance(node, dict):
            uuid = node.get("uuid", uuid)
            if node.get("label") == label and uuid is not None:
                return str(uuid)
            for value in node.values():
                found = search(value, uuid)
                if found is not None:
                    return found
        elif isinstance(node, list | tuple):
            for value in node:
                found = search(value, uuid)
                if found is not None:
                    return found
        return None
    return search(messages, None)


#: The camera message viser's page sends first (viser counts a page as connected from then).
CAMERA = {"type": "ViewerCameraMessage", "wxyz": (1.0, 0.0, 0.0, 0.0),
          "position": (2.0, 0.0, 1.0), "fov": 1.0, "near": 0.01, "far": 100.0,
          "image_height": 800, "image_width": 1280, "look_at": (0.0, 0.0, 0.0),
          "up_direction": (0.0, 0.0, 1.0)}


async def _click(connection: Any, label: str) -> None:
    """Click the page's button ``label`` as viser's page does: send the camera, find the
    button in the GUI the server sends, send its GuiUpdateMessage."""
    await connection.send(msgspec.msgpack.encode(CAMERA))
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        frame = await asyncio.wait_for(connection.recv(), 20)
        if isinstance(frame, bytes):
            uuid = _uuid_of(_decode(frame), label)
            if uuid is not None:
                await connection.send(msgspec.msgpack.encode(
                    {"type": "GuiUpdateMessage", "uuid": uuid, "updates": {"value": True}}))
                return
    pytest.fail(f"no button {label!r} in the page's GUI")


def _attack(url: str, **connect: Any) -> int | None:
    """Connect as a page would and click "Arm guiding"; the refusing status, or None if the
    click was sent."""
    async def attack() -> int | None:
        try:
            async with ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                         open_timeout=10, max_size=None, **connect) as c:
                await _click(c, "Arm guiding")
                await asyncio.sleep(0.5)
        except websockets.InvalidStatus as e:
            return int(e.response.status_code)
        return None
    return asyncio.run(attack())


def _pose(app: Pendant) -> np.ndarray:
    snap = app.live.snapshot()
    assert snap is not None
    return np.array(snap.q, copy=True)


def _still(app: Pendant, before: np.ndarray) -> None:
    """The session alive, idle, the robot where it was (1 µrad), no page connected."""
    snap = app.live.snapshot()
    assert app.live.running and snap is not None and snap.error is None
    assert snap.state == State.IDLE
    assert float(np.max(np.abs(np.array(snap.q) - before))) < 1e-6
    assert not app.server.get_clients()


def test_a_foreign_page_without_the_token_moves_nothing(app: Pendant,
                                                        caplog: pytest.LogCaptureFixture) -> None:
    spy, before = Spy(app), _pose(app)
    port = app.server.get_port()
    with caplog.at_level(logging.WARNING, logger="leadthrough.pendant.access"):
        # another site's page in the operator's browser, without the token, then with it
        assert _attack(f"ws://127.0.0.1:{port}", origin=EVIL) == 403
        assert _attack(f"ws://127.0.0.1:{port}/", origin=EVIL) == 403
        assert _attack(_ws_url(app, new_token()), origin=EVIL) == 403
        assert _attack(_ws_url(app), origin=EVIL) == 403
        assert _attack(_ws_url(app), origin="null") == 403          # a sandboxed frame, a file
        assert _attack(_ws_url(app), origin=f"https://127.0.0.1:{port}") == 403
        # a local process without the token (no Origin at all)
        assert _attack(f"ws://127.0.0.1:{port}/x") == 403
    time.sleep(0.3)
    assert spy.calls == []
    _still(app, before)
    assert app.gate.refused["token"] == 4 and app.gate.refused["origin"] == 3
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 7 and all(line.startswith("pendant: refused WebSocket") for line in lines)
    assert any("Origin 'http://evil.example'" in line for line in lines)
    assert all(app.gate.token not in line for line in lines)           # the secret is not logged


def test_the_page_with_the_token_and_its_own_origin_reaches_the_pendant(app: Pendant) -> None:
    """The same client as the attacks', with the token and the page's own Origin: its click
    arrives (so a refusal above is the gate's, not a client that could not have clicked)."""
    spy = Spy(app)
    assert _attack(_ws_url(app), origin=_own_origin(app)) is None
    assert "arm" in [name for name, _ in spy.calls]
    assert _attack(_ws_url(app) + "/") is None        # a local client: no Origin


def test_a_foreign_host_is_refused_dns_rebinding(app: Pendant) -> None:
    spy, before = Spy(app), _pose(app)
    port = app.server.get_port()
    token = app.gate.token
    for host in (f"evil.example:{port}", "127.0.0.1", f"127.0.0.1:{port + 1}",
                 f"localhost.evil.example:{port}"):
        status, body, _ = _get(app, f"/{token}/", Host=host)
        assert status == 403, host
        assert b"<html" not in body
        # (the URL's host is the Host header; the connection goes to 127.0.0.1)
        assert _attack(f"ws://{host}/{token}", host="127.0.0.1", port=port) == 403, host
    assert _get(app, f"/{token}/", Host=f"user@127.0.0.1:{port}")[0] == 403
    # a rebinding page sends its own Origin, matching its foreign Host
    assert _attack(f"ws://evil.example:{port}/{token}", host="127.0.0.1", port=port,
                   origin=f"http://evil.example:{port}") == 403
    for host in (f"localhost:{port}", f"127.0.0.1:{port}", f"LOCALHOST:{port}"):
        assert _get(app, f"/{app.gate.token}/", Host=host)[0] == 200, host
    assert spy.calls == []
    _still(app, before)
    assert app.gate.refused["host"] == 10


def test_http_needs_the_token(app: Pendant) -> None:
    token = app.gate.token
    for path in ("/", "/index.html", f"/{token[:-1]}/", f"/x{token}/", f"/{token}x/",
                 f"/?{token}", f"/index.html/{token}/", f"/{token.upper()}/"):
        status, body, _ = _get(app, path)
        assert status == 403, path
        assert b"Viser" not in body
    status, body, headers = _get(app, f"/{token}/")
    assert status == 200 and b"<title>Viser</title>" in body
    assert headers["Referrer-Policy"] == "no-referrer"          # the URL holds the token
    assert headers["X-Frame-Options"] == "DENY"
    policy = headers["Content-Security-Policy"]
    assert "frame-ancestors 'none'" in policy
    assert f"connect-src 'self' ws://127.0.0.1:{app.server.get_port()} " in policy
    assert _get(app, f"/{token}")[0] == 200
    assert _get(app, f"/{token}/?websocket=ws://127.0.0.1")[0] == 200
    assert _get(app, f"/{token}/../{token}/")[0] == 404           # viser's own traversal check
    assert app.url == f"http://127.0.0.1:{app.server.get_port()}/{token}/"
    assert app.gate.refused["token"] == 8


def test_the_page_script_goes_before_the_head_end(sim: SimulatedPendantSession) -> None:
    gate = Gate(new_token(), page_script="window.__guard = 1;")
    from leadthrough.pendant.access import serve_gated
    server = serve_gated(gate, host="127.0.0.1", port=0, verbose=False)
    try:
        for encoding in ("identity", "gzip"):
            conn = http.client.HTTPConnection("127.0.0.1", server.get_port(), timeout=10)
            conn.request("GET", f"/{gate.token}/", headers={"Accept-Encoding": encoding})
            response = conn.getresponse()
            body = response.read()
            conn.close()
            if encoding == "gzip":
                import gzip
                assert response.headers["Content-Encoding"] == "gzip"
                body = gzip.decompress(body)
            assert response.status == 200
            assert body.count(b"<script>window.__guard = 1;</script></head>") == 1
    finally:
        server.stop()
    with pytest.raises(DataError, match="</script"):
        Gate(new_token(), page_script="x = '</SCRIPT>';")


def test_at_most_max_clients_pages(app: Pendant) -> None:
    async def scenario() -> None:
        url, origin = _ws_url(app), _own_origin(app)
        first = await ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                        origin=origin, max_size=None)   # type: ignore[arg-type]
        second = await ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                         origin=origin, max_size=None)  # type: ignore[arg-type]
        try:
            with pytest.raises(websockets.InvalidStatus) as refused:
                await ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                        origin=origin)  # type: ignore[arg-type]
            assert refused.value.response.status_code == 503
            await first.close()
            # a place is free again once the server has let go of the closed page
            deadline = time.monotonic() + 10
            while True:
                try:
                    third = await ws_client.connect(
                        url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                        origin=origin)  # type: ignore[arg-type]
                    break
                except websockets.InvalidStatus as e:
                    assert e.response.status_code == 503
                    if time.monotonic() > deadline:
                        raise
                    await asyncio.sleep(0.05)
            await third.close()
        finally:
            await first.close()
            await second.close()
    asyncio.run(scenario())
    assert app.gate.refused["clients"] >= 1
    assert app.live.running


def test_an_oversize_message_closes_only_its_sender(app: Pendant) -> None:
    spy, before = Spy(app), _pose(app)

    async def scenario() -> tuple[int | None, bool]:
        url, origin = _ws_url(app), _own_origin(app)
        big = await ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                      origin=origin, max_size=None)  # type: ignore[arg-type]
        other = await ws_client.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                        origin=origin, max_size=None)  # type: ignore[arg-type]
        try:
            label = "W" * (MAX_MESSAGE_BYTES + 1)
            await big.send(msgspec.msgpack.encode(
                {"type": "GuiUpdateMessage", "uuid": "x", "updates": {"value": label}}))
            await asyncio.wait_for(big.wait_closed(), 10)
            await asyncio.sleep(0.3)
            return big.close_code, other.state is websockets.State.OPEN
        finally:
            await big.close()
            await other.close()

    code, other_open = asyncio.run(scenario())
    assert code == 1009                        # "message too big"
    assert other_open
    assert spy.calls == []
    _still(app, before)
    assert wait_for_clients(app, 0, 1.0)


def test_a_flood_of_refusals_is_logged_a_few_lines(app: Pendant,
                                                   caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="leadthrough.pendant.access"):
        for _ in range(60):
            assert _get(app, "/")[0] == 403
    lines = [r.getMessage() for r in caplog.records]
    assert 1 <= len(lines) <= 12, lines
    assert app.gate.refused["token"] == 60


def test_the_host_check_on_loopback_and_remote() -> None:
    token = new_token()
    local = Gate(token)
    headers = websockets.Headers
    ok = {"Host": "127.0.0.1:8080"}
    assert local.verdict(f"/{token}/", headers(ok), 8080, False, 0) is None
    assert local.verdict(f"/{token}/", headers({"Host": "[::1]:8080"}), 8080, False, 0) is None
    for host in ("10.0.0.5:8080", "evil:8080", "127.0.0.1:8080 x", ""):
        verdict = local.verdict(f"/{token}/", headers({"Host": host}), 8080, False, 0)
        assert verdict is not None and verdict.status == 403, host
    twice = headers([("Host", "127.0.0.1:8080"), ("Host", "evil:8080")])
    assert local.verdict(f"/{token}/", twice, 8080, False, 0) is not None
    assert local.verdict(f"/{token}/", headers(ok), 8080, True, 4) is not None   # the limit
    with pytest.raises(DataError, match="--allow-remote"):
        Gate(token, "0.0.0.0")
    remote = Gate(token, "0.0.0.0", allow_remote=True)        # (no socket is opened)
    assert remote.verdict(f"/{token}/", headers({"Host": "10.0.0.5:8080"}), 8080, False, 0) \
        is None                                            # an address literal cannot rebind
    assert remote.verdict(f"/{token}/", headers({"Host": "evil.example:8080"}), 8080,
                          False, 0) is not None


def test_loopback_addresses() -> None:
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert is_loopback("127.0.0.2")
    assert not is_loopback("0.0.0.0") and not is_loopback("::")
    assert not is_loopback("192.0.2.1") and not is_loopback("no.such.host.invalid")


def test_bind_to_the_network_needs_allow_remote(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["pendant", "--bind", "0.0.0.0", "--duration", "1"]) == 2
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("leadthrough: error:"), captured.err
    assert "'--bind' = '0.0.0.0'" in lines[0] and "--allow-remote" in lines[0]
    assert "move the robot" in lines[0]
    assert "starting the loop" not in captured.out
    check_access("0.0.0.0", True)                  # accepted with it (nothing is started)
    check_access("127.0.0.1", False)
    token = new_token()
    warning = remote_warning("0.0.0.0", 8080, token)
    assert warning is not None and "anyone on the network" in warning
    assert "move the robot" in warning and "unencrypted" in warning
    assert f":8080/{token}/" in warning
    assert remote_warning("127.0.0.1", 8080) is None


def test_the_help_states_the_limits(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["pendant", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--token-file" in text and "--allow-remote" in text and "--max-clients" in text
    assert f"{MAX_MESSAGE_BYTES // 1024} kB" in text and "default 4" in text
    assert "403" in text and "unencrypted" in text


def test_a_token_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "token"
    token = new_token()
    good.write_text(token + "\n")
    assert read_token_file(good) == token
    cases = {"short": "abc\n", "chars": "x" * 40 + "!\n", "lines": token + "\n" + token + "\n",
             "binary": "é" * 40, "empty": ""}
    for name, text in cases.items():
        bad = tmp_path / name
        bad.write_text(text, encoding="utf-8")
        with pytest.raises(DataError) as e:
            read_token_file(bad)
        assert "--token-file" in str(e.value) and str(bad) in str(e.value), name
    with pytest.raises(DataError, match="cannot read"):
        read_token_file(tmp_path / "missing")
    with pytest.raises(DataError, match="cannot read"):
        read_token_file(tmp_path)                           # a folder
    assert main(["pendant", "--token-file", str(tmp_path / "short"), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "--token-file" in err and "short" in err and "abc" not in err  # (not the secret)


def test_a_page_cannot_open_viser_s_share_tunnel(caplog: pytest.LogCaptureFixture) -> None:
    """viser answers a page's "share" request by opening a tunnel to its public relay; the
    pendant's server refuses it (and logs it)."""
    from leadthrough.pendant.access import serve_gated
    gate = Gate(new_token())
    server = serve_gated(gate, host="127.0.0.1", port=0, verbose=False)

    async def ask() -> None:
        async with ws_client.connect(f"ws://127.0.0.1:{server.get_port()}/{gate.token}",
                                     subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                     max_size=None) as c:
            await c.send(msgspec.msgpack.encode(CAMERA))
            await c.send(msgspec.msgpack.encode({"type": "ShareUrlRequest"}))
            await asyncio.sleep(0.5)

    try:
        with caplog.at_level(logging.WARNING, logger="leadthrough.pendant.access"):
            asyncio.run(ask())
            deadline = time.monotonic() + 5
            while not caplog.records and time.monotonic() < deadline:
                time.sleep(0.05)
    finally:
        server.stop()
    assert any("share the pendant" in r.getMessage() for r in caplog.records)


class _Running:
    """The module's running session for the command to serve (it neither starts nor stops
    it: the loop's start is what takes the command's time)."""

    def __init__(self, live: Any) -> None:
        self._live = live

    def __getattr__(self, name: str) -> Any:
        return getattr(self._live, name)

    def start(self, **_: Any) -> None:
        pass

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_the_command_prints_the_url_with_the_token_of_its_file(
        sim: SimulatedPendantSession, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``pendant --token-file``: the printed URL carries that token, and that URL (and only
    it) is served while the command runs."""
    import socket
    import threading

    import leadthrough.pendant.simulated as simulated
    running: Any = _Running(sim.live)
    monkeypatch.setattr(simulated, "simulated_session",
                        lambda *_, **__: sim._replace(live=running))
    token_file = tmp_path / "token"
    token = new_token()
    token_file.write_text(token + "\n")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    served: dict[str, int] = {}

    def probe() -> None:       # while the command runs
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(served) < 2:
            try:
                for path in (f"/{token}/", "/"):
                    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
                    conn.request("GET", path)
                    served[path] = conn.getresponse().status
                    conn.close()
            except OSError:
                time.sleep(0.1)

    thread = threading.Thread(target=probe, daemon=True)
    thread.start()
    assert main(["pendant", "--port", str(port), "--duration", "2", "--token-file",
                 str(token_file), "-o", str(tmp_path / "out")]) == 0
    thread.join(5)
    out = capsys.readouterr().out
    assert f"pendant: http://127.0.0.1:{port}/{token}/" in out
    assert "WARNING" not in out                          # served on this machine only
    assert served == {f"/{token}/": 200, "/": 403}
