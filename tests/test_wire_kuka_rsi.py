"""KUKA RSI: golden XML documents written from the RSI Ethernet format, the shipped
controller files, and our client against the emulated robot over loopback (trajectory, gear
torque, inputs, late answers, correction monitoring, lost documents, NaN)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from leadthrough.drivers.kuka_rsi.client import RsiClient
from leadthrough.drivers.kuka_rsi.config import EthernetConfig, RsiContext, shipped_file
from leadthrough.drivers.kuka_rsi.messages import RobotMessage, SensorMessage
from leadthrough.errors import DataError
from leadthrough.robot import Robot
from leadthrough.sim.emulators import (
    EmulatorOptions,
    FaultPlan,
    InputSchedule,
    KukaRsiEmulator,
    RunningEmulator,
    Window,
    start,
)
from leadthrough.sim.emulators.kuka_rsi import IPOC_START
from wire_helpers import DIRECTION, POSE, exchange, min_jerk

# ------------------------------------------------------------------ golden documents (by hand)
# as the robot sends them (RSI manual style, one element per line)
ROB = """<Rob TYPE="KUKA">
<RIst X="445.0" Y="0.0" Z="900.0" A="0.0" B="90.0" C="0.0" />
<RSol X="445.5" Y="0.0" Z="900.0" A="0.0" B="90.0" C="0.0" />
<AIPos A1="0.1" A2="-90.0" A3="90.0" A4="0.0" A5="45.5" A6="-0.25" />
<ASPos A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="45.0" A6="0.0" />
<Delay D="3" />
<GearTorque A1="1.5" A2="-120.25" A3="40.0" A4="0.5" A5="2.0" A6="-0.125" />
<DiL>3</DiL>
<IPOC>123645634563</IPOC>
</Rob>"""
# our encoding: the same elements, no whitespace, Precision decimals (here 4)
ROB_ENCODED = (
    b'<Rob TYPE="KUKA">'
    b'<RIst X="445.0000" Y="0.0000" Z="900.0000" A="0.0000" B="90.0000" C="0.0000" />'
    b'<RSol X="445.5000" Y="0.0000" Z="900.0000" A="0.0000" B="90.0000" C="0.0000" />'
    b'<AIPos A1="0.1000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="45.5000" A6="-0.2500" />'
    b'<ASPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="45.0000" A6="0.0000" />'
    b'<Delay D="3" />'
    b'<GearTorque A1="1.5000" A2="-120.2500" A3="40.0000" A4="0.5000" A5="2.0000" '
    b'A6="-0.1250" />'
    b"<DiL>3</DiL><IPOC>123645634563</IPOC></Rob>")
SEN = (b'<Sen Type="ImFree"><AK A1="0.1000" A2="-0.2000" A3="0.0000" A4="1.5000" '
       b'A5="-1.5000" A6="0.0100" /><IPOC>123645634563</IPOC></Sen>')


def _rob_message() -> RobotMessage:
    return RobotMessage(
        ipoc=123645634563, axis_actual=(0.1, -90.0, 90.0, 0.0, 45.5, -0.25),
        axis_setpoint=(0.0, -90.0, 90.0, 0.0, 45.0, 0.0),
        cart_actual=(445.0, 0.0, 900.0, 0.0, 90.0, 0.0),
        cart_setpoint=(445.5, 0.0, 900.0, 0.0, 90.0, 0.0), delay=3,
        gear_torque=(1.5, -120.25, 40.0, 0.5, 2.0, -0.125), digital_inputs=3)


def test_robot_document_golden_both_directions() -> None:
    assert RobotMessage.decode(ROB) == _rob_message()
    assert _rob_message().encode(precision=4) == ROB_ENCODED
    assert RobotMessage.decode(ROB_ENCODED) == _rob_message()


def test_sensor_document_golden_both_directions() -> None:
    msg = SensorMessage(123645634563, (0.1, -0.2, 0.0, 1.5, -1.5, 0.01))
    assert msg.encode(precision=4) == SEN
    assert SensorMessage.decode(SEN) == msg
    # kuka_rsi_hw_interface writes std::to_string numbers (6 decimals) and no spaces
    ros = ('<Sen Type="ImFree"><AK A1="0.100000" A2="-0.200000" A3="0.000000" A4="1.500000" '
           'A5="-1.500000" A6="0.010000"/><IPOC>123645634563</IPOC></Sen>')
    assert SensorMessage.decode(ros) == msg


def test_the_last_answer_sets_stop() -> None:
    """The Stop flag of the session's last answer, an element with the value 1 (a BOOL
    ``TAG="Stop"`` of the RECEIVE list, as in KUKA's kuka-external-control-sdk
    rsi_ethernet.xml), before the IPOC; absent from every other answer."""
    last = SensorMessage(123645634563, (0.1, -0.2, 0.0, 1.5, -1.5, 0.01), stop=True)
    assert last.encode(precision=4) == SEN.replace(b"<IPOC>", b"<Stop>1</Stop><IPOC>")
    assert SensorMessage.decode(last.encode()) == last
    assert b"Stop" not in SensorMessage(1, (0.0,) * 6).encode()


@pytest.mark.parametrize(("text", "field", "value"), [
    ("<Rob TYPE='KUKA'><IPOC>5</IPOC></Rob>", "AIPos", None),
    ('<Rob><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" /><IPOC>5</IPOC></Rob>', "AIPos.A6", None),
    ('<Rob><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="x" /><IPOC>5</IPOC></Rob>',
     "AIPos.A6", "x"),
    ('<Rob><AIPos A1="1" A2="2" A3="3" A4="4" A5="5" A6="6" /><IPOC>5.5</IPOC></Rob>',
     "IPOC", "5.5"),
    ("<Sen Type='ImFree'><AK A1='0'/>", "document", None),
    ("<Sen Type='ImFree'></Sen>", "root", "Sen"),
])
def test_malformed_documents_name_the_field(text: str, field: str, value: object) -> None:
    with pytest.raises(DataError) as err:
        RobotMessage.decode(text)
    assert err.value.field == field and err.value.expected
    if value is not None:
        assert err.value.value == value


def test_sensor_encoding_refuses_non_finite_corrections() -> None:
    with pytest.raises(DataError) as err:
        SensorMessage(1, (0.0, 0.0, math.inf, 0.0, 0.0, 0.0)).encode()
    assert err.value.field == "AK.A3"


def test_shipped_controller_files_agree() -> None:
    cfg, ctx = EthernetConfig.shipped(), RsiContext.shipped()
    assert (cfg.port, cfg.sentype, cfg.only_send) == (49152, "ImFree", False)
    assert {"DEF_AIPos", "DEF_ASPos", "DEF_Delay", "DiL"} <= cfg.send_tags
    assert [e.tag for e in cfg.send if e.tag.startswith("GearTorque")] == [
        f"GearTorque.A{i}" for i in range(1, 7)]
    assert [e.tag for e in cfg.receive] == [*(f"AK.A{i}" for i in range(1, 7)), "Stop"]
    assert [e.hold_on for e in cfg.receive] == [True] * 6 + [False]
    assert ctx.timeout == 100 and ctx.precision == 6 and ctx.max_correction == (90.0,) * 6
    rsix = shipped_file("leadthrough_rsi.rsix").read_text()
    assert 'ParamValue="leadthrough_rsi_ethernet.xml"' in rsix
    stop = rsix.split('ObjType="Stop"')[1].split("</RsiObject>")[0]   # Stop <- output 6
    assert '<Input InIdx="0" OutObjId="RSI" OutIdx="6" />' in stop
    assert [e.index for e in cfg.receive if e.tag == "Stop"] == [7]   # ETHERNET output 6
    krl = shipped_file("leadthrough_rsi.src").read_text()
    assert 'RSI_CREATE("leadthrough_rsi"' in krl and "RSI_ON(#ABSOLUTE)" in krl
    assert "RSI_MOVECORR()" in krl
    with pytest.raises(DataError) as err:
        EthernetConfig.parse("<ROOT><CONFIG><IP_NUMBER>1</IP_NUMBER><PORT>70000</PORT>"
                             "<SENTYPE>x</SENTYPE><ONLYSEND>FALSE</ONLYSEND></CONFIG></ROOT>")
    assert err.value.field == "CONFIG/PORT" and err.value.value == 70000


# ------------------------------------------------------------------- client vs emulator
def _session(client: RsiClient, target: object, duration: float,
             answer: object = None) -> list[RobotMessage]:
    """Answer every document for ``duration`` s with corrections towards
    ``target(t, first)`` [deg]; ``answer(k)`` False skips the answer to document k."""

    def respond(msg: RobotMessage, got: list[RobotMessage]) -> None:
        if answer is not None and not answer(len(got)):  # type: ignore[operator]
            return
        t = (msg.ipoc - got[0].ipoc) * 1e-3
        client.send(client.correction_for(target(t, got[0])))  # type: ignore[operator]

    return exchange(client.receive, duration, respond)


def _client() -> RsiClient:
    client = RsiClient("127.0.0.1", 0)
    client.open()
    return client


def _start(robot: Robot, client: RsiClient, **kw: object) -> RunningEmulator:
    return start("kuka-rsi", robot, seed=4, port=client.address[1],
                 options=EmulatorOptions(q0=POSE, **kw))  # type: ignore[arg-type]


def test_corrections_follow_a_trajectory_with_torque_and_inputs(er20: Robot) -> None:
    client = _client()
    inputs = InputSchedule(mark=(Window(0.2, 0.3),))
    with _start(er20, client, inputs=inputs) as emu:
        delta = np.degrees(0.05 * DIRECTION)
        msgs = _session(client, lambda t, f: min_jerk(np.array(f.axis_setpoint), delta,
                                                           t, 0.5), 0.8)
        report = emu.stop()
    client.close()
    first, last = msgs[0], msgs[-1]
    assert np.abs(np.array(first.axis_actual) - np.degrees(POSE)).max() < 1e-3
    assert np.abs(np.array(last.axis_actual) - (np.array(first.axis_setpoint) + delta)).max() \
        < 0.02
    assert last.delay is not None and last.delay <= 2 and client.stats.missed == 0
    assert first.gear_torque is not None and abs(first.gear_torque[1]) > 50.0  # gravity, N·m
    pressed = [(m.ipoc - first.ipoc) * 1e-3 for m in msgs if m.digital_inputs == 2]
    assert pressed and min(pressed) >= 0.19 and max(pressed) <= 0.31
    assert first.cart_actual is not None and 500 < math.hypot(*first.cart_actual[:2]) < 2000
    assert report.violations == () and report.stop_kind is None and report.accepted > 150


def test_gear_torque_is_the_measured_current_times_the_nominal_drive_factor(
        er20: Robot) -> None:
    emu = KukaRsiEmulator(er20, 4, EmulatorOptions(q0=POSE, realtime=False), port=9)
    for _ in range(20):
        emu.arm.step()
    msg = emu._message(emu.t)
    current = emu.arm.sample().current
    assert msg.gear_torque == pytest.approx(tuple(current * er20.torque_per_amp), rel=1e-12)


def test_late_answers_are_counted_then_rsi_stops(er20: Robot) -> None:
    client = _client()
    with _start(er20, client, watchdog=0.02) as emu:  # Timeout: 5 late answers in a row
        msgs = _session(client, lambda t, f: f.axis_setpoint, 0.6,
                        answer=lambda k: not (20 <= k < 23 or k > 60))
        silent = client.silent_for
        report = emu.stop()
    client.close()
    delays = [m.delay for m in msgs]
    # documents 20-22 unanswered: the next documents count them (a loaded machine may add
    # a late answer of its own), and RSI goes on
    assert delays[19] is not None and delays[22] is not None
    assert delays[22] - delays[19] >= 3 and len(msgs) > 55
    assert report.stop_kind == "watchdog" and "late answers" in report.stop_reason
    assert len(msgs) < 70 and silent > 0.2  # the robot stopped sending after the timeout
    # the answer timing names the three unanswered documents (msgs[19:22]: answer(k) sees
    # the document counted), and not the run that ended the stream (silence from msgs[60])
    events = " ".join(report.timing.events)
    assert all(f"#{m.ipoc} never" in events for m in msgs[19:22]), events
    assert not any(f"#{m.ipoc} " in events for m in msgs[60:]), events
    assert report.timing.never >= 3 and report.timing.in_time > 50


def test_correction_monitor_stops_rsi(er20: Robot) -> None:
    ctx = RsiContext(timeout=100, precision=6, lower=(-2.0,) * 6, upper=(2.0,) * 6,
                     max_correction=(1.0,) * 6)
    client = _client()
    emulator = KukaRsiEmulator(er20, 4, EmulatorOptions(q0=POSE), port=client.address[1],
                               context=ctx)
    with RunningEmulator(emulator) as emu:
        ramp = np.array([10.0, 0, 0, 0, 0, 0])  # A1 at 10 deg/s: 1 deg after 0.1 s
        _session(client, lambda t, f: np.array(f.axis_setpoint) + ramp * t, 0.4)
        report = emu.stop()
    client.close()
    assert report.stop_kind == "limit" and "AXISCORRMON: A1" in report.stop_reason
    assert report.violations == ()


def test_lost_documents_and_nan_are_seen_for_what_they_are(er20: Robot) -> None:
    faults = FaultPlan(loss_bursts=(Window(0.2, 0.22),), nan_q=(Window(0.3, 0.32),),
                       close_at=0.5)
    client = _client()
    with _start(er20, client, faults=faults) as emu:
        msgs = _session(client, lambda t, f: f.axis_setpoint, 0.8)
        report = emu.stop()
    client.close()
    assert client.stats.gaps == 1 and client.stats.missed == 5 == report.dropped
    assert any(all(math.isnan(a) for a in m.axis_actual) for m in msgs)
    # the robot counts each document it lost as a late answer (a loaded machine may add late
    # answers of its own, so only the lower bound is exact)
    before = [m.delay for m in msgs if (m.ipoc - IPOC_START) * 1e-3 < 0.19]
    after = [m.delay for m in msgs if (m.ipoc - IPOC_START) * 1e-3 > 0.23]
    assert before[-1] is not None and after[0] is not None
    assert after[0] - before[-1] >= 5
    assert client.silent_for > 0.2  # a closed robot socket is silence for the listener
