"""The pendant in a real browser (Chromium driven by Playwright), on the simulated robot.

An operator's session end to end: open the page (its URL carries the run's token), take
control, arm guiding and hold the (simulated) hold-to-run enabling device with the mouse: GUIDING
while held, the commanded stop when let go; drag the push handle at the tool with the mouse while
the operator's other hand holds the device (a second pointer) and see the robot follow and the
state change, mark P1 and P2, export, and take a screenshot; then hold the device and let the
page lose focus: the page guard lets go of the button, and the release stops the robot.

Chromium: Debian's ``/usr/bin/chromium`` (``.ci/run`` installs it), never a browser downloaded
by Playwright. Without it (or without the ``playwright`` package) the test **fails when the
environment variable ``CI`` is set** (CI must run it) and is skipped with the reason otherwise
(a developer's machine without a browser). ``LEADTHROUGH_DOCS_SCREENSHOT=1`` also writes the
screenshot to ``docs/pendant.png`` (the README's).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from leadthrough.control.safety import State
from leadthrough.pendant.app import Pendant, wait_for_clients
from leadthrough.pendant.controls import DEVICE_LABEL, HOLD_HZ
from leadthrough.pendant.messages import LEASE_S
from leadthrough.pendant.simulated import SimulatedPendantSession, simulated_session
from leadthrough.robot import Robot

DOCS_SHOT = Path(__file__).resolve().parent.parent / "docs" / "pendant.png"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def _chromium() -> str:
    """Debian's Chromium and Playwright, or fail (CI) / skip (elsewhere) saying what is
    missing."""
    missing = []
    path = shutil.which("chromium") or ("/usr/bin/chromium"
                                        if Path("/usr/bin/chromium").exists() else None)
    if path is None:
        missing.append("Chromium (apt-get install chromium)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (pip install -e '.[pendant]')")
    if missing:
        message = "the browser test needs " + " and ".join(missing)
        if os.environ.get("CI"):
            pytest.fail(message + " (CI is set: the test must run there)")
        pytest.skip(message)
    assert path is not None
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _until(condition: Callable[[], bool], timeout_s: float,
           what: str | Callable[[], str]) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            said = what if isinstance(what, str) else what()
            pytest.fail(f"timed out after {timeout_s} s waiting for {said}")
        time.sleep(0.05)


def _loop_state(app: Pendant) -> str:
    """The loop's state, cause, enabling and latest notices, for a failure's message."""
    snap = app.live.snapshot()
    if snap is None:
        return "no snapshot"
    return (f"{snap.state.name}, {snap.cause!r}, enabled {snap.enabled}, lapsed {snap.lapsed}, "
            f"force {snap.wrench_base[:3].round(1)}, "
            f"notices {[n.text for n in snap.notices[-4:]]}, "
            f"page told {app.told(app.controller or 0)[-3:]}")


def _at_rest(app: Pendant, hold_s: float, timeout_s: float) -> None:
    """Until the commanded speed has been 0 for ``hold_s``."""
    deadline = time.monotonic() + timeout_s
    since = time.monotonic()
    while time.monotonic() - since < hold_s:
        if time.monotonic() > deadline:
            pytest.fail(f"the robot did not come to rest within {timeout_s} s")
        time.sleep(0.05)
        if app.live.snapshot().speed != 0.0:
            since = time.monotonic()


def _screen(camera: Any, point: np.ndarray) -> tuple[float, float]:
    """Pixel of a world point [m] in the browser's view (viser's camera: OpenCV axes, +z
    forward, +y down; ``fov`` vertical)."""
    w, x, y, z = camera.wxyz
    p = Rotation.from_quat([x, y, z, w]).as_matrix().T @ (point - camera.position)
    f = 0.5 * camera.image_height / np.tan(0.5 * camera.fov)
    return (0.5 * camera.image_width + f * p[0] / p[2],
            0.5 * camera.image_height + f * p[1] / p[2])


@pytest.fixture
def pendant(er20: Robot, tmp_path: Path) -> Iterator[tuple[Pendant, SimulatedPendantSession]]:
    sim = simulated_session(er20)
    sim.live.start()
    app = Pendant(sim.live, tmp_path / "out", hand=sim.hand, port=_free_port(),
                  params_note=sim.params_note)
    app.start()
    try:
        yield app, sim
    finally:
        app.stop()
        sim.live.stop()


@pytest.mark.exclusive
def test_operator_session_in_chromium(pendant: tuple[Pendant, SimulatedPendantSession],
                                      tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright
    chromium = _chromium()
    app, sim = pendant
    live = sim.live
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            console: list[str] = []
            page.on("console", lambda m: console.append(f"{m.type}: {m.text}"))
            page.on("pageerror", lambda e: console.append(f"page error: {e}"))
            page.on("crash", lambda _: console.append("the page crashed"))
            page.goto(app.url)
            if not wait_for_clients(app):
                with contextlib.suppress(Exception):     # (a crashed page takes none)
                    page.screenshot(path=str(tmp_path / "not-connected.png"))
                pytest.fail(f"the page did not connect within 30 s; its console: {console}")
            state = page.locator("#lt-state")
            _until(lambda: state.get_attribute("data-state") == "IDLE", 30, "IDLE on the page")
            _until(lambda: live.snapshot().estimator.name == "OK", 10, "the estimator's tare")
            _dismiss_notifications(page)        # (a click: not while dragging)

            assert page.evaluate("window.__leadthroughPageGuard === true"), \
                "the page guard is not on the served page"
            page.get_by_role("button", name="Take control").click()
            _until(lambda: app.controller is not None, 5, "control")
            page.get_by_role("button", name="Arm guiding").click()
            _until(lambda: app.armed, 5, "armed")
            device = page.get_by_role("button", name=DEVICE_LABEL)

            # hold-to-run with the mouse: GUIDING while held, the commanded stop on letting go.
            # (Headless Chromium rendering the scene on the CPU stalls its timers by up to
            # 0.36 s on a loaded 2-core machine: there a held device is released by a missed
            # heartbeat, and the page asks to let go and press again, as the operator does.)
            _hold_until_guiding(page, device, app, state)
            page.mouse.up()
            _until(lambda: not live.snapshot().enabled, 5, "the release on letting go")
            _until(lambda: state.get_attribute("data-state") == "IDLE", 10, "STOPPING -> IDLE")
            _stays_released(live, 0.6)
            _dismiss_notifications(page)

            # the operator's other hand holds the device while the mouse drags the handle (a
            # page has one mouse). Not the page's own heartbeat here: while the mouse drags,
            # headless Chromium renders the scene on the CPU, and on a loaded 2-core machine
            # its timers stalled for 0.2-1 s (2026-12-07: the page's heartbeat lapsed 29 times
            # in 8 s of dragging at the 200 ms lease, twice at a 1 s lease; a lapse is a
            # commanded stop, and guiding does not resume under the hand's push). So the
            # other hand is the pendant's own hold_device at the page's rate, with a 1 s
            # lease; the page's hold-to-run is the mouse's above and below, and the 200 ms
            # lease is tested with real pages in test_pendant_control.py.
            app.lease_s = 1.0
            other_hand = _OtherHand(app)
            _until(lambda: state.get_attribute("data-state") == "GUIDING", 10, "GUIDING")
            page.get_by_role("button", name="P1", exact=True).click()
            _until(lambda: "P1" in [p.label for p in app.points.points], 5,
                   lambda: f"P1 marked ({_loop_state(app)})")

            start = app.scene.tcp_m.copy()
            _drag_handle(page, app, start, np.array([0.0, 1.0, 0.0]), 0.25)
            moved = float(np.linalg.norm(app.scene.tcp_m - start))
            assert moved > 0.05, f"the robot moved {moved * 1e3:.0f} mm under the mouse's push"

            # P2 is marked with the hand still on the tool and the enabling device released
            # (the operator's other hand lets go of it): the robot held by its controller,
            # where the hand took it. Marked while guiding under the hand's push, P2 raced the
            # law at rest: there the force estimate drifts up under a steady hand (10 N held
            # read 8 -> 24 N within 2 s) and the tool creeps on by 0.1-1 mm every 1.5-2 s, or
            # by more once the settling window (settle_s: the stopping friction after a stop)
            # ends with the hand still pushing more than δ (CI on 21b3b96: stopped with the
            # spring at about 26 N, the tool went on 5.6 mm between the page's TCP at the
            # click and the mark). That is the law's behaviour at rest (issue 24), not the
            # pendant's; P1 is marked while guiding.
            _at_rest(app, 0.5, 10)
            other_hand.let_go()                  # (the mouse stays down on the handle)
            app.lease_s = LEASE_S
            _until(lambda: state.get_attribute("data-state") == "IDLE", 10, "STOPPING -> IDLE")
            _at_rest(app, 0.5, 10)
            at_p2 = app.scene.tcp_m.copy()
            page.get_by_role("button", name="P2", exact=True).dispatch_event("click")
            _until(lambda: "P2" in [p.label for p in app.points.points], 5, "P2 marked")
            _let_go(page, app)
            assert live.snapshot().state == State.IDLE

            page.get_by_role("button", name="Export").click()
            _until(lambda: (tmp_path / "out" / "export-001" / "path.json").exists(), 20,
                   "the export")
            page.screenshot(path=str(tmp_path / "after-export.png"))

            # held, then the page loses focus: the guard lets go, the release stops the robot
            _dismiss_notifications(page)
            lapsed = live.snapshot().lapsed
            _hold_until_guiding(page, device, app, state)
            page.evaluate("window.dispatchEvent(new FocusEvent('blur'))")
            _until(lambda: not live.snapshot().enabled, 5, "the release on losing focus")
            _until(lambda: live.snapshot().state == State.IDLE, 10, "the stop to IDLE")
            assert live.snapshot().lapsed > lapsed or any(
                "no heartbeat" in t for t in app.told(app.controller or 0))
            _stays_released(live, 1.0)        # the mouse still down: no heartbeat any more
            page.mouse.up()
        finally:
            browser.close()
    _check_export(tmp_path / "out" / "export-001", start, at_p2)


def _stays_released(live: Any, for_s: float) -> None:
    """The enabling input stays released for ``for_s`` (the page sends no heartbeat)."""
    deadline = time.monotonic() + for_s
    while time.monotonic() < deadline:
        snap = live.snapshot()
        assert not snap.enabled and snap.state != State.GUIDING, "pressed again"
        time.sleep(0.02)


def _press(page: Any, button: Any) -> None:
    """The mouse down on ``button`` (and held there)."""
    box = button.bounding_box()
    assert box is not None
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()


def _hold_until_guiding(page: Any, device: Any, app: Pendant, state: Any,
                        presses: int = 3) -> None:
    """Hold the device with the mouse until the page shows GUIDING. A heartbeat that the
    page's stalled timers missed releases the device for good: the page then asks to let go
    and press again, and the operator does (at most ``presses`` presses in all)."""
    for _ in range(presses):
        _press(page, device)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            if state.get_attribute("data-state") == "GUIDING":
                return
            if app.needs_fresh_press:
                break
            time.sleep(0.05)
        else:
            pytest.fail(f"not GUIDING within 10 s of pressing ({_loop_state(app)})")
        page.mouse.up()                      # let go (the page's click), then press anew
        time.sleep(0.2)
    pytest.fail(f"a heartbeat lapsed on each of {presses} presses")


class _OtherHand:
    """The operator's other hand on the enabling device: the controlling page's heartbeat at
    the page's rate, from this process, until :meth:`let_go`."""

    def __init__(self, app: Pendant) -> None:
        self.app, self.page = app, app.controller
        assert self.page is not None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(1.0 / HOLD_HZ):
            self.app.hold_device(self.page)     # type: ignore[arg-type]

    def let_go(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.app.release_device(self.page)      # type: ignore[arg-type]


def _drag_handle(page: Any, app: Pendant, tcp: np.ndarray, axis: np.ndarray,
                 distance_m: float) -> None:
    """Drag the push handle's ``axis`` arrow by ``distance_m``, hold until the robot has come
    to rest near it, take the screenshot; the mouse stays down (:func:`_let_go`)."""
    camera = next(iter(app.server.get_clients().values())).camera
    grab = _screen(camera, tcp + 0.14 * axis)        # on the arrow (the gizmo is 0.2 m)
    to = _screen(camera, tcp + (0.14 + distance_m) * axis)
    page.mouse.move(*grab)
    page.mouse.down()
    page.mouse.move(*to, steps=5)
    _until(lambda: app.scene.dragging and app.hand is not None
           and bool(app.hand.force_base.any()), 5, "the drag to push the simulated tool")
    _until(lambda: app.live.snapshot().speed > 0.05, 8,
           lambda: f"the robot to follow the push ({_loop_state(app)})")
    page.screenshot(path=str(_shot_path(app)))        # under way
    _at_rest(app, 0.5, 15)                           # stopped at the handle


def _let_go(page: Any, app: Pendant) -> None:
    """Let go of the handle: the mouse up, the end of the drag, no force from the hand."""
    page.mouse.up()
    _until(lambda: not app.scene.dragging, 5, "the end of the drag")
    # the page's next update lets go, the loop's next cycle applies it (a fixed 0.1 s was too
    # short on a loaded CI runner: CI on 3494f0f still saw the hand's 20.6 N)
    _until(lambda: app.hand is not None and not app.hand.force_base.any(), 5,
           "the hand to let go")


def _shot_path(app: Pendant) -> Path:
    if os.environ.get("LEADTHROUGH_DOCS_SCREENSHOT"):
        return DOCS_SHOT
    return app.out.parent / "pendant.png"


def _dismiss_notifications(page: Any) -> None:
    """Close the browser's "software WebGL" notice (headless Chromium renders on the CPU)."""
    for button in page.locator(".mantine-Notification-closeButton").all():
        button.click()
    time.sleep(0.5)


def _check_export(folder: Path, at_p1: np.ndarray, at_p2: np.ndarray) -> None:
    """The export holds the session, the two points where the robot stood when they were
    marked (the page's TCP when the button was pressed, the robot at rest: within 2 mm), and
    the welding line between them."""
    assert (folder / "session.parquet").is_file()
    points = json.loads((folder / "points.json").read_text())["points"]
    assert [p["label"] for p in points] == ["P1", "P2"]
    p1, p2 = (np.array(p["tcp_position_m"]) for p in points)
    assert np.linalg.norm(p1 - at_p1) < 0.002
    assert np.linalg.norm(p2 - at_p2) < 0.002
    line = json.loads((folder / "path.json").read_text())["welding_line"]
    assert (line["start_label"], line["end_label"]) == ("P1", "P2")
    assert line["length_m"] > 0.15
    assert abs(line["length_m"] - np.linalg.norm(p2 - p1)) < 0.01



@pytest.mark.exclusive
def test_a_robot_session_shows_the_controllers_input_and_its_fault_in_chromium(
        er20: Robot, tmp_path: Path) -> None:
    """The pendant on a robot: ``leadthrough emulate ur-rtde`` in its own process, the loop of
    ``pendant --driver ur-rtde`` (a DriverRecipe) in the pendant's loop process. The page has
    no hold-to-run device and shows the controller's enabling input as the loop reads it:
    pressed (the emulator's input held from its start), not GUIDING all the same (held since
    before the loop was ready: no fresh press). Then the controller goes (its process killed:
    its TCP connection closed, at a time the test chooses): FAULT with the fault latched
    shown, the notice naming the lost link,
    and once the session has ended, STOPPED with the fault still shown. (The page's state
    and fault are the controller's latched ones: the last snapshot of a loop ended by a lost
    link showed IDLE and no fault before.)"""
    from playwright.sync_api import sync_playwright

    from leadthrough.drivers.controllers import DEFAULT_PORTS
    from leadthrough.identification.params_file import load_params
    from leadthrough.pendant.backend import LiveSession
    from leadthrough.pendant.loop_process import DriverRecipe
    from leadthrough.robot.poses import guide_start_pose
    from leadthrough.session.loop_config import LoopOptions
    from leadthrough.sim.guiding_params import shipped_params_path
    from wire_helpers import free_loopback_address, spawn_emulator, stop_process

    chromium = _chromium()
    port = DEFAULT_PORTS["ur-rtde"]
    host = free_loopback_address(port)
    emu = spawn_emulator("ur-rtde", "er20", host, port, "--seed", "1", "--q0",
                         *map(str, guide_start_pose(er20)), "--watchdog", "0.5",
                         "--enable", "0:inf")
    recipe = DriverRecipe(er20, load_params(shipped_params_path("er20"), er20), "ur-rtde",
                          host, options=LoopOptions(enable_input=0, mark_input=1,
                                                    watchdog_s=0.5, abort_s=1.0))
    live = LiveSession(recipe, er20, record_s=30.0)
    app = None
    report = ""
    try:
        live.start(timeout_s=120.0)
        app = Pendant(live, tmp_path / "out", port=_free_port(), params_note="shipped")
        app.start()
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url)
                assert wait_for_clients(app), "the page did not connect within 30 s"
                state, enable = page.locator("#lt-state"), page.locator("#lt-enable")
                fault = page.locator("#lt-fault")
                _until(lambda: enable.count() == 1 and enable.inner_text()
                       == "controller's enabling input pressed", 30,
                       lambda: f"the input pressed on the page ({_loop_state(app)})")
                _until(lambda: live.snapshot().estimator.name == "OK", 10,  # type: ignore[union-attr]
                       "the estimator's tare")
                time.sleep(0.5)         # ready, the input held: still no guiding
                # (IDLE, or FAULT where the machine's load stalled the 2 ms stream: a stale
                # sample, as on a real controller; the link's end below shows either way)
                assert state.get_attribute("data-state") in ("IDLE", "FAULT"), _loop_state(app)
                assert page.get_by_role("button", name=DEVICE_LABEL).count() == 0
                report = stop_process(emu)             # the controller is gone
                _until(lambda: state.get_attribute("data-state") in ("FAULT", "STOPPED"), 15,
                       lambda: f"FAULT on the page ({_loop_state(app)})")
                _until(lambda: fault.inner_text() in LINK_FAULTS, 10,
                       lambda: f"the link's fault on the page ({_loop_state(app)})")
                _until(lambda: "link lost: DriverError" in page.inner_text("body"), 10,
                       "the notice naming the lost link")
                if live.running:                # (a second failure ends it: the link lost)
                    live.stop(timeout_s=20.0)
                _until(lambda: state.get_attribute("data-state") == "STOPPED", 15,
                       lambda: f"STOPPED on the page ({_loop_state(app)})")
                assert fault.inner_text() in LINK_FAULTS    # still shown, stopped
                page.screenshot(path=str(tmp_path / "robot-fault.png"))
            finally:
                browser.close()
    finally:
        if app is not None:
            app.stop()
        live.close()
        if not report:
            report = stop_process(emu)
    assert "violations: ()" in report, report


#: What a controller gone shows as: its socket's error, or silence.
LINK_FAULTS = ("DRIVER_ERROR", "DRIVER_TIMEOUT", "STALE_FEEDBACK")
