"""``leadthrough pendant``: bad input is one line naming the option and the value, exit code 2,
no traceback, before the loop or the page's server starts (which would take seconds, and on a
bad port or address used to hang), and nothing written."""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from leadthrough.cli import build_parser, main
from leadthrough.cli.pendant_cmd import check_address, check_export_folder, run
from leadthrough.errors import DataError, MissingPackageError

SHIPPED = (Path(__file__).resolve().parent.parent / "src" / "leadthrough" / "sim" / "data"
           / "er20_seed1_guiding.toml")


def _refused(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """Run ``leadthrough pendant *argv`` in this process; it must exit 2 with one error line
    and no traceback, and start nothing. Returns that line."""
    assert main(["pendant", *argv]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "starting the loop" not in captured.out      # refused before any work
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("leadthrough: error:"), captured.err
    return lines[0]


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A port something listens on, on 127.0.0.1."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield int(s.getsockname()[1])


@pytest.mark.parametrize("port", ["-1", "70000", "65536"])
def test_port_out_of_range(capsys: pytest.CaptureFixture[str], port: str) -> None:
    err = _refused(capsys, "--port", port, "--duration", "2")
    assert "'--port'" in err and f"= {port}:" in err and "out of range" in err
    assert "65535" in err


@pytest.mark.parametrize("bind", ["999.1.1.1", "no.such.host.invalid", "192.0.2.1", " "])
def test_bind_not_an_address_of_this_machine(capsys: pytest.CaptureFixture[str],
                                             bind: str) -> None:
    err = _refused(capsys, "--bind", bind, "--duration", "2")
    assert "'--bind'" in err and repr(bind) in err and "address of this machine" in err


@pytest.mark.parametrize("duration", ["nan", "-1", "0", "inf"])
def test_duration_finite_and_positive(capsys: pytest.CaptureFixture[str],
                                      duration: str) -> None:
    err = _refused(capsys, "--duration", duration)
    assert "'--duration'" in err and f"= {float(duration)!r}:" in err
    assert "finite, > 0" in err and "until Ctrl-C" in err


@pytest.mark.parametrize("record_s", ["-5", "0", "nan", "1e9"])
def test_record_s_out_of_range(capsys: pytest.CaptureFixture[str], record_s: str) -> None:
    err = _refused(capsys, "--record-s", record_s, "--duration", "1")
    assert "'--record-s'" in err and f"= {float(record_s)!r}:" in err
    assert "0 < seconds <= 3600" in err


@pytest.mark.parametrize("priority", ["500", "0", "-3", "100"])
def test_rt_priority_out_of_range(capsys: pytest.CaptureFixture[str], priority: str) -> None:
    err = _refused(capsys, "--rt-priority", priority, "--duration", "1")
    assert "'--rt-priority'" in err and f"= {priority}:" in err and "1..99" in err


def test_output_an_existing_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    params = tmp_path / "params.toml"
    params.write_text("x = 1\n")
    err = _refused(capsys, "-o", str(params), "--duration", "1")
    assert "'-o'" in err and repr(str(params)) in err and "not a folder" in err
    assert params.read_text() == "x = 1\n"


def test_output_a_file_name(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "points.json"
    err = _refused(capsys, "-o", str(out), "--duration", "1")
    assert "'-o'" in err and repr(str(out)) in err and "a folder" in err
    assert not out.exists()


def test_output_in_a_missing_folder(capsys: pytest.CaptureFixture[str],
                                    tmp_path: Path) -> None:
    out = tmp_path / "nope" / "x" / "y"
    err = _refused(capsys, "-o", str(out), "--duration", "1")
    assert "'-o'" in err and repr(str(out)) in err and "parent folder does not exist" in err
    assert not (tmp_path / "nope").exists()                  # nothing made


def test_output_folder_accepted(tmp_path: Path) -> None:
    check_export_folder(tmp_path)                               # an existing folder
    check_export_folder(tmp_path / "taught")                    # a new one, made on export
    (tmp_path / "run.2026").mkdir()
    check_export_folder(tmp_path / "run.2026")                  # a folder with a dot
    assert not (tmp_path / "taught").exists()
    with pytest.raises(DataError, match="'-o'"):
        check_export_folder(tmp_path / "a" / "b")


def test_explicit_port_in_use(capsys: pytest.CaptureFixture[str], busy_port: int) -> None:
    err = _refused(capsys, "--port", str(busy_port), "--duration", "1")
    assert "'--port'" in err and f"= {busy_port}:" in err and "port in use" in err
    assert "a free port" in err


def test_address_and_free_port_accepted(busy_port: int) -> None:
    check_address("127.0.0.1", None)
    check_address("127.0.0.1", 0)
    check_address("localhost", None)        # a busy default port: viser takes the next one
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        free = int(s.getsockname()[1])
    check_address("127.0.0.1", free)


@pytest.mark.parametrize("seed", ["-1", "-100"])
def test_seed_out_of_range(capsys: pytest.CaptureFixture[str], seed: str) -> None:
    err = _refused(capsys, "--seed", seed, "--duration", "1")
    assert "'--seed'" in err and f"= {seed}:" in err and "out of range" in err
    assert ">= 0" in err and "another simulated robot" not in err


@pytest.fixture
def bare_params(tmp_path: Path) -> Path:
    """The shipped guiding parameters of the simulated er20 without their friction sweep."""
    text = SHIPPED.read_text()
    assert "friction_sweep = true" in text
    bare = tmp_path / "bare.toml"
    bare.write_text(text.replace("friction_sweep = true", ""))
    return bare


def test_params_without_a_friction_sweep(capsys: pytest.CaptureFixture[str],
                                         bare_params: Path) -> None:
    err = _refused(capsys, "--params", str(bare_params), "--duration", "1")
    assert "bare.toml" in err and "'meta.friction_sweep' = False" in err
    assert "--allow-no-sweep" in err and "--friction-sweep" in err


def test_allow_no_sweep_passes_the_sweep_check(capsys: pytest.CaptureFixture[str],
                                               bare_params: Path) -> None:
    # past the sweep check, the next one refuses: another instance than the params' (seed 1)
    err = _refused(capsys, "--params", str(bare_params), "--allow-no-sweep", "--seed", "2",
                   "--duration", "1")
    assert "friction_sweep" not in err and "'--seed' = 2" in err


@pytest.mark.parametrize("argv", [["--port", "-1"], ["--bind", "999.1.1.1"],
                                  ["--duration", "nan"]])
def test_console_script_exits_2_at_once(argv: list[str]) -> None:
    # these used to hang (a traceback in viser's thread, or an endless run)
    proc = subprocess.run([sys.executable, "-m", "leadthrough", "pendant", *argv,
                           "--duration" if argv[0] != "--duration" else "--record-s", "2"],
                          capture_output=True, text=True, check=False, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "starting the loop" not in proc.stdout
    assert f"'{argv[0]}'" in proc.stderr and argv[1] in proc.stderr


def test_a_missing_web_stack_names_the_extra(capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the pendant's extra (its import fails) the command exits 2 with one line that
    says how to install it, raised as MissingPackageError, before anything starts."""
    monkeypatch.setitem(sys.modules, "leadthrough.pendant.app", None)
    line = _refused(capsys, "--port", "0")
    assert "web stack is not installed" in line
    assert "pip install 'leadthrough[pendant]'" in line
    with pytest.raises(MissingPackageError, match="extra"):
        run(build_parser().parse_args(["pendant", "--port", "0"]))


# ------------------------------------------------------------------ on a robot (--driver)
ROBOT = ["--driver", "ur-rtde", "--host", "127.0.0.1", "--params", str(SHIPPED)]


def test_a_robot_needs_its_enabling_input(capsys: pytest.CaptureFixture[str]) -> None:
    """As ``guide --driver``: the same error, naming ``--enable-input``."""
    err = _refused(capsys, *ROBOT, "--duration", "1")
    assert "'--enable-input'" in err and "no enabling device" in err
    assert "the controller's digital input wired to the enabling device" in err


@pytest.mark.parametrize(("drop", "option"), [("--host", "'--host'"),
                                              ("--params", "'--params'")])
def test_a_robot_needs_its_address_and_parameters(capsys: pytest.CaptureFixture[str],
                                                  drop: str, option: str) -> None:
    i = ROBOT.index(drop)
    argv = ROBOT[:i] + ROBOT[i + 2:]
    err = _refused(capsys, *argv, "--enable-input", "0", "--duration", "1")
    assert option in err and "a robot needs" in err


@pytest.mark.parametrize(("extra", "expected"), [
    (["--enable-input", "0", "--reset-input", "0"], "'loop.reset_input' = 0"),
    (["--enable-input", "1", "--mark-input", "1"], "'loop.mark_input' = 1"),
    (["--enable-input", "64"], "'loop.enable_input' = 64"),
    (["--enable-input", "0", "--watchdog", "nan"], "'loop.watchdog_s' = nan"),
    (["--enable-input", "0", "--watchdog", "-0.1"], "'loop.watchdog_s' = -0.1"),
    (["--enable-input", "0", "--controller-port", "70000"], "'--controller-port' = 70000"),
    (["--enable-input", "0", "--controller-port", "0"], "'--controller-port' = 0"),
    (["--enable-input", "0", "--robot-address", "127.0.0.2"], "only for kuka-rsi"),
    (["--enable-input", "0", "--seed", "3"], "'--seed' = 3"),
    (["--enable-input", "0", "--hand-release"], "'--hand-release' = True"),
])
def test_a_robot_sessions_options_are_checked(capsys: pytest.CaptureFixture[str],
                                              extra: list[str], expected: str) -> None:
    """The inputs and the watchdog as ``guide --driver`` checks them (the loop's options),
    the controller's port, and no simulator setting: each refused before anything connects."""
    err = _refused(capsys, *ROBOT, *extra, "--duration", "1")
    assert expected in err, err


@pytest.mark.parametrize("option", [["--enable-input", "0"], ["--mark-input", "1"],
                                    ["--reset-input", "2"], ["--watchdog", "0.5"],
                                    ["--host", "127.0.0.1"], ["--controller-port", "30004"],
                                    ["--robot-address", "127.0.0.2"]])
def test_a_robots_options_on_the_simulator(capsys: pytest.CaptureFixture[str],
                                           option: list[str]) -> None:
    """On the simulator the page is the enabling device: a robot's option is refused, not
    ignored."""
    err = _refused(capsys, *option, "--duration", "1")
    assert f"'{option[0]}'" in err and "setting of a robot session" in err


def test_a_robots_parameters_need_their_sweep(capsys: pytest.CaptureFixture[str],
                                              bare_params: Path) -> None:
    err = _refused(capsys, "--driver", "fanuc-j519", "--host", "127.0.0.1", "--params",
                   str(bare_params), "--enable-input", "0", "--duration", "1")
    assert "'meta.friction_sweep' = False" in err and "--allow-no-sweep" in err


def test_a_robot_session_runs_the_guide_loops_recipe(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path) -> None:
    """A good robot command builds the loop of ``guide --driver`` (a DriverRecipe) with the
    controller's port, the inputs and ``guide``'s watchdog default; the page's --port is not
    the controller's."""
    import leadthrough.cli.pendant_cmd as pendant_cmd
    from leadthrough.cli.guide_robot import DEFAULT_WATCHDOG_S
    from leadthrough.pendant.loop_process import DriverRecipe

    class BuiltError(Exception):
        pass

    seen: list[tuple[object, dict[str, object]]] = []

    def live_session(recipe: object, robot: object, **kwargs: object) -> None:
        seen.append((recipe, kwargs))
        raise BuiltError

    monkeypatch.setattr(pendant_cmd, "LiveSession", live_session)
    base = ["pendant", "--host", "127.0.0.5", "--params", str(SHIPPED), "--port", "0",
            "--enable-input", "0", "--mark-input", "1", "-o", str(tmp_path)]
    with pytest.raises(BuiltError):
        main([*base, "--driver", "ur-rtde", "--controller-port", "30010", "--reset-input",
              "2", "--rt-priority", "20"])
    with pytest.raises(BuiltError):
        main([*base, "--driver", "kuka-rsi", "--robot-address", "127.0.0.6:49200",
              "--watchdog", "2"])
    (ur, ur_kwargs), (rsi, _) = seen
    assert isinstance(ur, DriverRecipe) and isinstance(rsi, DriverRecipe)
    assert (ur.driver, ur.host, ur.port, ur.robot_address) == ("ur-rtde", "127.0.0.5", 30010,
                                                               None)
    assert (ur.options.enable_input, ur.options.mark_input, ur.options.reset_input) == (0, 1, 2)
    assert ur.options.watchdog_s == DEFAULT_WATCHDOG_S and ur.options.abort_s == 1.0
    assert ur.params.friction_sweep and ur_kwargs["rt_priority"] == 20
    assert (rsi.driver, rsi.port, rsi.robot_address) == ("kuka-rsi", None, "127.0.0.6:49200")
    assert rsi.options.watchdog_s == 2.0 and rsi.options.abort_s == 2.0
    assert rsi.options.reset_input is None
