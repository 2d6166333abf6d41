"""The pendant's parts without a browser: the robot drawn from its URDF and posed by Pinocchio,
the status panel, the mouse's spring and the simulated hand, and ``leadthrough pendant``."""

from __future__ import annotations

import math
import socket
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from leadthrough.cli import main
from leadthrough.control import GuidingConfig
from leadthrough.control.safety import Fault, State
from leadthrough.estimation.estimator import EstimatorStatus
from leadthrough.pendant.backend import LoopSnapshot
from leadthrough.pendant.push import PushSpring
from leadthrough.pendant.robot_scene import RobotScene, link_meshes
from leadthrough.pendant.status_view import StatusExtras, status_html
from leadthrough.robot import Robot, load_robot
from leadthrough.sim.guiding_params import shipped_params_path
from leadthrough.sim.operator import HandPush


class _Node:
    def __init__(self, mesh: Any) -> None:
        self.mesh, self.position, self.wxyz = mesh, np.zeros(3), (1.0, 0.0, 0.0, 0.0)


class _Scene:
    """Records what a viser scene would be given."""

    def __init__(self) -> None:
        self.nodes: dict[str, _Node] = {}

    def add_mesh_trimesh(self, name: str, mesh: Any) -> _Node:
        self.nodes[name] = _Node(mesh)
        return self.nodes[name]


@pytest.mark.parametrize("name", ["er20", "ur5"])
def test_links_are_posed_by_pinocchio(name: str) -> None:
    robot = load_robot(name)
    scene = _Scene()
    view = RobotScene(scene, robot)
    q = np.random.default_rng(3).uniform(robot.lower_limits, robot.upper_limits)
    tcp = view.show(q)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    assert np.allclose(tcp, data.oMf[robot.tcp_frame_id].homogeneous, atol=1e-12)
    assert len(scene.nodes) >= robot.n
    for node_name, node in scene.nodes.items():
        placement = data.oMf[robot.model.getFrameId(node_name.split("/")[-1], pin.BODY)]
        w, x, y, z = node.wxyz
        assert np.allclose(node.position, placement.translation, atol=1e-12)
        assert np.allclose(pin.Quaternion(w, x, y, z).matrix(), placement.rotation, atol=1e-12)


def test_a_urdf_without_visuals_is_drawn_from_its_kinematics(er20: Robot) -> None:
    """Each limb of the er20 reaches from its link's origin to the next joint."""
    import yourdfpy
    meshes = {m.link: m.mesh for m in link_meshes(er20)}
    urdf = yourdfpy.URDF.load(str(er20.drive_file.urdf_path), load_meshes=False,
                              build_scene_graph=False)
    checked = 0
    for joint in urdf.robot.joints:
        end = joint.origin[:3, 3]
        if np.linalg.norm(end) > 1e-6 and joint.parent in meshes:
            lo, hi = meshes[joint.parent].bounds
            assert np.all(end >= lo - 1e-9) and np.all(end <= hi + 1e-9), joint.name
            checked += 1
    assert checked >= 5


def test_ur5_meshes_come_from_its_urdf() -> None:
    meshes = link_meshes(load_robot("ur5"))
    assert {"shoulder_link", "upper_arm_link", "forearm_link"} <= {m.link for m in meshes}
    upper = next(m.mesh for m in meshes if m.link == "upper_arm_link")
    assert upper.faces.shape[0] > 1000                     # the shipped mesh, not a cylinder


def _snapshot(state: State, **changes: Any) -> LoopSnapshot:
    snap = LoopSnapshot(time=12.3, q=np.zeros(6), transform_tool_to_base=np.eye(4),
                        wrench_base=np.array([3.0, -4.0, 0.0, 0, 0, 0]),
                        twist_base=np.array([0.06, 0.08, 0.0, 0, 0, 0]), state=state,
                        fault=Fault.NONE, cause="DEADMAN_PRESSED",
                        estimator=EstimatorStatus.OK, enabled=True,
                        settings=GuidingConfig(frame="tool",
                                               axes_enabled=(True,) * 3 + (False,) * 3),
                        marks=(), notices=())
    return replace(snap, **changes)


def test_status_shows_state_speed_force_and_axes() -> None:
    extras = StatusExtras(armed=True, device=True, push_n=np.array([0.0, 0.0, 30.0]),
                          period_us=(21.0, 80.0), params="shipped <er20>")
    text = status_html(_snapshot(State.GUIDING), extras)
    assert 'data-state="GUIDING"' in text and ">GUIDING<" in text
    assert ">100 mm/s<" in text                            # ‖(0.06, 0.08)‖
    assert ">5 N (+3, -4, +0)<" in text
    assert ">30 N<" in text
    assert "tool · x y z · · ·" in text
    assert "shipped &lt;er20&gt;" in text                  # escaped
    stopped = status_html(_snapshot(State.FAULT, error="RuntimeError: link lost"), extras)
    assert 'data-state="STOPPED"' in stopped and "link lost" in stopped
    assert 'data-state="STARTING"' in status_html(None, extras)


def test_status_on_a_robot_shows_its_enabling_input_and_the_fault() -> None:
    """On a robot (no device on the page) the enabling row is the controller's input as the
    loop reads it, and the latched fault stays shown once the session has stopped."""
    robot = StatusExtras(armed=False, device=None, push_n=None, period_us=(0.0, 0.0),
                         params="p")
    text = status_html(_snapshot(State.GUIDING, enabled=True), robot)
    assert ">controller&#x27;s enabling input pressed<" in text and "armed" not in text
    assert '<span id="lt-fault" style="font-weight:600">NONE<' in text
    released = status_html(_snapshot(State.IDLE, enabled=False), robot)
    assert ">controller&#x27;s enabling input released<" in released
    stopped = status_html(_snapshot(State.FAULT, fault=Fault.CONTROLLER_STATE,
                                    cause="CONTROLLER_STATE", error="stopped"), robot)
    assert 'data-state="STOPPED"' in stopped and ">CONTROLLER_STATE<" in stopped


def test_spring_damping_and_cap() -> None:
    spring = PushSpring(newton_per_cm=10.0, max_force_n=80.0, damping_ratio=0.7)
    assert spring.stiffness == 1000.0
    assert spring.damping(100.0) == pytest.approx(2 * 0.7 * math.sqrt(1000.0 * 100.0))
    hand = HandPush()
    spring.hold(hand, [0.0, 0.03, 0.0], 100.0)
    assert np.allclose(hand.wrench(0.0, np.zeros(3))[:3], [0.0, 30.0, 0.0])
    # moving towards the handle at 0.1 m/s: the damper takes c·v off
    w = hand.wrench(0.001, np.array([0.0, 1e-4, 0.0]))
    assert w[1] == pytest.approx(1000.0 * (0.03 - 1e-4) - spring.damping(100.0) * 0.1)
    spring.hold(hand, [0.5, 0.0, 0.0], 100.0)               # 500 N asked: capped
    w = hand.wrench(0.002, np.zeros(3))                     # (and back at 0.1 m/s along y)
    asked = np.array([500.0, spring.damping(100.0) * 0.1, 0.0])
    assert np.allclose(w[:3], 80.0 * asked / np.linalg.norm(asked), rtol=1e-12)
    assert np.array_equal(hand.force_base, w[:3])
    hand.release()
    assert not hand.wrench(0.003, np.zeros(3)).any()
    hand.push([1.0, 2.0, 3.0])
    assert np.array_equal(hand.wrench(0.004, np.zeros(3)), [1.0, 2.0, 3.0, 0.0, 0.0, 0.0])


def test_pendant_command_refuses_a_driver_it_does_not_have(capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    with pytest.raises(SystemExit) as e:      # argparse's choices: the three controllers
        main(["pendant", "--driver", "ur", "--host", "192.0.2.1"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--driver" in err and "'ur'" in err
    assert "ur-rtde" in err and "kuka-rsi" in err and "fanuc-j519" in err
    # the stop after letting go is the simulated session's setting here; guide has it for robots
    assert main(["pendant", "--driver", "ur-rtde", "--host", "192.0.2.1", "--params",
                 str(shipped_params_path("er20")), "--enable-input", "0",
                 "--hand-release"]) == 2
    err = capsys.readouterr().err
    assert "--hand-release" in err and "guide --driver D --hand-release" in err


def test_pendant_hand_release_reaches_the_simulated_session(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import leadthrough.pendant.simulated as simulated

    class RecordedError(Exception):
        pass

    seen: list[object] = []

    def record(*args: object, **kwargs: object) -> None:
        seen.append(kwargs["guiding"])
        raise RecordedError  # nothing is started

    monkeypatch.setattr(simulated, "simulated_session", record)
    for flags in ([], ["--hand-release"]):
        with pytest.raises(RecordedError):
            main(["pendant", *flags, "--duration", "0.1", "-o", str(tmp_path)])
    assert seen[0] is None       # the default: Table IV's settings with the paper's law alone
    assert isinstance(seen[1], GuidingConfig) and seen[1].hand_release.enabled
    assert replace(seen[1], hand_release=GuidingConfig().hand_release) == GuidingConfig()


def test_pendant_command_serves_the_simulator(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["pendant", "--port", str(port), "--duration", "1.5",
                 "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"http://127.0.0.1:{port}" in out
