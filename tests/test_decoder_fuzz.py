"""Fuzzing each decoder of the real-controller protocols (hypothesis): any bytes give a value
or a typed error (:class:`~leadthrough.drivers.wire.PacketError` with a
:class:`~leadthrough.drivers.wire.BadPacket` code) within a time bound, and through the
transports' decode call (:func:`~leadthrough.drivers.link.decode_packet`, the RTDE client's
``feed``) a counted refusal, never an exception."""

from __future__ import annotations

import math
import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from leadthrough.drivers.fanuc_j519.packets import (
    CommandPacket,
    StatusPacket,
    decode_client_packet,
    decode_robot_packet,
)
from leadthrough.drivers.kuka_rsi.messages import RobotMessage, SensorMessage
from leadthrough.drivers.link import LinkStats, decode_packet
from leadthrough.drivers.ur_rtde.client import DEFAULT_OUTPUTS, RtdeClient
from leadthrough.drivers.ur_rtde.protocol import (
    OUTPUT_TYPES,
    MessageType,
    Recipe,
    TextMessage,
    frame,
)
from leadthrough.drivers.wire import BadPacket, PacketError

#: One decode may take at most this long [s], in this thread's CPU time (a preemption by
#: another process is not the decoder's cost): a valid one takes tens of µs; far below the
#: 38 ms a billion-laughs document cost before.
BOUND_S = 5e-3
FUZZ = settings(max_examples=300, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])

VALID_ROB = RobotMessage(123645634563, (0.1, -90.0, 90.0, 0.0, 45.5, -0.25),
                         axis_setpoint=(0.0,) * 6, delay=3, gear_torque=(1.0,) * 6,
                         digital_inputs=3).encode(4)
VALID_SEN = SensorMessage(5, (0.1,) * 6, stop=True).encode(4)
TOKENS = [b"<Rob", b"<Sen", b' TYPE="KUKA">', b"</Rob>", b"</Sen>", b"<AIPos ", b"<ASPos ",
          b'A1="1.5" ', b'A2="-2" A3="3" A4="4" A5="5" A6="6" ', b"/>", b"<IPOC>", b"</IPOC>",
          b"<DiL>", b"</DiL>", b"<Delay D=\"", b"\" />", b"<!DOCTYPE r [", b"<!ENTITY a \"",
          b"&a;", b"]>", b"<?pi x?>", b"<![CDATA[", b"]]>", b"<!-- -->", b"nan", b"inf",
          b"9" * 30, b"-", b".", b"e", b"\xff", b"\x00", b"<", b">", b"&", b"'", b'"']


def _rsi_documents() -> st.SearchStrategy[bytes]:
    tokens = st.lists(st.sampled_from(TOKENS), max_size=40).map(b"".join)
    mutated = st.tuples(st.integers(0, len(VALID_ROB) - 1), st.binary(max_size=8)).map(
        lambda m: VALID_ROB[:m[0]] + m[1] + VALID_ROB[m[0] + 1:])
    return st.one_of(st.binary(max_size=600), tokens, mutated)


def _decoded_or_typed(decode, data):  # type: ignore[no-untyped-def]
    """Decode ``data``: the value, or the PacketError's code; asserts the time bound (on the
    fastest of three decodes: a preempted one says nothing of the decoder)."""
    fastest = math.inf
    for _ in range(3):
        t0 = time.thread_time()
        try:
            out = decode(data)
        except PacketError as e:
            assert isinstance(e.code, BadPacket) and e.field
            out = e.code
        fastest = min(fastest, time.thread_time() - t0)
    assert fastest < BOUND_S
    return out


@FUZZ
@given(_rsi_documents())
def test_rsi_documents_decode_or_are_refused_by_code(data: bytes) -> None:
    for decode in (RobotMessage.decode, SensorMessage.decode):
        out = _decoded_or_typed(decode, data)
        stats = LinkStats()
        again = decode_packet(data, decode, stats)
        if isinstance(out, BadPacket):
            assert again is None and stats.bad == {out: 1} and stats.malformed == 1
        else:
            assert again == out and not stats.bad


def test_rsi_golden_documents_still_decode() -> None:
    assert RobotMessage.decode(VALID_ROB).ipoc == 123645634563
    assert SensorMessage.decode(VALID_SEN).stop


def _recipe() -> Recipe:
    return Recipe(1, DEFAULT_OUTPUTS, tuple(OUTPUT_TYPES[n] for n in DEFAULT_OUTPUTS))


def _valid_package(t: float) -> bytes:
    recipe = _recipe()
    values = {n: 0 for n in recipe.names}
    values.update(timestamp=t, actual_q=(0.0,) * 6, actual_current=(0.0,) * 6)
    return recipe.encode(values)


@FUZZ
@given(st.one_of(st.binary(max_size=200),
                 st.floats(allow_nan=True, allow_infinity=True).map(_valid_package),
                 st.tuples(st.integers(0, 150), st.binary(min_size=1, max_size=1)).map(
                     lambda m: _valid_package(1.0)[:m[0]] + m[1] + _valid_package(1.0)[
                         m[0] + 1:])))
def test_rtde_payloads_decode_or_are_refused_by_code(payload: bytes) -> None:
    recipe = _recipe()
    _decoded_or_typed(recipe.decode, payload)
    _decoded_or_typed(TextMessage.decode, payload)


def _client() -> RtdeClient:
    """A client past its handshake (the recipe set), fed bytes instead of a socket."""
    client = RtdeClient("127.0.0.1", 1, frequency=500.0)
    client._out = _recipe()   # as the handshake leaves it
    return client


@FUZZ
@given(st.lists(st.one_of(
    st.binary(max_size=120),
    st.tuples(st.integers(0, 255), st.binary(max_size=120)).map(lambda m: frame(*m)),
    st.floats(allow_nan=True, allow_infinity=True).map(
        lambda t: frame(MessageType.DATA_PACKAGE, _valid_package(t))),
    st.binary(max_size=20).map(lambda b: frame(MessageType.TEXT_MESSAGE, b))), max_size=12))
def test_the_rtde_client_takes_any_stream_without_raising(chunks: list[bytes]) -> None:
    client = _client()
    t0 = time.thread_time()
    last = -math.inf
    for chunk in chunks:
        state = client.feed(chunk)       # never raises
        if state is not None:
            assert math.isfinite(state.timestamp) and state.timestamp > last
            last = state.timestamp
    assert time.thread_time() - t0 < BOUND_S * (1 + len(chunks))
    assert client.stats.bad[BadPacket.UNEXPECTED] == 0
    # only a corrupt header (size < 3) breaks the stream
    if client.error is not None:
        assert "corrupt header" in client.error.detail


VALID_STATUS = StatusPacket(sequence=7, status=5, joints=(1.0,) * 9, current=(0.0,) * 9,
                            timestamp=100).encode()


@FUZZ
@given(st.one_of(st.binary(max_size=200), st.binary(min_size=132, max_size=132),
                 st.binary(min_size=184, max_size=184),
                 st.tuples(st.integers(0, 131), st.binary(min_size=1, max_size=1)).map(
                     lambda m: VALID_STATUS[:m[0]] + m[1] + VALID_STATUS[m[0] + 1:])))
def test_j519_packets_decode_or_are_refused_by_code(data: bytes) -> None:
    for decode in (decode_robot_packet, decode_client_packet, StatusPacket.decode,
                   CommandPacket.decode):
        out = _decoded_or_typed(decode, data)
        stats = LinkStats()
        again = decode_packet(data, decode, stats)
        assert (again is None) == isinstance(out, BadPacket)
        assert stats.bad[BadPacket.UNEXPECTED] == 0
