"""An emulated KUKA robot running the shipped RSI configuration over UDP.

Here the emulator is the robot: it sends first. Every RSI cycle (4 ms) it sends a ``<Rob>``
document with the elements of the shipped Ethernet configuration's ``<SEND>`` list to the
client's address (``options.host`` and the configuration's ``PORT``, 49152, unless told
otherwise), and takes the ``<Sen>`` answer carrying the same IPOC that arrived before its next
cycle. Its behaviour, read from the shipped context (``leadthrough_rsi.rsix``):

* corrections are absolute (``RSI_ON(#ABSOLUTE)``): target = axis positions at start + AK;
  AXISCORRMON stops RSI when a correction exceeds ``MaxA1..A6``; AXISCORR clamps to
  ``LowerLim`` / ``UpperLim``; a target step faster than the drive file's joint speed limit
  stops the robot (its speed monitoring); a non-finite AK stops it too;
* a missing or late answer (wrong IPOC) keeps the last correction (``HOLDON``) and counts in
  ``<Delay D>``; after ``Timeout`` (100) late answers in a row RSI stops: the arm makes a
  controlled stop at its deceleration and the robot sends nothing more, as the KRL program
  ends. Any stop (also E-stop, protective stop) ends the exchange the same way;
* an answer with ``<Stop>1</Stop>`` (the configuration's ``Stop`` element, wired to the
  context's STOP object) is the client's end: its correction is applied, then the arm makes
  the same controlled stop (a requested stop, not a fault) and the exchange ends;
* ``<GearTorque>``: what the GEARTORQUE object reports is the controller's joint torque at
  the gear output, derived from the motor current (KUKA's manual, not public, describes its
  ``TorqueSource`` / ``LocationOnJoint`` options; the shipped context takes 0 / 0 as FZI's
  driver does). The emulator sends the simulator's measured motor current times the drive
  file's nominal ``gear_ratio × torque_constant``: the drive torque (before friction) that a
  real controller would compute, with the current sensor's noise; a driver recovers the
  current by dividing by the same factor;
* ``<DiL>``: $IN[1] (bit 0) enabling device, $IN[2] (bit 1) mark button, $IN[3] (bit 2)
  fault reset button;
* ``<RIst>`` / ``<RSol>``: TCP of the measured / commanded axes (forward kinematics) in mm
  and KUKA A B C (Z-Y-X Euler) degrees.

Message format and configuration: :mod:`leadthrough.drivers.kuka_rsi.messages`,
:mod:`leadthrough.drivers.kuka_rsi.config` (sources cited there).
"""

from __future__ import annotations

import math

import numpy as np

from leadthrough.drivers.kuka_rsi.client import DEFAULT_PORT
from leadthrough.drivers.kuka_rsi.config import EthernetConfig, RsiContext
from leadthrough.drivers.kuka_rsi.messages import RobotMessage, SensorMessage
from leadthrough.errors import DataError
from leadthrough.robot.description import Robot
from leadthrough.sim.emulators.arm import ArmPhase, MotionLimits, StopKind
from leadthrough.sim.emulators.controller import UdpController
from leadthrough.sim.emulators.scenario import EmulatorOptions, input_bits

__all__ = ["KukaRsiEmulator"]

IPOC_START = 1_000_000_000


class KukaRsiEmulator(UdpController):
    """KUKA robot with RSI (see the module doc).

    Args:
        robot, seed, options: As for every emulator (``options.host`` is the client's
            address).
        port: The client's UDP port.
        config: Ethernet configuration (default: the shipped one).
        context: RSI context (default: the shipped one).
    """

    kind = "kuka-rsi"
    default_cycle_ms = 4

    def __init__(self, robot: Robot, seed: int, options: EmulatorOptions,
                 port: int = DEFAULT_PORT, config: EthernetConfig | None = None,
                 context: RsiContext | None = None) -> None:
        super().__init__(robot, seed, options, port)
        self.config = config if config is not None else EthernetConfig.shipped()
        self.context = context if context is not None else RsiContext.shipped()
        self.timeout = (round(options.watchdog / self.arm.cycle) if options.watchdog is not None
                        else self.context.timeout)
        self.ipoc = IPOC_START
        self.cycle_ms = round(self.arm.cycle * 1000)
        self.start_deg = np.degrees(self.arm.target)
        self.active = True
        self.late_total = self.late_run = self.stale_answers = self.malformed = 0
        self._awaiting: int | None = None
        self._answer: SensorMessage | None = None
        self._tpa = robot.torque_per_amp
        #: The configuration wires the answers' ``Stop`` to a STOP object.
        self.stop_element = any(el.tag == "Stop" for el in self.config.receive)

    def motion_limits(self, robot: Robot) -> MotionLimits:
        """Joint speed (the robot's monitoring); corrections are checked separately."""
        return MotionLimits.of(robot, acceleration=False, jerk_per_accel=None)

    @property
    def port(self) -> int:
        """The client's port the documents are sent to."""
        return self.requested_port

    @property
    def bind_port(self) -> int:
        """The robot sends from an ephemeral port."""
        return 0

    def poll(self, t: float) -> None:
        """Take the answers that arrived; keep the one for the awaited IPOC."""
        for data, _, rx, exact in self.datagrams(self._sock):
            try:
                answer = SensorMessage.decode(data)
            except DataError:
                self.malformed += 1
                continue
            self.timing.answer(rx, key=answer.ipoc, exact=exact)
            if answer.ipoc == self._awaiting:
                self._answer = answer
            else:
                self.stale_answers += 1

    def on_cycle(self, t: float) -> None:
        """Apply the answer to the last document (or count it late), send the next one."""
        if not self.active or self._sock is None:
            return
        if self._awaiting is not None:
            if self._answer is None:
                self.wait_for_reply()
            self.cycle_answered(self._answer is not None)
            if self._answer is not None:
                self.late_run = 0
                self._apply(np.array(self._answer.correction, dtype=float), t)
                if self._answer.stop and self.stop_element:
                    self.arm.stop(StopKind.REQUEST, "RSI: Stop from the sensor "
                                                    "(RSI_MOVECORR ends)")
                    self.stream_ended()
            else:
                self.late_total += 1
                self.late_run += 1
                if self.late_run > self.timeout:
                    self.arm.stop(StopKind.WATCHDOG, f"RSI: {self.late_run} late answers in a "
                                  f"row (Timeout {self.timeout})")
                    self.stream_ended()
                else:
                    self.arm.hold()
        if self.arm.phase in (ArmPhase.STOPPING, ArmPhase.FAULT):
            self.active = False  # RSI off: the KRL program ends, nothing more is sent
            return
        self._answer = None
        self.ipoc += self.cycle_ms
        self._awaiting = self.ipoc
        data = self._message(t).encode(self.context.precision)
        self.transmit(self._sock, data, (self.options.host, self.requested_port),
                      key=self.ipoc)

    def _apply(self, ak: np.ndarray, t: float) -> None:
        ctx = self.context
        target = np.radians(self.start_deg + ak)
        if not np.all(np.isfinite(ak)):
            self.arm.refuse(tuple(target), t, "RSI: correction not finite")
        elif np.any(np.abs(ak) > np.array(ctx.max_correction)):
            j = int(np.argmax(np.abs(ak) - np.array(ctx.max_correction)))
            self.arm.refuse(tuple(target), t, f"AXISCORRMON: A{j + 1} correction "
                            f"{ak[j]:.3f} deg beyond {ctx.max_correction[j]:g} deg")
        else:
            ak = np.clip(ak, ctx.lower, ctx.upper)
            self.arm.command(np.radians(self.start_deg + ak), t)

    def _message(self, t: float) -> RobotMessage:
        fb = self.arm.sample()
        tags = self.config.send_tags
        actual = np.degrees(fb.q)
        if self.options.faults.nan(t):
            actual = np.full(self.robot.n, math.nan)
        state = self.inputs()

        def want(tag: str) -> bool:
            return tag in tags

        def abc(q: np.ndarray) -> tuple[float, ...]:
            x, y, z, roll, pitch, yaw = self.arm.tcp_pose(q)
            return (x, y, z, yaw, pitch, roll)

        return RobotMessage(
            ipoc=self.ipoc, axis_actual=tuple(actual.tolist()),
            axis_setpoint=tuple(np.degrees(self.arm.target).tolist())
            if want("DEF_ASPos") else None,
            cart_actual=abc(fb.q) if want("DEF_RIst") else None,
            cart_setpoint=abc(self.arm.target) if want("DEF_RSol") else None,
            delay=self.late_total if want("DEF_Delay") else None,
            gear_torque=tuple((fb.current * self._tpa).tolist())
            if want("GearTorque.A1") else None,
            digital_inputs=input_bits(state) if want("DiL") else None)
