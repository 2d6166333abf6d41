"""The operator's inputs: the enabling device's fresh-press rule and the mark button's debounce,
checked as properties over random input sequences."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from leadthrough.session.operator_inputs import EnablingDevice, MarkButton, input_bit

cycles = st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=60)


def _engaged_by_definition(seq: list[tuple[bool, bool]]) -> list[bool]:
    """Engaged at k iff some j <= k saw a press (held at j, released at j-1, never released
    before the first cycle counts as held) while ready, and held and ready at every cycle
    j..k."""
    out = []
    for k in range(len(seq)):
        ok = False
        for j in range(k + 1):
            was_held = True if j == 0 else seq[j - 1][0]
            if seq[j][0] and not was_held and all(h and r for h, r in seq[j:k + 1]):
                ok = True
        out.append(ok)
    return out


@settings(max_examples=300, deadline=None)
@given(cycles)
def test_enabled_only_from_a_fresh_press_while_ready_and_held_since(
        seq: list[tuple[bool, bool]]) -> None:
    dev = EnablingDevice()
    got = [dev.update(held, ready) for held, ready in seq]
    assert got == _engaged_by_definition(seq)


def test_held_at_start_or_pressed_before_ready_needs_a_new_press() -> None:
    dev = EnablingDevice()
    # held from the start, the loop becomes ready: not enabled, must release first
    assert [dev.update(True, r) for r in (False, False, True, True)] == [False] * 4
    assert dev.needs_release
    assert not dev.update(False, True)       # released
    assert dev.update(True, True)            # fresh press while ready
    # a press during warm-up (not ready) does not count once ready
    dev = EnablingDevice()
    dev.update(False, False)
    assert not dev.update(True, False)
    assert not dev.update(True, True) and dev.needs_release
    # a fault (not ready) drops it; still held when ready again: release and press
    dev = EnablingDevice()
    dev.update(False, True)
    assert dev.update(True, True)
    assert not dev.update(True, False)
    assert not dev.update(True, True)
    assert not dev.update(False, True) and dev.update(True, True)


def test_reset_forgets_the_device() -> None:
    dev = EnablingDevice()
    dev.update(False, True)
    assert dev.update(True, True)
    dev.reset()
    assert not dev.update(True, True)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=200), st.integers(0, 30))
def test_one_mark_per_debounced_press(levels: list[bool], debounce_ms: int) -> None:
    """At 1 ms per sample: a mark exactly where the button rises after having been released
    for at least the debounce time (a button pressed at the start marks nothing)."""
    button = MarkButton(debounce_s=debounce_ms * 1e-3)
    marks = [button.update(level, k * 1e-3) for k, level in enumerate(levels)]
    expected = []
    released_at = None
    previous = True
    for k, level in enumerate(levels):
        if not level and previous:
            released_at = k
        expected.append(level and not previous and released_at is not None
                        and k - released_at >= debounce_ms)
        previous = level
    assert marks == expected


def test_input_bit() -> None:
    assert input_bit(0b101, 0) and not input_bit(0b101, 1) and input_bit(0b101, 2)
    assert input_bit(1 << 63, 63) and not input_bit(0, 63)
