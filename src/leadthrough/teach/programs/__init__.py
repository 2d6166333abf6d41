"""Robot programs of a taught path: URScript, KUKA KRL, FANUC TP, ABB RAPID.

Each language writes the same moves (:mod:`~leadthrough.teach.programs.targets`): a joint move to
the first waypoint, then linear moves to poses with the controller's configuration data
(:mod:`~leadthrough.teach.programs.configuration`), or, with ``joint_space``, joint moves to the
taught joints. Every file is read back by the language's strict reader (only the statements its
writer emits, in their order: :mod:`~leadthrough.teach.programs.grammar`), every move compared
with the move written (count, kind, in order) and solved back with our inverse kinematics
(:mod:`~leadthrough.teach.programs.parsed`) before it is written: a program with a statement we
did not write, a move added or missing, or poses and configurations that do not give back the
taught joints to 0.01° is not written. The writers embed only mark labels
(:func:`leadthrough.labels.check_label`), valid program names and finite numbers; other text in
comments (robot and frame names) is written with ``?`` for any character a comment cannot hold.

Example::

    from leadthrough.teach.programs import ProgramOptions, write_robot_program

    opts = ProgramOptions(name="seam", speed_m_s=0.1)
    write_robot_program(program, robot, "krl", "seam.src", opts)   # seam.src + seam.dat
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leadthrough.errors import TeachError
from leadthrough.fileio import atomic_write_text, require_folder
from leadthrough.robot.arm_configuration import arm_structure, branch_values
from leadthrough.robot.description import Robot
from leadthrough.teach.program import TaughtProgram
from leadthrough.teach.programs.configuration import abb_config, fanuc_config, kuka_config
from leadthrough.teach.programs.fanuc_tp import parse_tp, render_tp
from leadthrough.teach.programs.krl import parse_krl, render_krl
from leadthrough.teach.programs.parsed import (
    ParsedProgram,
    check_round_trip,
    solve_back,
)
from leadthrough.teach.programs.rapid import parse_rapid, render_rapid
from leadthrough.teach.programs.targets import (
    ProgramOptions,
    ProgramTarget,
    program_name,
    program_targets,
    xyzabc,
)
from leadthrough.teach.programs.urscript import parse_urscript, render_urscript

__all__ = ["LANGUAGES", "Language", "ProgramOptions", "ProgramTarget", "RenderedProgram",
           "check_program", "program_name", "program_targets", "render_robot_program", "solve_back",
           "target_configurations", "write_robot_program"]


class Language(NamedTuple):
    """A program language.

    Attributes:
        suffix: File suffix of the main file (others share its stem).
        configure: Configuration data of a joint configuration, or None (URScript).
        render: Texts by suffix from the targets (:func:`~leadthrough.teach.programs.targets.
            program_targets`), the configuration data of each (None for joint moves and in
            URScript), the options (name, speeds, zone, tool, joint space, FANUC CNT) and the
            header comment lines.
        parse: The program read back from its texts by suffix.
    """

    suffix: str
    configure: Callable[..., Any] | None
    render: Callable[..., dict[str, str]]
    parse: Callable[[dict[str, str]], ParsedProgram]


LANGUAGES: dict[str, Language] = {
    "urscript": Language(".script", None, lambda t, c, o, h: render_urscript(t, o, h),
                         parse_urscript),
    "krl": Language(".src", kuka_config, render_krl, parse_krl),
    "tp": Language(".ls", fanuc_config, render_tp, parse_tp),
    "rapid": Language(".mod", abb_config, render_rapid, parse_rapid),
}


class RenderedProgram(NamedTuple):
    """A program ready to write.

    Attributes:
        files: Text by suffix (``.src`` and ``.dat`` for KRL, one file otherwise).
        targets: Its moves.
        max_round_trip_deg: Largest difference between the taught joints and the joints solved
            back from the text [deg].
    """

    files: dict[str, str]
    targets: list[ProgramTarget]
    max_round_trip_deg: float


def _header(program: TaughtProgram, robot: Robot, options: ProgramOptions, language: str,
            n: int) -> list[str]:
    tool = ", ".join(f"{v:.3f}" for v in xyzabc(options.tool))
    lines = [f"leadthrough taught path: robot {robot.name}, {n} targets, "
             f"{'joint' if options.joint_space else 'linear'} moves",
             f"TCP = {robot.tcp_frame} + tool X, Y, Z, A, B, C = {tool} mm, deg",
             f"poses in the robot base frame; speed {options.speed_m_s:g} m/s, "
             f"zone {options.zone_mm:g} mm"]
    line = program.welding_line
    if line is not None:
        lines.append(f"welding line {line.start_label}->{line.end_label} "
                     f"{1e3 * line.length_m:.1f} mm (one linear move)")
    return lines


def target_configurations(language: str, robot: Robot, targets: list[ProgramTarget],
                          joint_space: bool, source: str | None = None) -> list[Any]:
    """Configuration data of each target in ``language`` (None: a joint move, or URScript).

    The first target is a joint move; the others carry configuration data unless
    ``joint_space``.

    Raises:
        TeachError: A robot or joint angle the language's configuration cannot express,
            naming the target.
    """
    lang = LANGUAGES[language]
    configs: list[Any] = [None] * len(targets)
    if joint_space or lang.configure is None:
        return configs
    structure = arm_structure(robot)
    data = robot.model.createData()
    for i, t in enumerate(targets[1:], start=1):
        try:
            configs[i] = lang.configure(structure, robot, t.q,
                                        branch_values(structure, robot, t.q, data))
        except TeachError as e:
            label = f" ({t.label})" if t.label else ""
            raise TeachError(f"target {i}{label}: {e.message}", source=source, field=e.field,
                             value=e.value, expected=e.expected) from e
    return configs


def render_robot_program(program: TaughtProgram, robot: Robot, language: str,
                         options: ProgramOptions, source: str | None = None) -> RenderedProgram:
    """The program texts, checked by reading them back and solving them back.

    Args:
        program: The taught program.
        robot: Its robot.
        language: ``urscript``, ``krl``, ``tp`` or ``rapid``.
        options: Name, speeds, zone, tool, joint space.
        source: Session file, for messages.

    Returns:
        The texts, the targets and the round-trip figure.

    Raises:
        TeachError: An unknown language, a robot the language cannot express (7 axes, joints
            beyond the configuration's turns), a target outside the joint limits, or a text
            that does not solve back to the taught joints within 0.01°.
    """
    lang = LANGUAGES.get(language)
    if lang is None:
        raise TeachError("unknown program language", field="format", value=language,
                         expected=", ".join(LANGUAGES))
    targets = program_targets(program, robot, options, source)
    configs = target_configurations(language, robot, targets, options.joint_space, source)
    files = lang.render(targets, configs, options,
                        _header(program, robot, options, language, len(targets)))
    worst = check_program(language, files, robot, targets, configs, options)
    return RenderedProgram(files, targets, worst)


def check_program(language: str, files: dict[str, str], robot: Robot,
                  targets: list[ProgramTarget], configs: list[Any],
                  options: ProgramOptions) -> float:
    """Read a program text back strictly and compare every move with the moves written.

    The language's reader accepts only the statements its writer emits, in their order (a
    digital output, a wait, an extra move or a comment ended by an embedded newline is an
    error); then the program must carry the options' name, hold exactly one move per target,
    in order, of the target's kind (a joint move where the configuration is None, or in
    URScript's joint space), and solve back to each target's joints within
    :data:`~leadthrough.teach.programs.parsed.ROUND_TRIP_TOLERANCE_DEG`.

    Args:
        language: ``urscript``, ``krl``, ``tp`` or ``rapid``.
        files: The texts by suffix.
        robot: The robot.
        targets: The moves written.
        configs: Their configuration data (None: a joint move).
        options: The options written (name, joint space).

    Returns:
        The largest joint difference [deg].

    Raises:
        TeachError: A statement, order, name or move the writer did not write, naming the
            file and line, or the move and joint.
    """
    parsed = LANGUAGES[language].parse(files)
    if parsed.name != options.name:
        raise TeachError(f"the {language} program names another program", field="name",
                         value=parsed.name, expected=options.name)
    joint_moves = [c is None for c in configs]
    if language == "urscript":  # no configuration data: movel unless in joint space
        joint_moves = [i == 0 or options.joint_space for i in range(len(targets))]
    return check_round_trip(parsed, robot, np.array([t.q for t in targets]), language,
                            joint_moves)


def write_robot_program(program: TaughtProgram, robot: Robot, language: str,
                        path: str | Path, options: ProgramOptions,
                        source: str | None = None) -> list[Path]:
    """Render (see :func:`render_robot_program`) and write the program atomically.

    Args:
        program: The taught program.
        robot: Its robot.
        language: ``urscript``, ``krl``, ``tp`` or ``rapid``.
        path: Main file (its suffix is replaced by the language's); KRL adds the ``.dat``.
        options: Settings.
        source: Session file, for messages.

    Returns:
        The files written (none is written if any check or write fails).
    """
    rendered = render_robot_program(program, robot, language, options, source)
    return write_texts(Path(path), rendered.files)


def write_texts(path: Path, files: dict[str, str]) -> list[Path]:
    """Write ``path`` with each suffix's text, all or none (each file atomically)."""
    targets = [path.with_suffix(suffix) for suffix in files]
    for t in targets:
        require_folder(t)
    existed = {t: t.exists() for t in targets}
    written: list[Path] = []
    try:
        for t, text in zip(targets, files.values(), strict=True):
            written.append(atomic_write_text(t, text))
    except BaseException:
        for t in written:
            if not existed[t]:
                t.unlink(missing_ok=True)
        raise
    return written
