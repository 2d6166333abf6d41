"""An emulated Universal Robots controller: RTDE on TCP port 30004 and the behaviour of the
shipped URScript program (:mod:`leadthrough.drivers.ur_rtde.script`).

The emulator is the server, as the controller is. It runs at 500 Hz (e-Series, controller
version 5.11) or 125 Hz (``generation="cb3"``, version 3.15), accepts several connections
(:mod:`~leadthrough.sim.emulators.rtde_session`) and sends each started one a data package of
its output recipe every ``rate / frequency`` cycles.

Its secondary interface (:mod:`~leadthrough.sim.emulators.ur_secondary`) listens 2 below the
RTDE port (30002 for 30004, as on a UR controller; an ephemeral port when the RTDE port is)
and runs ``leadthrough_servo.script`` when it receives it, with the received program's
watchdog time and register offset: the program writes 1 to its state register, then every
cycle reads the registers: mode 1 servos to the six targets (``servoj``, modelled by the
arm's per-cycle interpolation; lookahead and gain are not modelled) and reports their watchdog
counter in its output register R+1 (the package of that cycle carries it), mode 0 holds, mode 2
stops the arm and halts the program (state 2). Once the watchdog counter has changed, when
it then does not change for the watchdog time (the program's, unless ``options.watchdog``),
the program stops the arm at its deceleration and halts (state 3, ``runtime_state``
STOPPED). Receiving the program again restarts it (after a watchdog or requested stop).
A target whose step from the previous one exceeds the joint speed limit triggers a protective stop
(``safety_mode`` 3, bit 2 of ``safety_status_bits``), as the controller does on a servoj jump;
the program halts. E-stop: ``safety_mode`` 7 (robot emergency stop), bits 6, 7 and 10,
``robot_mode`` POWER_OFF once stopped. Digital inputs: standard DI0 = enabling device, DI1 =
mark button (``actual_digital_input_bits``). Output variables the emulator does not produce
(TCP pose, forces, temperatures, ...) are answered NOT_FOUND.

Input variables (recipes, ids, IN_USE / NOT_FOUND, packages before START:
:mod:`~leadthrough.sim.emulators.rtde_session`) act as on a real controller, as far as the
RTDE outputs show them (UR's RTDE guide, output list):

* the general-purpose input registers are readable as outputs of the same name
  (``input_int_register_X``, ``input_double_register_X``, ``input_bit_register_X`` for
  64-127, ``input_bit_registers0_to_31`` / ``32_to_63``), holding the last value written;
* ``speed_slider_mask`` 1 sets the speed slider to ``speed_slider_fraction`` (clipped to
  0..1), reported as ``target_speed_fraction``; the servo program's motion is not scaled by it
  (``speed_scaling`` stays 1);
* ``standard_digital_output`` / ``configurable_digital_output`` / ``tool_digital_output`` set
  the outputs their mask selects, reported in ``actual_digital_output_bits`` (bits 0-7
  standard, 8-15 configurable, 16-17 tool, the guide's layout);
* ``standard_analog_output_0`` / ``_1`` set the analog output their mask selects, reported as
  ``standard_analog_output0`` / ``1`` (the value as sent, a fraction of the range; the type,
  current or voltage, is kept but not reported);
* ``external_force_torque`` is accepted and kept, and changes nothing.

``RTDEControlInterface`` of SDU Robotics' ``ur_rtde`` is not served. It needs, before its
RTDE session (whose output recipe and 23 input recipes the emulator does accept, with the ids it
assumes): the dashboard server on TCP 29999 (``PolyscopeVersion``, ``get serial number``,
``is in remote control``, ``stop``), which the emulator does not run, so the constructor fails
there; then it uploads its own ``rtde_control.script`` on TCP 30003 (the emulator's secondary
interface listens on 30002 only and runs only leadthrough's servo program), waits up to 5 s for
``robot_status_bits`` bit 1 (program running), and drives every call through that script's
command protocol (a command code in ``input_int_register_0``, arguments in the double
registers, the script's state in ``output_int_register_0``: ready / done with the command).
Serving it would take a dashboard server, a listener on 30003 and a model of that script's
command protocol (its moves, servo and speed modes, force mode, kinematics queries) in place of
the interpreter the controller has; the emulator has none of the three.
"""

from __future__ import annotations

import dataclasses
import math
import socket
from typing import Any

import numpy as np

from leadthrough.drivers.ur_rtde.protocol import DEFAULT_PORT, OUTPUT_TYPES, ControllerVersion
from leadthrough.drivers.ur_rtde.script import Mode, ScriptState, ServoScriptParameters
from leadthrough.robot.description import Robot
from leadthrough.sim.emulators.answer_timing import enable_rx_stamps
from leadthrough.sim.emulators.arm import ArmPhase, MotionLimits, StopKind
from leadthrough.sim.emulators.controller import EmulatedController
from leadthrough.sim.emulators.rtde_session import RtdeSession
from leadthrough.sim.emulators.scenario import EmulatorOptions, input_bits
from leadthrough.sim.emulators.ur_secondary import ReceivedProgram, ScriptListener

__all__ = ["PRODUCED_OUTPUTS", "UrRtdeEmulator"]

_PRODUCED_FIXED = ("timestamp", "target_q", "target_qd", "actual_q", "actual_qd",
                   "actual_current", "actual_digital_input_bits", "actual_digital_output_bits",
                   "robot_mode", "joint_mode", "safety_mode", "safety_status", "runtime_state",
                   "robot_status_bits", "safety_status_bits", "speed_scaling",
                   "target_speed_fraction")
PRODUCED_OUTPUTS: dict[str, str] = {
    **{n: t for n, t in OUTPUT_TYPES.items()
       if n in _PRODUCED_FIXED or n.startswith(("output_int_register", "output_double_register",
                                                "output_bit_register"))},
    **{f"input_int_register_{i}": "INT32" for i in range(48)},
    **{f"input_double_register_{i}": "DOUBLE" for i in range(48)},
    **{f"input_bit_register_{i}": "BOOL" for i in range(64, 128)},
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE",
}
"""Output variables the emulator fills, {name: type} (the RTDE guide's names and types)."""

# digital outputs in actual_digital_output_bits: (mask name, value name, first bit, width)
_DIGITAL_OUTPUTS = (("standard_digital_output_mask", "standard_digital_output", 0, 8),
                    ("configurable_digital_output_mask", "configurable_digital_output", 8, 8),
                    ("tool_digital_output_mask", "tool_digital_output", 16, 2))
_IO_INPUTS = frozenset({"speed_slider_mask", "speed_slider_fraction", "standard_analog_output_mask",
                        "standard_analog_output_0", "standard_analog_output_1",
                        *(n for d in _DIGITAL_OUTPUTS for n in d[:2])})

ROBOT_RUNNING, ROBOT_POWER_OFF = 7, 3
SAFETY_NORMAL, SAFETY_PROTECTIVE, SAFETY_ROBOT_ESTOP = 1, 3, 7
RUNTIME_STOPPED, RUNTIME_PLAYING = 1, 2
JOINT_RUNNING = 253
_SAFETY = {StopKind.ESTOP: SAFETY_ROBOT_ESTOP, StopKind.PROTECTIVE: SAFETY_PROTECTIVE,
           StopKind.LIMIT: SAFETY_PROTECTIVE}


class _Outputs(dict[str, Any]):
    """Output values; the general-purpose registers are looked up on demand (the input
    registers hold what the clients last wrote, 0 / 0.0 / False before)."""

    def __init__(self, values: dict[str, Any], out_int: list[int],
                 registers: dict[str, Any]) -> None:
        super().__init__(values)
        self.out_int = out_int
        self.registers = registers

    def __missing__(self, key: str) -> Any:
        if key.startswith("output_int_register_"):
            return self.out_int[int(key.rsplit("_", 1)[1])]
        if key.startswith("output_double_register_"):
            return 0.0
        if key.startswith("output_bit_register_"):
            return False
        if key.startswith("input_"):
            default = {"BOOL": False, "DOUBLE": 0.0}.get(PRODUCED_OUTPUTS.get(key, ""), 0)
            return self.registers.get(key, default)
        raise KeyError(key)


class UrRtdeEmulator(EmulatedController):
    """UR controller with RTDE and the leadthrough servo program (see the module doc)."""

    kind = "ur-rtde"
    default_cycle_ms = 2

    def __init__(self, robot: Robot, seed: int, options: EmulatorOptions,
                 port: int = DEFAULT_PORT) -> None:
        e_series = options.generation == "e-series"
        if options.cycle_ms is None:
            options = dataclasses.replace(options, cycle_ms=2 if e_series else 8)
        super().__init__(robot, seed, options, port)
        self.version = ControllerVersion(5, 11, 6, 0) if e_series else ControllerVersion(
            3, 15, 7, 0)
        self.rate = 1.0 / self.arm.cycle
        script = ServoScriptParameters()
        self.watchdog = options.watchdog if options.watchdog is not None else (
            script.watchdog_timeout)
        self.offset = script.register_offset
        self.registers: dict[str, Any] = {}
        self.out_int = [0] * 48
        self.speed_slider = 1.0          # fraction (RTDE speed_slider_fraction)
        self.digital_outputs = 0         # actual_digital_output_bits
        self.analog_outputs = [0.0, 0.0]  # standard analog outputs 0, 1 (fractions)
        self.program = ScriptState.NOT_RUNNING
        self.programs_received = 0
        self._counter: int | None = None
        self._armed = False
        self._silent = 0.0
        self._listener: socket.socket | None = None
        self._secondary: ScriptListener | None = None
        self.sessions: list[RtdeSession] = []
        self._owners: dict[str, RtdeSession] = {}
        self._cycles = 0
        self._q_prev: np.ndarray | None = None

    def motion_limits(self, robot: Robot) -> MotionLimits:
        """Joint speed only: a faster step is a servoj jump (protective stop)."""
        return MotionLimits.of(robot, acceleration=False, jerk_per_accel=None)

    @property
    def port(self) -> int:
        """The listening TCP port."""
        if self._listener is None:
            return self.requested_port
        return int(self._listener.getsockname()[1])

    @property
    def script_port(self) -> int:
        """The secondary interface's port (URScript programs)."""
        if self._secondary is not None:
            return self._secondary.port
        return self.requested_port - 2 if self.requested_port else 0

    def open(self) -> None:
        """Listen on the RTDE port and the secondary interface."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((self.options.host, self.requested_port))
        sock.listen(8)
        sock.setblocking(False)
        self._listener = sock
        try:
            self._secondary = ScriptListener(self.options.host, self.script_port)
        except OSError:
            self.close_sockets()
            raise

    def close_sockets(self) -> None:
        """Close every connection and the listening sockets."""
        for s in self.sessions:
            s.close()
        self.sessions.clear()
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        if self._secondary is not None:
            self._secondary.close()
            self._secondary = None

    def on_send_error(self, sock: socket.socket) -> None:
        """Drop the session whose socket failed."""
        for s in self.sessions:
            if s.sock is sock:
                s.close()

    # ---------------------------------------------------------------------------- input
    def poll(self, t: float) -> None:
        """Accept connections and answer requests."""
        while self._listener is not None:
            try:
                conn, _ = self._listener.accept()
            except BlockingIOError:
                break
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            enable_rx_stamps(conn)
            self.sessions.append(RtdeSession(conn, self.version, self.rate, PRODUCED_OUTPUTS,
                                              self._owners, self._write))
        for s in self.sessions:
            s.receive()
        self.sessions = [s for s in self.sessions if s.open]
        if self._secondary is not None:
            for program in self._secondary.poll():
                self._start_program(program)

    def _write(self, values: dict[str, Any], rx: float, exact: bool) -> None:
        """Input registers written at ``rx``: a changed watchdog counter answers the latest
        data package sent before it (``AnswerTiming.answer`` without a key)."""
        counter = f"input_int_register_{self.offset}"
        if (self.program is ScriptState.RUNNING and counter in values
                and values[counter] != self.registers.get(counter)):
            self.timing.answer(rx, exact=exact)
        self.registers.update(values)
        self._apply_io(values)

    def _apply_io(self, values: dict[str, Any]) -> None:
        """The speed slider, digital and analog outputs a package sets (module doc)."""
        if _IO_INPUTS.isdisjoint(values):
            return  # registers only (the servo program's packages)
        reg = self.registers
        if "speed_slider_mask" in values or "speed_slider_fraction" in values:
            fraction = reg.get("speed_slider_fraction", self.speed_slider)
            if reg.get("speed_slider_mask", 0) & 1 and math.isfinite(fraction):
                self.speed_slider = min(max(float(fraction), 0.0), 1.0)
        for mask_name, value_name, first, width in _DIGITAL_OUTPUTS:
            if mask_name in values or value_name in values:
                mask = (int(reg.get(mask_name, 0)) & ((1 << width) - 1)) << first
                value = int(reg.get(value_name, 0)) << first
                self.digital_outputs = (self.digital_outputs & ~mask) | (value & mask)
        if not {"standard_analog_output_mask", "standard_analog_output_0",
                "standard_analog_output_1"}.isdisjoint(values):
            mask = int(reg.get("standard_analog_output_mask", 0))
            for i in (0, 1):
                value = reg.get(f"standard_analog_output_{i}", self.analog_outputs[i])
                if mask >> i & 1 and math.isfinite(value):
                    self.analog_outputs[i] = float(value)

    def _start_program(self, program: ReceivedProgram) -> None:
        """Run a received servo program (restarts it; refused while the arm is stopping or
        in a safety stop, as a controller in a safety stop runs no program)."""
        self.programs_received += 1
        arm = self.arm
        if arm.phase is ArmPhase.STOPPING or (self.faulted and arm.stop_kind not in (
                StopKind.WATCHDOG, StopKind.REQUEST)):
            return
        if arm.phase is ArmPhase.FAULT or arm.stop_kind is StopKind.REQUEST:
            arm.reset()
        if self.options.watchdog is None:
            self.watchdog = program.watchdog_timeout
        self.offset = program.register_offset
        self.program = ScriptState.RUNNING
        self.out_int[self.offset] = int(ScriptState.RUNNING)
        self._counter = int(self._register("int", 0))
        self._armed, self._silent = False, 0.0

    # ---------------------------------------------------------------------------- cycle
    def on_cycle(self, t: float) -> None:
        """Run one cycle of the servo program, then send the due data packages."""
        if self.program is ScriptState.RUNNING:
            self._program_cycle(t)
        if self.faulted and self.program is ScriptState.RUNNING:
            self._halt(ScriptState.STOPPED, write=False)  # the controller stopped it
        values: dict[str, Any] | None = None
        # the package the servo program's client answers is timed (once a cycle)
        key = self._cycles if self._armed and self.program is ScriptState.RUNNING else None
        for s in self.sessions:
            if s.started and s.output is not None and self._cycles % s.divider == 0:
                values = values if values is not None else self._outputs(t)
                self.transmit(s.sock, s.output_package(values), None, key=key)
                key = None
        self._cycles += 1

    def _register(self, kind: str, i: int, default: float = 0) -> Any:
        return self.registers.get(f"input_{kind}_register_{self.offset + i}", default)

    def _program_cycle(self, t: float) -> None:
        counter = int(self._register("int", 0))
        if self._armed and counter == self._counter:
            self.wait_for_reply()
            counter = int(self._register("int", 0))
        mode = int(self._register("int", 1))
        fresh = counter != self._counter
        self._counter = counter
        self._armed = self._armed or fresh
        self._silent = 0.0 if fresh else self._silent + self.arm.cycle
        if self._armed and mode != Mode.STOP:  # the stop's own cycle ends the stream
            self.cycle_answered(fresh)
        if self._armed and self._silent > self.watchdog + 1e-9:
            self.arm.stop(StopKind.WATCHDOG, f"script watchdog: counter unchanged for "
                          f"{self._silent:.3f} s")
            self._halt(ScriptState.WATCHDOG)
            self.stream_ended()
        elif mode == Mode.STOP:
            self.arm.stop(StopKind.REQUEST, "stop requested (mode 2)")
            self._halt(ScriptState.STOPPED)
            self.stream_ended()
        elif mode == Mode.SERVO and fresh:
            q = np.array([float(self._register("double", i)) for i in range(6)])
            self.out_int[self.offset + 1] = counter  # the command servoj takes
            self.arm.command(q, t, refusal=StopKind.PROTECTIVE)
        else:
            self.arm.hold()

    def _halt(self, state: ScriptState, write: bool = True) -> None:
        """End the program; ``write``: it reports why in its output register."""
        self.program = state
        if write:
            self.out_int[self.offset] = int(state)

    def _outputs(self, t: float) -> dict[str, Any]:
        fb, arm = self.arm.sample(), self.arm
        q = fb.q if not self.options.faults.nan(t) else np.full(self.robot.n, math.nan)
        qd = (fb.q - self._q_prev) / arm.dt if self._q_prev is not None else np.zeros(6)
        self._q_prev = fb.q.copy()
        inputs = self.inputs()
        kind = arm.stop_kind if self.faulted else None
        safety = _SAFETY.get(kind, SAFETY_NORMAL) if kind is not None else SAFETY_NORMAL
        bits = {SAFETY_NORMAL: 1, SAFETY_PROTECTIVE: (1 << 2) | (1 << 10),
                SAFETY_ROBOT_ESTOP: (1 << 6) | (1 << 7) | (1 << 10)}[safety]
        powered = not (kind is StopKind.ESTOP and arm.phase is ArmPhase.FAULT)
        playing = self.program is ScriptState.RUNNING
        out: dict[str, Any] = {
            "timestamp": t, "actual_q": tuple(q), "actual_current": tuple(fb.current),
            "target_q": tuple(arm.target), "target_qd": tuple(arm.target_velocity),
            "actual_qd": tuple(qd),
            "actual_digital_input_bits": input_bits(inputs),
            "actual_digital_output_bits": self.digital_outputs,
            "robot_mode": ROBOT_RUNNING if powered else ROBOT_POWER_OFF,
            "joint_mode": (JOINT_RUNNING,) * 6, "safety_mode": safety, "safety_status": safety,
            "runtime_state": RUNTIME_PLAYING if playing else RUNTIME_STOPPED,
            "robot_status_bits": int(powered) | int(playing) << 1,
            "safety_status_bits": bits, "speed_scaling": 1.0,
            "target_speed_fraction": self.speed_slider,
            "standard_analog_output0": self.analog_outputs[0],
            "standard_analog_output1": self.analog_outputs[1],
        }
        return _Outputs(out, self.out_int, self.registers)
