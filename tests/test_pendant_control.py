"""Attacks on the pendant's page, through its public interface: real pages (WebSocket clients
that talk viser's protocol, as the browser's page does) and the pendant's own methods with
distinct page ids, against a live session on the simulator (its loop in a process of its own).

* two pages fighting for the hold-to-run enabling device: the page in control holds it, the
  other page's release, press, disarm, mark and take-over are refused to that page alone;
* a frozen page (it stops heartbeating) is released within the lease; the loop's process
  releases a lapsed lease by itself, with the pendant's process stalled;
* crafted labels (markup, a newline with a robot statement, 600 kB) and a NaN handle position
  are refused before anything reaches the loop; sent to the loop's process directly they are
  refused there and counted, and the session stays alive;
* what the page shows of a label or a notice is escaped text, never markup;
* exports: the page in control only, one at a time, apart, at most so many a run.

Each refused attack leaves the robot where it was, writes nothing and keeps the session alive.
"""

from __future__ import annotations

import contextlib
import math
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
import viser
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol

from leadthrough.control.safety import State
from leadthrough.identification.params_file import ParamsFile
from leadthrough.pendant.app import Pendant
from leadthrough.pendant.backend import LiveSession, LoopSnapshot, MarkPoint, SetEnable
from leadthrough.pendant.controls import HOLD_HZ, text_html
from leadthrough.pendant.messages import (
    LEASE_S,
    Adjust,
    Notice,
    SlowState,
    check_request,
    fit_slow,
)
from leadthrough.pendant.push import Hold, Push
from leadthrough.pendant.simulated import SimulatedPendantSession, simulated_session
from leadthrough.robot import Robot

IMG = "<img src=x onerror=alert(1)>"
RAPID = "W1\n SetDO do1, 1;"
HUGE = "x" * 600_000
CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
          "position": [2.0, -0.6, 1.3], "fov": 1.3, "near": 0.01, "far": 100.0,
          "image_height": 800, "image_width": 1280, "look_at": [0.5, 0.1, 0.6],
          "up_direction": [0.0, 0.0, 1.0]}


def _until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.01)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _snap(live: LiveSession) -> LoopSnapshot:
    snap = live.snapshot()
    assert snap is not None
    assert snap.error is None, f"the loop stopped: {snap.error}"
    assert live.running
    return snap


@pytest.fixture(scope="module")
def sim(er20: Robot) -> Iterator[SimulatedPendantSession]:
    """One live session on the simulator, in real time, for the module's tests."""
    s = simulated_session(er20, record_s=30.0)
    s.live.start()
    _until(lambda: getattr(s.live.snapshot(), "estimator", None) is not None
           and _snap(s.live).estimator.name == "OK", 20, "the estimator's tare")
    try:
        yield s
    finally:
        s.live.stop()
        s.live.close()


@pytest.fixture
def app(sim: SimulatedPendantSession, tmp_path: Path) -> Iterator[Pendant]:
    """A pendant on the session (its page updates not started: see each test), torn down
    with the enabling input released and the robot at rest."""
    pendant = Pendant(sim.live, tmp_path / "out", hand=sim.hand, port=_free_port())
    try:
        yield pendant
    finally:
        pendant.stop()
        sim.live.send(SetEnable(False))
        sim.hand.release()
        _until(lambda: _snap(sim.live).state in (State.IDLE, State.FAULT)
               and _snap(sim.live).speed == 0.0, 15, "rest after the test")


class Page:
    """A page on the pendant: a WebSocket client speaking viser's protocol, its first message
    the camera (which makes it a client, as the browser's page does); what the server sends
    is read and dropped on a thread."""

    def __init__(self, app: Pendant) -> None:
        before = set(app.server.get_clients())
        self.ws: ClientConnection = connect(app.url.replace("http", "ws", 1),
                                            subprotocols=[Subprotocol(
                                                f"viser-v{viser.__version__}")],
                                            max_size=None)
        self.ws.send(msgspec.msgpack.encode(CAMERA))
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        _until(lambda: bool(set(app.server.get_clients()) - before), 10,
               "the page to connect")
        (self.id,) = set(app.server.get_clients()) - before

    def _drain(self) -> None:
        with contextlib.suppress(Exception):
            while True:
                self.ws.recv()

    def send(self, message: dict[str, Any]) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def click(self, handle: Any, value: Any = True) -> None:
        """A click on a button (or a value set on an input), by the element's id (which the
        server sends every page)."""
        self.send({"type": "GuiUpdateMessage", "uuid": handle._impl.uuid,
                   "updates": {"value": value}})

    def hold(self, handle: Any) -> None:
        """One heartbeat of a held button."""
        self.send({"type": "GuiButtonHoldMessage", "uuid": handle._impl.uuid,
                   "frequency": HOLD_HZ})

    def close(self) -> None:
        self.ws.close()


class Holding:
    """A page holding a button: heartbeats at :data:`HOLD_HZ` until stopped."""

    def __init__(self, page: Page, button: Any) -> None:
        self.page, self.button = page, button
        self._stop = threading.Event()
        self.last_sent = 0.0
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(Exception):
                self.page.hold(self.button)
                self.last_sent = time.monotonic()
            self._stop.wait(1.0 / HOLD_HZ)

    def stop(self) -> float:
        """Stop (the page freezes); returns when the last heartbeat was sent."""
        self._stop.set()
        self._thread.join(2.0)
        return self.last_sent


def _guiding(app: Pendant, live: LiveSession, page: Page) -> Holding:
    """``page`` takes control, arms and holds the enabling device: GUIDING."""
    page.click(app.controls.take)
    _until(lambda: app.controller == page.id, 5, "control")
    page.click(app.controls.arm)
    _until(lambda: app.armed, 5, "armed")
    assert app.controls.device is not None
    held = Holding(page, app.controls.device)
    _until(lambda: _snap(live).state == State.GUIDING, 10, "GUIDING")
    return held


def test_two_pages_fight_for_the_enabling_device(app: Pendant,
                                                  sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a, b = Page(app), Page(app)
    try:
        held = _guiding(app, live, a)
        lapsed0, marks0 = _snap(live).lapsed, _snap(live).marks
        device = app.controls.device
        assert device is not None
        samples = []
        for _ in range(5):           # b releases, presses, disarms, marks, takes over
            b.click(device)
            for _ in range(3):
                b.hold(device)
            b.click(app.controls.arm)
            b.click(app.controls.marks, "P1")
            b.click(app.controls.take)
            for _ in range(10):
                samples.append(_snap(live))
                time.sleep(0.01)
        _until(lambda: any("asks for control" in t for t in app.told(a.id)), 5,
               "the page in control to be asked")
        released = [s for s in samples if not s.enabled or s.state != State.GUIDING]
        if released:    # only a starved heartbeat of a's own may release, never b
            assert _snap(live).lapsed > lapsed0 or any(
                "no heartbeat" in t for t in app.told(a.id)), released[0]
        assert app.controller == a.id and app.armed
        told_b = app.told(b.id)
        for what in ("the enabling device refused", "arming refused", "marking refused"):
            assert any(t.startswith(what) and "read-only" in t for t in told_b), (what, told_b)
        assert any(t.startswith("asked the page in control") for t in told_b)
        assert not any(t.startswith("asked") for t in app.told(a.id))   # told b alone
        assert len(_snap(live).marks) == len(marks0)

        app.answer_control(a.id, True)              # a confirms: b in control, disarmed
        assert app.controller == b.id and not app.armed
        _until(lambda: not _snap(live).enabled, 2, "the release on the hand-over")
        _until(lambda: _snap(live).state == State.IDLE, 10, "IDLE after the hand-over")
        time.sleep(0.3)                              # a still heartbeats: refused now
        assert not _snap(live).enabled
        assert any("read-only now" in t for t in app.told(a.id))
        assert any(t.startswith("the enabling device refused") for t in app.told(a.id))
        held.stop()
    finally:
        a.close()
        b.close()


def test_a_frozen_page_is_released_within_the_lease(app: Pendant,
                                                    sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a = Page(app)
    try:
        held = _guiding(app, live, a)
        time.sleep(0.3)
        lapsed0 = _snap(live).lapsed
        last = held.stop()               # the page freezes: connected, no more heartbeats
        _until(lambda: not _snap(live).enabled, 5, "the release of a frozen page's device")
        seen = time.monotonic() - last
        _until(lambda: _snap(live).state == State.IDLE and _snap(live).speed == 0.0, 10,
               "the commanded stop to rest")
        snap = _snap(live)
        assert snap.cause == "STOPPED"                    # the normal release path
        assert seen < 2.0, f"released {seen:.2f} s after the last heartbeat"
        # the loop released the lease itself, within a controller cycle or so of its end
        # (the pendant's own watchdog is slower: it runs at the page's update rate)
        lapses = [n for n in snap.notices if "lease lapsed" in n.text]
        if snap.lapsed > lapsed0:
            late_ms = float(lapses[-1].text.split("lease lapsed ")[1].split(" ms")[0])
            assert late_ms < 100.0, lapses[-1].text
        else:
            assert any("no heartbeat" in t for t in app.told(a.id))
        assert app.controller == a.id                     # frozen, still in control
    finally:
        a.close()


def test_a_page_that_resumes_after_a_freeze_must_press_again(
        app: Pendant, sim: SimulatedPendantSession) -> None:
    """A frozen page whose heartbeats resume (the pointer still down) does not enable again:
    the device is held again only after the pointer let go of it (its click) and pressed."""
    live = sim.live
    app.start()
    a = Page(app)
    try:
        held = _guiding(app, live, a)
        held.stop()                                   # frozen: no heartbeat
        _until(lambda: not _snap(live).enabled, 5, "the release of the frozen page")
        _until(lambda: _snap(live).state == State.IDLE, 10, "the stop to IDLE")
        device = app.controls.device
        assert device is not None
        resumed = Holding(a, device)                  # the page thaws, pointer still down
        try:
            time.sleep(0.6)                           # nine heartbeats
            assert not _snap(live).enabled and _snap(live).state == State.IDLE
            assert any("press it again" in t for t in app.told(a.id))
        finally:
            resumed.stop()
        a.click(device)                               # the pointer lets go on the button
        pressed = Holding(a, device)                  # and presses anew
        try:
            _until(lambda: _snap(live).state == State.GUIDING, 10, "GUIDING on a new press")
        finally:
            pressed.stop()
    finally:
        a.close()


def test_the_loop_releases_a_lapsed_lease_with_the_pendant_stalled(
        app: Pendant, sim: SimulatedPendantSession) -> None:
    """One heartbeat, and the pendant's process does nothing more (its page updates and
    watchdog never started): the loop's process drops the hold by itself."""
    live = sim.live
    app.take_control(7)
    app.arm(7, True)
    lapsed0 = _snap(live).lapsed
    app.hold_device(7)
    _until(lambda: _snap(live).enabled or _snap(live).lapsed > lapsed0, 5, "the hold")
    _until(lambda: _snap(live).lapsed > lapsed0, 5, "the loop to drop the lapsed lease")
    snap = _snap(live)
    assert not snap.enabled and snap.lapsed == lapsed0 + 1
    assert "lease lapsed" in snap.notices[-1].text or any(
        "lease lapsed" in n.text for n in snap.notices)


def test_a_lease_lapses_at_the_first_cycle_after_it(er20: Robot,
                                                     nominal_params: ParamsFile) -> None:
    """The loop's side, on a clock the test owns: held up to the lease's end, released at the
    first controller cycle after it (one cycle: 10 ms here), whatever arrives."""
    from leadthrough.session.pacing import VirtualClock
    from loop_helpers import bare_loop
    clock = VirtualClock()
    loop = bare_loop(er20, nominal_params, clock=clock)
    loop.serve(SetEnable(True, until=LEASE_S), 0.0)
    for t in np.arange(0.0, LEASE_S + 1e-9, 0.01):
        clock.t = float(t)
        assert loop.enabled_by_operator(float(t)), t
    clock.t = LEASE_S + 0.01                                   # the next cycle
    assert not loop.enabled_by_operator(clock.t) and loop.lapsed == 1
    loop.serve(SetEnable(True, until=clock.t - 0.001), 0.0)    # a late heartbeat: no hold
    assert not loop.enabled_by_operator(clock.t) and loop.lapsed == 2
    loop.serve(SetEnable(True, until=math.nan), 0.0)           # malformed: refused, released
    assert not loop.enabled_by_operator(clock.t) and loop.refused == 1


def test_crafted_labels_are_refused_to_that_page(app: Pendant,
                                                 sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a, b = Page(app), Page(app)
    try:
        a.click(app.controls.take)
        _until(lambda: app.controller == a.id, 5, "control")
        refused0, marks0 = _snap(live).refused, len(_snap(live).marks)
        for label in (IMG, RAPID):                 # what the page's Mark buttons carry
            a.click(app.controls.marks, label)
        labels: tuple[Any, ...] = (IMG, RAPID, HUGE, "", " P1", 5)
        for label in labels:
            app.mark(a.id, label)
        _until(lambda: sum(t.startswith("mark refused") for t in app.told(a.id)) >= 8, 5,
               "the refusals")
        assert not app.told(b.id)                  # told to that page alone
        a.click(app.controls.marks, "P1")
        _until(lambda: len(_snap(live).marks) == marks0 + 1, 5, "the good mark")
        time.sleep(0.1)
        snap = _snap(live)
        assert [m.label for m in snap.marks[marks0:]] == ["P1"]
        assert snap.refused == refused0             # nothing bad reached the loop
        assert all(len(t) < 400 for t in app.told(a.id))
        _until(lambda: "P1 at" in app.controls.points.content, 5, "the list")
        assert "<img" not in app.controls.points.content
        assert "<img" not in app.controls.messages.content
        # past the pendant (straight to the loop): the loop's refusal quotes the label, and
        # the page shows that notice as text
        live.send(MarkPoint(IMG))
        _until(lambda: "&lt;img src=x onerror=alert(1)&gt;" in app.controls.messages.content,
               5, "the loop's refusal on the page")
        assert "<img" not in app.controls.messages.content
    finally:
        a.close()
        b.close()


def test_the_loop_refuses_what_bypasses_the_pendant(sim: SimulatedPendantSession) -> None:
    """Sent to the loop's process directly (the pendant's checks skipped), a 600 kB label, a
    crafted one, a NaN handle or push and malformed settings are refused there and counted;
    the session stays alive and nothing moves."""
    live = sim.live
    before = _snap(live)
    bad = [MarkPoint(HUGE), MarkPoint(IMG), MarkPoint(RAPID),
           Hold((math.nan, 0.0, 0.0), 1000.0, 10.0, 80.0),
           Hold((0.5, 0.0, 1e9), 1000.0, 10.0, 80.0), Push((0.0, math.inf, 0.0)),
           Push((500.0, 0.0, 0.0)), Adjust(mass=(math.nan, 1.0)), Adjust(frame="<b>"),
           SetEnable("yes")]  # type: ignore[arg-type]
    for request in bad:
        with pytest.raises(Exception, match="field"):
            check_request(request)
        live.send(request)                          # type: ignore[arg-type]
    _until(lambda: _snap(live).refused >= before.refused + len(bad), 5, "the refusals")
    time.sleep(0.2)
    after = _snap(live)
    assert after.refused == before.refused + len(bad)
    assert [(m.label, m.t) for m in after.marks] == [(m.label, m.t) for m in before.marks]
    assert after.state == before.state == State.IDLE
    assert not after.enabled and not after.push_base.any()
    assert np.allclose(after.transform_tool_to_base, before.transform_tool_to_base,
                       atol=1e-6)
    assert after.time > before.time                 # still running
    texts = [n.text for n in after.notices]
    assert any("MarkPoint refused" in t and "at most 32 characters" in t for t in texts)
    assert all(len(t) < 400 for t in texts)


def test_a_nan_handle_is_refused_with_nothing_moved(app: Pendant,
                                                    sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a = Page(app)
    try:
        a.click(app.controls.take)
        _until(lambda: app.controller == a.id, 5, "control")
        before = _snap(live)
        name = "/push_handle"
        a.send({"type": "TransformControlsDragStartMessage", "name": name})
        for _ in range(5):
            a.send({"type": "TransformControlsUpdateMessage", "name": name,
                    "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [math.nan, 0.0, 1.0]})
            time.sleep(0.05)
        _until(lambda: any(t.startswith("push refused") for t in app.told(a.id)), 5,
               "the refusal")
        a.send({"type": "TransformControlsDragEndMessage", "name": name})
        app.push(a.id, [math.nan, 0.0, 0.0])
        app.push(a.id, [1e6, 0.0, 0.0])
        app.adjust(a.id, mass=(math.nan, 1.0))
        app.adjust(a.id, frame="<script>")
        app.adjust(a.id, nonsense=1)
        assert sum("refused" in t for t in app.told(a.id)) >= 6
        time.sleep(0.2)
        after = _snap(live)
        assert after.refused == before.refused      # nothing reached the loop
        assert not after.push_base.any() and after.speed == 0.0
        assert np.allclose(after.transform_tool_to_base, before.transform_tool_to_base,
                           atol=1e-6)
        assert after.settings == before.settings
    finally:
        a.close()


def test_a_read_only_page_changes_no_setting(app: Pendant,
                                             sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a, b = Page(app), Page(app)
    try:
        a.click(app.controls.take)
        _until(lambda: app.controller == a.id, 5, "control")
        _until(lambda: 'data-state="IDLE"' in app.controls.status.content, 5,
               "the page's first update")
        b.click(app.controls.frame, "tool")
        _until(lambda: any("read-only" in t for t in app.told(b.id)), 5, "the refusal")
        _until(lambda: app.controls.frame.value == "base", 5, "the control to snap back")
        time.sleep(0.3)
        assert _snap(live).settings.frame == "base"
    finally:
        a.close()
        b.close()


def test_control_passes_when_the_controlling_page_disconnects(
        app: Pendant, sim: SimulatedPendantSession) -> None:
    live = sim.live
    app.start()
    a, b = Page(app), Page(app)
    try:
        held = _guiding(app, live, a)
        b.click(app.controls.take)
        _until(lambda: app.asking == b.id, 5, "the request")
        assert app.controller == a.id
        app.answer_control(b.id, True)              # only the page in control may answer
        assert app.controller == a.id
        held.stop()
        a.close()                                   # a goes: b gets control, disarmed
        _until(lambda: app.controller == b.id, 5, "control to pass to b")
        assert not app.armed
        _until(lambda: _snap(live).state == State.IDLE, 10, "IDLE")
        assert any("disconnected" in t for t in app.told(b.id))
    finally:
        b.close()


def test_exports_are_limited(app: Pendant, sim: SimulatedPendantSession) -> None:
    out = app.out
    app.take_control(1)
    assert app.export(2).startswith("not exported: this page is read-only")
    assert not out.exists()
    results: list[str] = []
    threads = [threading.Thread(target=lambda: results.append(app.export(1)))
               for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert sorted(r.split(":")[0] for r in results) == ["exported to " + str(out / "export-001"),
                                                       "not exported"]
    refused = next(r for r in results if r.startswith("not exported"))
    assert "under way" in refused or "apart" in refused
    assert app.export(1).startswith("not exported: exports are")
    assert sorted(p.name for p in out.iterdir()) == ["export-001"]
    app.export_interval_s, app.max_exports = 0.0, 2
    assert app.export(1).startswith("exported to")
    assert app.export(1).startswith("not exported: 2 exports is the most")
    assert sorted(p.name for p in out.iterdir()) == ["export-001", "export-002"]
    assert any(t.startswith("not exported: 2 exports") for t in app.told(1))


def test_text_on_the_page_is_escaped() -> None:
    shown = text_html([IMG, "a & b", RAPID])
    assert "<img" not in shown and "&lt;img src=x onerror=alert(1)&gt;" in shown
    assert "a &amp; b" in shown
    assert text_html([], empty="<b>none</b>").count("<b>") == 0


def test_an_oversize_snapshot_leaves_out_the_oldest_with_a_note() -> None:
    from leadthrough.control.guiding import GuidingConfig
    from leadthrough.pendant.messages import MarkedPoint
    marks = tuple(MarkedPoint(f"W{k}", float(k), np.zeros(6)) for k in range(5000))
    slow = SlowState("cause", GuidingConfig(), marks,
                     tuple(Notice(k, "info", "n" * 5000) for k in range(20)))
    full = len(slow.encode())
    blob, note = fit_slow(slow, 100_000)
    assert full > 100_000 >= len(blob)
    kept = SlowState.decode(blob)
    labels = [m.label for m in kept.marks]
    assert labels == [m.label for m in marks[-len(labels):]] and 0 < len(labels) < len(marks)
    assert note is not None and "oldest marks" in note
    assert fit_slow(SlowState("c", GuidingConfig()), 100_000)[1] is None


def test_the_help_states_the_limits(capsys: pytest.CaptureFixture[str]) -> None:
    from leadthrough.cli import main
    from leadthrough.pendant.app import EXPORT_INTERVAL_S, MAX_EXPORTS
    with pytest.raises(SystemExit):
        main(["pendant", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"Exports: one at a time, {EXPORT_INTERVAL_S:g} s apart, at most {MAX_EXPORTS} a run" \
        in text
    assert f"{1e3 * LEASE_S:.0f} ms without its heartbeat" in text
    assert "Take control" in text and "read-only" in text


def _dialog_button(app: Pendant, page: Page, label: str) -> Any:
    """A button of the dialog shown on ``page`` alone (found by its label, as the page
    shows it)."""
    gui = app.server.get_clients()[page.id].gui
    found = [h for h in gui._gui_input_handle_from_uuid.values()
             if getattr(h, "label", None) == label]
    assert len(found) == 1, label
    return found[0]


def test_the_page_in_control_confirms_a_hand_over(app: Pendant,
                                                  sim: SimulatedPendantSession) -> None:
    app.start()
    a, b = Page(app), Page(app)
    try:
        a.click(app.controls.take)
        _until(lambda: app.controller == a.id, 5, "control")
        b.click(app.controls.take)
        _until(lambda: app.asking == b.id, 5, "the request")
        a.click(_dialog_button(app, a, "Keep control"))         # on a's page only
        _until(lambda: app.asking is None, 5, "the answer")
        assert app.controller == a.id
        assert "the page in control kept control" in app.told(b.id)
        b.click(app.controls.take)
        _until(lambda: app.asking == b.id, 5, "the second request")
        a.click(_dialog_button(app, a, "Hand over control"))
        _until(lambda: app.controller == b.id, 5, "the hand-over")
        assert not app.armed and not _snap(sim.live).enabled
    finally:
        a.close()
        b.close()
