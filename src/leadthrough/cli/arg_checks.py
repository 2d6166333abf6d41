"""Checks of the CLI's arguments that the library cannot make (file types, limits of a
trajectory file), done before any work so that a bad argument exits 2 with nothing written."""

from __future__ import annotations

import errno
import socket
from pathlib import Path

import numpy as np
import pinocchio as pin

from leadthrough.errors import ControlError, DataError
from leadthrough.excitation.fourier import TrajectorySamples
from leadthrough.fileio import require_folder
from leadthrough.identification.calibration import check_command_lag, check_sweep
from leadthrough.identification.params_file import ParamsFile
from leadthrough.robot.description import Robot
from leadthrough.session.realtime import MAX_FIFO_PRIORITY

__all__ = ["MAX_DURATION_S", "MAX_PAYLOAD_COM_M", "check_bindable", "check_not_input",
           "check_output", "check_payload_torques",
           "check_rt_priority", "check_trajectory_limits", "require_sweep", "warm_up_seconds",
           "with_command_lag"]

#: Farthest payload CoM from the TCP ``record`` simulates [m].
MAX_PAYLOAD_COM_M = 1.0
#: Longest ``--duration`` of a command that otherwise runs until Ctrl-C [s] (about 115 days;
#: ``threading.Timer`` fails far beyond it).
MAX_DURATION_S = 1e7


def check_bindable(host: str, option: str, *, family: int = socket.AF_UNSPEC,
                   kind: int = socket.SOCK_STREAM, port: int | None = None,
                   port_expected: str = "a free port") -> None:
    """An address to serve on (``option``, e.g. ``--bind``, ``--host``): it resolves and a
    socket of ``kind`` binds to it, as a server's would (and to ``port`` when one is given
    and not 0: then it must be free). Checked before anything starts, so that a server that
    cannot bind fails with its option named, not later (viser hangs on such an address, and
    moves on to the next port when one is taken).

    Raises:
        DataError: Naming ``option`` (or ``--port`` for a port in use, with ``port_expected``),
            the value and why.
    """
    expected = "an address of this machine, e.g. 127.0.0.1, or 0.0.0.0 for all"
    if not host.strip():
        raise DataError("empty address", field=option, value=host, expected=expected)
    try:
        infos = socket.getaddrinfo(host, port or 0, family, kind, 0, socket.AI_PASSIVE)
    except (OSError, UnicodeError) as e:
        raise DataError(f"cannot resolve it: {getattr(e, 'strerror', None) or e}",
                        field=option, value=host, expected=expected) from e
    for fam, typ, proto, _, address in infos:
        with socket.socket(fam, typ, proto) as s:
            if typ == socket.SOCK_STREAM:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server
            if fam == socket.AF_INET6:
                s.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                s.bind(address)
            except OSError as e:
                if port and e.errno == errno.EADDRINUSE:
                    raise DataError(f"port in use on {host}", field="--port", value=port,
                                    expected=port_expected) from e
                raise DataError(f"cannot bind it: {e.strerror or e}", field=option,
                                value=host, expected=expected) from e


def check_rt_priority(priority: int | None) -> None:
    """``--rt-priority``: a SCHED_FIFO priority, or None (the normal scheduler).

    Raises:
        ControlError: Naming ``--rt-priority`` and its range.
    """
    if priority is not None and not 1 <= priority <= MAX_FIFO_PRIORITY:
        raise ControlError("out of range", field="--rt-priority", value=priority,
                           expected=f"a SCHED_FIFO priority 1..{MAX_FIFO_PRIORITY}")


def warm_up_seconds(minutes: float) -> float:
    """``--warm-up`` [min] of ``record`` and ``guide`` in seconds.

    Raises:
        DataError: Not a finite duration from 0 to 24 h.
    """
    if not (np.isfinite(minutes) and 0.0 <= minutes <= 24 * 60):
        raise DataError("out of range", field="--warm-up", value=minutes,
                        expected="0 <= minutes <= 1440")
    return 60.0 * float(minutes)


def with_command_lag(pf: ParamsFile, lag: float | None) -> ParamsFile:
    """The params of ``guide``, with ``--command-lag`` [s] in place of the measured lag if
    given.

    Raises:
        DataError: Not a finite lag from 0 to ``MAX_COMMAND_LAG_S``.
    """
    return check_command_lag(pf, lag, field="--command-lag")


def require_sweep(pf: ParamsFile, allow_no_sweep: bool) -> ParamsFile:
    """``pf`` if it can guide: identified with a friction sweep, or ``--allow-no-sweep``
    (``guide`` and ``pendant``; the library's check,
    :func:`~leadthrough.identification.calibration.check_sweep`).

    Raises:
        DataError: Naming the file, ``meta.friction_sweep`` and the ways out.
    """
    return check_sweep(pf, allow_no_sweep, opt_out="--allow-no-sweep")


def check_output(path: Path, suffixes: tuple[str, ...],
                 inputs: tuple[tuple[str, Path | None], ...] = ()) -> None:
    """An output file, checked before any work: its type (the writer would not convert), its
    folder (:func:`leadthrough.fileio.require_folder`), and that it is none of the command's
    ``inputs`` (option name, path or None), which writing it would replace."""
    if Path(path).suffix.lower() not in suffixes:
        raise DataError("unsupported output file type", source=path, field="-o",
                        value=Path(path).suffix or "(none)", expected=" or ".join(suffixes))
    require_folder(path)
    check_not_input(path, "-o", inputs)


def check_not_input(path: Path, option: str, inputs: tuple[tuple[str, Path | None], ...]
                    ) -> None:
    """Refuse an output ``path`` (given as ``option``) that is one of the command's inputs
    (option name, path or None; the same file by any path, a link included).

    Raises:
        DataError: Naming the output option, the path and the input it would overwrite.
    """
    out = Path(path).resolve()
    for name, given in inputs:
        if given is not None and Path(given).resolve() == out:
            raise DataError(f"the output would overwrite the input {name}", source=path,
                            field=option, value=str(path),
                            expected=f"a path other than {name}'s")


def check_trajectory_limits(path: Path, traj: TrajectorySamples, robot: Robot) -> None:
    """Positions within the joint limits, and the velocity both as written and as the
    positions' own rate of change (a time column squeezed by hand) within the speed limits."""
    dt = np.diff(traj.time)
    moved = np.abs(np.diff(traj.q, axis=0)) / dt[:, None] if dt.size else np.zeros((0, robot.n))
    for name, values, lo, hi, unit in (
            ("q", traj.q, robot.lower_limits, robot.upper_limits, "rad"),
            ("qd", traj.qd, -robot.velocity_limit, robot.velocity_limit, "rad/s"),
            ("qd (from q and time)", moved, -1.01 * robot.velocity_limit,
             1.01 * robot.velocity_limit, "rad/s")):
        bad = (values < lo) | (values > hi)
        if bad.any():
            row, j = (int(x) for x in np.argwhere(bad)[0])
            raise DataError(f"trajectory leaves the robot's limits in row {row}", source=path,
                            field=f"{name.split()[0]}{j + 1}{name[2:]}",
                            value=float(values[row, j]),
                            expected=f"{lo[j]:.4g} .. {hi[j]:.4g} {unit}")


def check_payload_torques(path: Path, traj: TrajectorySamples, robot: Robot,
                          payload: pin.Inertia, option: str, mass: float) -> None:
    """The links' torques along the trajectory with ``payload`` at the TCP (Pinocchio's RNEA
    of the robot's model, every sample) within the joints' max torque: beyond it the drives
    saturate and a recording shows only that (on the simulated er20 a 60 kg payload on a
    friction-check trajectory left the joints 0.6 rad behind their command).

    Args:
        path: The trajectory file (for the message).
        traj: Its samples.
        robot: The robot.
        payload: The payload's inertia in the TCP frame.
        option: The option that set the payload (for the message).
        mass: Its mass [kg] (the value the message names).
    """
    model = pin.Model(robot.model)
    frame = model.frames[robot.tcp_frame_id]
    model.inertias[frame.parentJoint] += frame.placement.act(payload)
    data = model.createData()
    for row in range(traj.time.size):
        tau = pin.rnea(model, data, traj.q[row], traj.qd[row], traj.qdd[row])
        over = np.abs(tau) > robot.max_torque
        if over.any():
            j = int(np.argmax(over))
            raise DataError("the robot cannot carry this payload along the trajectory",
                            source=path, field=option, value=mass,
                            expected=f"a payload within the joints' max torque: in row {row} "
                                     f"joint {j + 1} needs {abs(tau[j]):.0f} N·m, above its "
                                     f"{robot.max_torque[j]:g} N·m")
