"""``leadthrough emulate``: bad input is refused before the emulator starts, with exit code 2
and one line naming the option, the value and what is expected (no traceback)."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys

import pytest

from leadthrough.cli import build_parser, main
from leadthrough.cli.emulate_cmd import check_arguments

# in case a check ever lets a case through: a short run on a free port, not one forever
_SAFE = {"fanuc-j519": ["--port", "0"], "ur-rtde": ["--robot", "ur5", "--port", "0"],
         "kuka-rsi": []}


def _emulate(kind: str, *args: str) -> tuple[int, str]:
    """``leadthrough emulate KIND ...`` in this process: exit code and stderr (an exception
    that escapes ``main`` fails the test, as a traceback would)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(["emulate", kind, *_SAFE[kind], "--duration", "1", *args])
        except SystemExit as e:  # argparse's usage errors
            code = int(e.code or 0)
    return code, err.getvalue()


def _refused(kind: str, args: list[str], *names: str) -> str:
    code, err = _emulate(kind, *args)
    assert code == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("leadthrough: error:"), err
    for name in names:
        assert name in last, (name, last)
    assert "expected" in last, last
    return last


@pytest.mark.parametrize(("kind", "port", "range_"), [
    ("ur-rtde", "-1", "3-65535"), ("ur-rtde", "1", "3-65535"),
    ("fanuc-j519", "70000", "1-65535"), ("fanuc-j519", "-5", "1-65535"),
    ("kuka-rsi", "0", "1-65535"), ("kuka-rsi", "65536", "1-65535")])
def test_port_out_of_range_exits_2_naming_port_value_and_range(kind: str, port: str,
                                                               range_: str) -> None:
    _refused(kind, ["--port=" + port], "'--port'", f"= {port}", range_)


@pytest.mark.parametrize(("option", "value"), [
    ("--enable", "5:1"), ("--enable", "nan:1"), ("--enable", "1:nan"), ("--enable", "inf:inf"),
    ("--enable", "-1:2"), ("--mark", "5:1"), ("--mark", "3:3"), ("--reset", "nan:"),
    ("--loss-burst", "2:1"), ("--late", "2:1"), ("--nan", "-inf:1")])
def test_bad_window_exits_2_naming_option_and_value(option: str, value: str) -> None:
    last = _refused("ur-rtde", [f"{option}={value}"], f"'{option}'", repr(value))
    assert "0 <= START < END" in last


def test_unparsable_window_is_a_usage_error() -> None:
    code, err = _emulate("ur-rtde", "--enable", "1:x")
    assert code == 2 and "Traceback" not in err
    assert "--enable" in err and "'1:x'" in err and "START:END" in err


@pytest.mark.parametrize(("option", "value"), [
    ("--duration", "-1"), ("--duration", "0"), ("--duration", "nan"), ("--duration", "inf"),
    ("--duration", "1e300"), ("--close-at", "-1"), ("--close-at", "nan"),
    ("--estop-at", "-0.5"), ("--protective-stop-at", "inf")])
def test_bad_duration_or_event_time_exits_2(option: str, value: str) -> None:
    last = _refused("fanuc-j519", [f"{option}={value}"], f"'{option}'")
    assert f"= {float(value)!r}" in last
    if option == "--duration":
        assert "> 0" in last and "Ctrl-C" in last  # and no --duration runs until stopped


@pytest.mark.parametrize(("option", "value"), [
    ("--watchdog", "nan"), ("--watchdog", "0"), ("--loss-rate", "1.5"), ("--loss-rate", "nan"),
    ("--seed", "-1")])
def test_other_out_of_range_values_name_the_option(option: str, value: str) -> None:
    _refused("ur-rtde", [f"{option}={value}"], f"'{option}'", value)


@pytest.mark.parametrize(("kind", "args", "names"), [
    ("fanuc-j519", ["--cb3"], ("'--cb3'", "fanuc-j519", "ur-rtde")),
    ("kuka-rsi", ["--cb3"], ("'--cb3'", "kuka-rsi", "ur-rtde")),
    ("ur-rtde", ["--cb3", "--cycle-ms", "2"], ("'--cycle-ms' = 2", "--cb3", "8")),
    ("ur-rtde", ["--cycle-ms", "8"], ("'--cycle-ms' = 8", "ur-rtde", "--cb3")),
    ("kuka-rsi", ["--cycle-ms", "2"], ("'--cycle-ms' = 2", "kuka-rsi", "4 or 12")),
    ("fanuc-j519", ["--cycle-ms", "12"], ("'--cycle-ms' = 12", "fanuc-j519", "8 or 4")),
    ("ur-rtde", ["--late-by", "0.1"], ("'--late-by' = 0.1", "--late ")),
    ("ur-rtde", ["--operator-seed", "3"], ("'--operator-seed' = 3", "--operator ")),
    ("ur-rtde", ["--operator-delay", "1"], ("'--operator-delay' = 1.0", "--operator "))])
def test_contradictory_options_exit_2_naming_both(kind: str, args: list[str],
                                                  names: tuple[str, ...]) -> None:
    _refused(kind, args, *names)


@pytest.mark.parametrize(("host", "why"), [
    ("192.0.2.1", "cannot bind"),              # TEST-NET-1: not an address of this machine
    ("no-such-host.invalid", "cannot resolve")])
def test_unusable_host_names_host_not_port(host: str, why: str) -> None:
    last = _refused("ur-rtde", ["--host", host], "'--host'", repr(host), why)
    assert "--port" not in last


@pytest.mark.parametrize("args", [
    ["ur-rtde", "--port", "0", "--cb3", "--cycle-ms", "8", "--duration", "0.5"],
    ["ur-rtde", "--port", "3", "--cycle-ms", "2", "--enable", "0:inf", "--mark", "2:"],
    ["fanuc-j519", "--port", "0", "--cycle-ms", "4", "--late", "1:2", "--late-by", "0.1",
     "--estop-at", "0", "--close-at", "5"],
    ["kuka-rsi", "--port", "65535", "--cycle-ms", "12", "--operator", "random",
     "--operator-seed", "2", "--operator-delay", "0"]])
def test_valid_options_pass_the_checks(args: list[str]) -> None:
    check_arguments(build_parser().parse_args(["emulate", *args]))


@pytest.mark.parametrize(("args", "names"), [
    (["ur-rtde", "--robot", "ur5", "--port", "-1", "--duration", "2"], ("'--port' = -1",)),
    (["ur-rtde", "--robot", "ur5", "--enable", "5:1", "--duration", "2"],
     ("'--enable' = '5:1'",))])
def test_the_console_command_refuses_without_a_traceback(args: list[str],
                                                         names: tuple[str, ...]) -> None:
    r = subprocess.run([sys.executable, "-m", "leadthrough", "emulate", *args],
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stdout == ""  # refused before the emulator's ready line
    assert len(r.stderr.strip().splitlines()) == 1
    for name in names:
        assert name in r.stderr
